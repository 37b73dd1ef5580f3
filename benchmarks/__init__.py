"""``make bench``: accuracy and speed benchmarks, written to docs/BENCHMARKS.md."""
