"""ground-station: record telemetry to MCAP, review a recorded run.

    ground-station record --out RUN.mcap --telemetry-key-file DIR/telemetry.key [--duration S] [zenoh options]
    ground-station review RUN.mcap [--json] [--plots DIR]
    ground-station keys DIR [--config SCENARIO]

record stops on SIGINT/SIGTERM, after --duration seconds of wall time, or shortly after
the simulator's run_end event, and always finishes the file. review reads finished and
truncated logs (a killed recorder) alike. keys writes a run's telemetry keys for processes
started by hand: the recorder's master key and the simulator's and each companion's own
(telemetry.keyfiles). Exit status: 0 ok, 1 runtime failure,
2 bad input (missing file, not an MCAP, empty log, bad options, an output folder that
cannot be created or written).
"""
from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
from pathlib import Path

from amcore import cliargs
from amcore.config import DEFAULT_SCENARIO
from telemetry.session import TelemetryConfigError, add_zenoh_arguments, options_from_args


def _err(msg: str) -> None:
    print(f"ground-station: error: {msg}", file=sys.stderr)


def _record(a: argparse.Namespace) -> int:
    from .recorder import Recorder, RecorderError

    try:
        opts = options_from_args(a, role="recorder")
    except TelemetryConfigError as exc:
        _err(str(exc))
        return 2
    if not a.out.parent.is_dir():
        _err(f"--out {a.out}: {a.out.parent}: no such directory")
        return 2
    rec = Recorder(a.out, opts, scene_rate_hz=a.scene_rate, flush_period_s=a.flush_period,
                   compression=a.compression, linger_s=a.linger,
                   notify=lambda text: print(text, file=sys.stderr, flush=True))
    stop = threading.Event()

    def on_signal(signum, _frame):
        stop.set()

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    try:
        rec.open()
    except (RecorderError, TelemetryConfigError) as exc:
        _err(str(exc))
        return 2 if isinstance(exc, TelemetryConfigError) else 1
    where = ", ".join(opts.listen_endpoints) or ("(config file)" if opts.config_file is not None else "none")
    print(f"recording {opts.keys.everything} to {a.out} (zenoh {opts.mode}, listen {where}, "
          f"connect {', '.join(opts.connect_endpoints) or 'none'})", file=sys.stderr, flush=True)
    if rec.waiting_for_router is not None:
        print(f"zenoh: no router answers yet ({rec.waiting_for_router}); retrying every "
              f"{opts.retry_init_ms / 1e3:g}-{opts.retry_max_ms / 1e3:g} s, recording once one does",
              file=sys.stderr, flush=True)
    try:
        rec.run(duration_s=a.duration, stop=stop)
    finally:
        s = rec.close()
    print(f"stopped ({s.stop_reason}): {s.received} samples from {s.keys} keys, {s.written} messages, "
          f"{s.sim_time_s:.3f} s simulated, {s.bytes / 1e6:.2f} MB; lost: {s.missing} (seq gaps), "
          f"{s.inbox_overflow} (inbox overflow), {s.malformed} malformed, {s.rejected} rejected (unauthenticated)", file=sys.stderr)
    if not s.connected:
        print(f"ground-station: warning: zenoh: never reached {', '.join(opts.connect_endpoints) or 'the router'} "
              f"({rec.waiting_for_router}): nothing was recorded; is the router running there?", file=sys.stderr)
    if a.summary_json:
        print(json.dumps(s.as_dict()))
    return 0


def _keys(a: argparse.Namespace) -> int:
    from amcore.config import ConfigError, load_scenario
    from telemetry.keyfiles import MASTER_FILE, write_run_keys

    try:
        sysids = [am.sysid for am in load_scenario(a.config).ams]
    except ConfigError as exc:
        _err(str(exc))
        return 2
    if (a.folder / MASTER_FILE).exists():
        _err(f"{a.folder} already holds {MASTER_FILE}: a new set would lock out the processes using it; "
             f"choose another folder or remove the old keys")
        return 2
    try:
        a.folder.mkdir(parents=True, exist_ok=True)
        files = write_run_keys(a.folder, sysids)
    except OSError as exc:
        _err(f"keys {a.folder}: cannot write there: {exc.strerror or exc}")
        return 2
    for name, path in files.items():
        print(f"{name}: --telemetry-key-file {path}")
    return 0


def _review(a: argparse.Namespace) -> int:
    from .mcap_io import NotAnMcapError, read_log
    from .review import NoDataError, format_summary, load_run, summarize

    if not a.log.exists():
        _err(f"{a.log}: no such file")
        return 2
    if a.log.is_dir():
        _err(f"{a.log}: is a directory, not an MCAP file")
        return 2
    try:
        log = read_log(a.log)
        run = load_run(log)
        summary = summarize(log, run)
    except (NotAnMcapError, NoDataError, ValueError) as exc:  # ValueError: a message that does not decode
        _err(str(exc))
        return 2
    if a.plots is not None:
        from .plots import write_plots

        try:
            a.plots.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            _err(f"--plots {a.plots}: cannot create it: {exc.strerror or exc}")
            return 2
        try:
            summary["plots"] = [str(p) for p in write_plots(run, a.plots)]
        except OSError as exc:  # the folder is there: a full disk, say
            _err(f"--plots {a.plots}: cannot write {exc.filename or 'a plot'}: {exc.strerror or exc}")
            return 1
    if a.json:
        print(json.dumps(summary, indent=1))
    else:
        print(format_summary(summary))
    return 0


EXIT_CODES = cliargs.exit_codes(0, 1, 2, c1="a runtime failure", c2="bad input (a missing file, not an MCAP, an "
                                "empty log, bad options, an output folder that cannot be written)")


def build_parser() -> argparse.ArgumentParser:
    ap = cliargs.ArgumentParser(prog="ground-station", description=" ".join(__doc__.split("\n\n")[0].split()),
                                epilog=EXIT_CODES)
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("record", help="subscribe to the telemetry and write an MCAP log", epilog=EXIT_CODES)
    r.add_argument("--out", type=cliargs.output_file, required=True, help="MCAP file to write")
    r.add_argument("--duration", type=cliargs.seconds, default=None, help="stop after S seconds of wall time")
    r.add_argument("--linger", type=cliargs.seconds_or_zero, default=0.5, help="keep recording S seconds after run_end (default 0.5)")
    r.add_argument("--scene-rate", type=cliargs.number(0.0, 1000.0, unit=" Hz"), default=20.0, help="/scene updates per simulated second (0: none)")
    r.add_argument("--flush-period", type=cliargs.seconds, default=1.0, help="flush the file every S seconds (default 1)")
    r.add_argument("--compression", choices=("zstd", "lz4", "none"), default="zstd")
    r.add_argument("--summary-json", action="store_true", help="print the final summary as JSON on stdout")
    add_zenoh_arguments(r, role="recorder")
    k = sub.add_parser("keys", help="write a run's telemetry keys (recorder, simulator, each companion) into a folder",
                       epilog=EXIT_CODES)
    k.add_argument("folder", type=cliargs.output_dir, help="folder for the key files (created; mode 0600 files)")
    k.add_argument("--config", type=Path, default=DEFAULT_SCENARIO, help="scenario TOML: whose keys (its sysids)")
    v = sub.add_parser("review", help="summarize a recorded run per phase, optionally plot it", epilog=EXIT_CODES)
    v.add_argument("log", type=Path, help="MCAP file (a truncated one is salvaged)")
    v.add_argument("--json", action="store_true", help="print the summary as JSON")
    v.add_argument("--plots", type=cliargs.output_dir, default=None, metavar="DIR", help="write PNG plots into DIR")
    return ap


def main(argv: list[str] | None = None) -> int:
    a = build_parser().parse_args(argv)
    if a.command == "record":
        return _record(a)
    if a.command == "keys":
        return _keys(a)
    return _review(a)


if __name__ == "__main__":
    sys.exit(main())
