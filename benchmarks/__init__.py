"""Benchmarks run as ``python -m benchmarks.NAME``: latency, clutter removal, learning curve and more."""
