"""The segmentation stage's output (ARCHITECTURE.md contract)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Segmentation:
    """Surface instances of one scan and the 18-class label of each.

    instances: (H, W) int32; 0 = background/not part, 1..N = surface instance ids.
    labels: (N + 1,) uint8 18-class label of each instance (labels[0] = 0; 255 = non-analytic).
    scores: (N + 1,) float32 confidence of each instance's label in [0, 1].
    method: "oracle" | "learned" | "geometric".
    """

    instances: np.ndarray
    labels: np.ndarray
    scores: np.ndarray
    method: str

    @property
    def num_instances(self) -> int:
        """N, the number of instance ids (some may cover no pixel)."""
        return int(len(self.labels) - 1)

    def instance_ids(self) -> np.ndarray:
        """Sorted ids (>= 1) of the instances that cover at least one pixel."""
        ids = np.unique(self.instances)
        return ids[ids > 0]
