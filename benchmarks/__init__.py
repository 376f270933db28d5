"""Benchmark scripts (run as ``python benchmarks/bench_x.py``) and the BENCHMARKS.md report
(``python -m benchmarks.report``)."""
