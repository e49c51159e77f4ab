"""The project's benchmarks: each module measures one thing and prints what it measured.

Run one from the root of a clone, as a module of this package:

    python -m benchmarks.bench_core --n 2

Not part of the installed distribution: the benchmarks read `configs/` from the clone and
import the tests' helpers (`tests.*`: the literal controller, test worlds, free ports), which
`python -m` from the root finds beside them.
"""
