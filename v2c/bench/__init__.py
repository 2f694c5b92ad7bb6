"""Benchmarks against ground truth (../shared/BENCHMARK.md): `metrics` (every metric on one scan), `run`
(`v2c bench`: scans, ablations, tables); the per-stage benchmarks `fit`, `segmentation` and `vbrep`."""
