"""Benchmarks against ground truth (../shared/BENCHMARK.md), the application layer's `v2c bench`.

`run` coordinates a run of the paper's Table 1 from its parts, bottom to top: `config` (the run's and the metrics'
settings), `cache` (the scans), `surfaces` (the ground-truth and reconstructed surfaces, ray casts, Chamfer),
`vbrep` and `segmentation` (per-stage metrics), `metrics` (every metric of one scan), `workers` (one scan
reconstructed and scored; the executors over many), `tables` (summaries, JSON, Markdown). `suite` runs the
generalisation suites, `real` the real RGB-D frames, `fit` the geometry stage alone."""
