"""The SITL composed: the simulator and the companions run together, the one package that
imports both sides (the simulator never imports the companion, nor the companion the simulator).

- `sitl.launch`: `am-run`, the simulator and one companion process per AM over MAVLink/UDP,
  with the run folder, telemetry and review.
- `sitl.inprocess`: the same `simulator.core.SitlCore` and `companion.pilot.Pilot` per AM
  called in one loop, without processes or sockets (`python -m sitl.inprocess`; the trials'
  runner).
"""
