"""Quality studies: what a setting or a method changes in accuracy, with committed results.

Each module runs as `python -m studies.NAME` (its docstring gives the command that wrote its
results) and writes its tables to studies/results/<machine>/. Timings live in `bench`, whose
run header the studies share; docs/benchmarks.md lists every study and benchmark with its
numbers.
"""
