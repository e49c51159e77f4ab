"""Process runtime shared by the simulator and the companion, below both process mains.

- `amruntime.jitcache`: the compiled kernels (amcore.law, telemetry.kernels, the simulator's
  group) warmed once per machine, each group under a machine-wide file lock.
- `amruntime.procstats`: this process's memory and CPU, and how its main thread spent a run.

It imports amcore and telemetry's kernels, never `simulator` or `companion`: both import it.
"""
