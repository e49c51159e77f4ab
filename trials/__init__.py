"""Trial campaigns: randomized variations of a scenario, run in-process on a local process
pool or a Dask cluster, judged by the simulator's mission verdict (`simulator.verdict`).

`trials.randomize` draws each trial's variation from a seed; `trials.runner` runs them;
`trials.report` writes trials.csv, summary.json and plots; `am-trials` (`trials.cli`) wires it.
"""
