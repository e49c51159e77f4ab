"""What the process mains publish, in a few calls (pure: takes any object with `publish`).

Simulator main:

    sim_tele = SimulatorTelemetry(tele, spec, truth_every=1)
    sim_tele.start()                                   # run_start (the scenario) + first phase
    each step:  if sim_tele.due(world.step_index): sim_tele.truth(world.ground_truth())
    at the end: sim_tele.end(world.time_s, "completed")

Companion main (after each `amcore.control.step`):

    am_tele = CompanionTelemetry(tele, sysid)
    am_tele.step(t, mission.phase(t), res)             # res: StepResult
    am_tele.fault(t, "lost lockstep")                  # faults as events

`tele` is a telemetry.publisher.TelemetryPublisher (or anything with publish(key, payload)).

The hot samples (controller state, ground truth) go out binary by default (telemetry.binary:
ROS 1 messages, copied on the caller's thread and finished on the publisher's sender thread
by telemetry.capture, whose compiled kernels the constructors load or compile first; ~4x less CPU than JSON in all, benchmarks/bench_telemetry.py);
encoding="json" sends them as JSON texts (telemetry.schema), as earlier versions did.
Events are always JSON.
"""
from __future__ import annotations

from . import capture, kernels, schema

ENCODINGS = ("binary", "json")


def _check_encoding(encoding: str) -> None:
    if encoding not in ENCODINGS:
        raise ValueError(f"telemetry encoding {encoding!r} is not one of {ENCODINGS}")


def phase_at(t_s: float, phase_ends_s) -> str:
    """Mission phase at simulation time t_s from the scenario's (approach_end, grasp_end, ...)."""
    a, g = phase_ends_s[0], phase_ends_s[1]
    return "approach" if t_s < a else ("grasp" if t_s < g else "hover")


class SimulatorTelemetry:
    """Run start/end, phase changes and ground truth every `truth_every` physics steps."""

    def __init__(self, publisher, spec, truth_every: int = 1, keys: schema.Keys | None = None,
                 encoding: str = "binary"):
        if truth_every < 1:
            raise ValueError("truth_every must be >= 1")
        _check_encoding(encoding)
        self._samples = capture.ground_truth if encoding == "binary" else schema.ground_truth_samples
        self.pub = publisher
        self._on = getattr(publisher, "enabled", True)  # nothing to build for a disabled publisher (--no-telemetry)
        if self._on and encoding == "binary":
            kernels.warm_up()  # now, at start-up: not in the sender thread, holding the GIL in the loop
        self.spec = spec
        self.keys = keys or getattr(publisher, "keys", None) or schema.Keys()
        self.truth_every = truth_every
        m = spec.mission
        self._ends = (m.approach_end_s, m.grasp_end_s, m.hover_end_s)
        self._phase: str | None = None

    def start(self, t_s: float = 0.0) -> None:
        self.pub.publish(self.keys.sim_event, schema.run_start_event(t_s, self.spec))
        self._track_phase(t_s)

    def due(self, step_index: int) -> bool:
        return step_index % self.truth_every == 0

    def truth(self, gt) -> None:
        """Publish one GroundTruth (and a phase event if its time entered a new phase)."""
        self._track_phase(gt.time_s)
        if self._on:
            for key, payload in self._samples(gt, self.keys):
                self.pub.publish(key, payload)

    def fault(self, t_s: float, text: str, level: str = "error") -> None:
        self.pub.publish(self.keys.sim_event, schema.fault_event(t_s, text, "simulator", level))

    def end(self, t_s: float, reason: str = "completed", level: str = "info") -> None:
        self.pub.publish(self.keys.sim_event, schema.run_end_event(t_s, reason, level=level))

    def _track_phase(self, t_s: float) -> None:
        ph = phase_at(t_s, self._ends)
        if ph != self._phase:
            self._phase = ph
            self.pub.publish(self.keys.sim_event, schema.phase_event(t_s, ph, "simulator"))


class CompanionTelemetry:
    """One AM's controller state every `every` control steps, and its fault events."""

    def __init__(self, publisher, sysid: int, every: int = 1, keys: schema.Keys | None = None,
                 encoding: str = "binary"):
        if every < 1:
            raise ValueError("every must be >= 1")
        _check_encoding(encoding)
        self._sample = capture.controller if encoding == "binary" else schema.controller_sample
        self.pub = publisher
        self._on = getattr(publisher, "enabled", True)
        if self._on and encoding == "binary":
            kernels.warm_up()  # loaded from the cache that amruntime.jitcache.warm filled
        self.sysid = int(sysid)
        self.every = every
        self.keys = keys or getattr(publisher, "keys", None) or schema.Keys()
        self._key = self.keys.controller(sysid)
        self._n = 0

    def step(self, t_s: float, phase: str, result) -> None:
        """result: amcore.control.StepResult (diagnostics and command are read)."""
        if self._n % self.every == 0 and self._on:
            self.pub.publish(self._key, self._sample(t_s, phase, result.diagnostics, result.command,
                                                     sysid=self.sysid))
        self._n += 1

    def fault(self, t_s: float, text: str, level: str = "error") -> None:
        self.pub.publish(self.keys.am_event(self.sysid), schema.fault_event(t_s, text, f"am{self.sysid}", level))

    def loop_stats(self, t_s: float, stats: dict) -> None:
        """The wall-clock loop's measurements so far (period, lateness, deadline misses, sample ages,
        sample-to-setpoint latency; companion.looptimer.LoopStats), an info event "loop timing"."""
        if self._on:
            self.pub.publish(self.keys.am_event(self.sysid), schema.loop_timing_event(t_s, stats, f"am{self.sysid}"))
