"""Names a user chooses between on every entry point (CLI options, `v2c.api`, `v2c.pipeline.reconstruct`,
fixtures_design), kept in one light module so the CLI can show them without importing the stages."""

from __future__ import annotations

#: Segmentation methods by name (`v2c.segment.SEGMENTERS`): the learned RGB-D segmenter, the depth-only geometric
#: one, and the ground-truth oracle (synthetic scans with gt/ only).
SEGMENTATION_METHODS: tuple[str, ...] = ("learned", "geometric", "oracle")
#: The segmentation every entry point uses unless told otherwise.
DEFAULT_SEGMENTATION = "learned"
#: Fit ablations of the paper's Table 2 (`v2c.fit.fit_scan`): everything, without the shared axis frame, without
#: the intersection refinement, RANSAC fits only.
ABLATIONS: tuple[str, ...] = ("full", "no-axis", "no-int", "fit-only")
#: The ablation every entry point uses unless told otherwise.
DEFAULT_ABLATION = "full"
