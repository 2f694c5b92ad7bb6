"""Ground-truth ("oracle") segmentation read from a synthetic scan's gt/faces.png and gt/labels.png."""

from __future__ import annotations

import numpy as np

from v2c.errors import ScanError
from v2c.labels import IGNORE
from v2c.scan import Scan
from v2c.segment.types import Segmentation


def segment_oracle(scan: Scan) -> Segmentation:
    """Instances = ground-truth faces relabelled 1..N consecutively (in increasing faces.png value); faces labelled
    255 (non-analytic) are dropped to 0. Each instance's label is the most frequent labels.png value over its pixels;
    scores are 1. Pixels outside ``scan.mask`` (when given) stay as in faces.png: the gt faces are the part.

    Raises ValueError when the scan has no ground truth.
    """
    if scan.gt is None:
        raise ScanError(f"{scan.path}: oracle segmentation needs gt/ (a synthetic scan); use --segmentation learned")
    faces = np.asarray(scan.gt.faces).astype(np.int64)
    labels = np.asarray(scan.gt.labels).astype(np.int64)
    keep = (faces > 0) & (labels != IGNORE)
    vals, inv = np.unique(np.where(keep, faces, 0), return_inverse=True)
    inv = inv.reshape(faces.shape)
    if vals[0] != 0:  # every pixel is a kept face: shift so that 0 stays background
        inv = inv + 1
        vals = np.concatenate([[0], vals])
    instances = inv.astype(np.int32)
    n = len(vals) - 1
    # per-instance label: the mode of labels.png over the instance (bincount over instance * 256 + label)
    hist = np.bincount((instances[keep] * 256 + labels[keep]).ravel(), minlength=(n + 1) * 256)
    out_labels = hist.reshape(n + 1, 256).argmax(axis=1).astype(np.uint8)
    out_labels[0] = 0
    scores = np.ones(n + 1, np.float32)
    scores[0] = 0.0
    return Segmentation(instances=instances, labels=out_labels, scores=scores, method="oracle")
