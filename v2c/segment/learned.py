"""The learned segmenter: U-Net label + boundary maps -> instances (``segment_learned``).

Weights default to ``v2c/segment/weights/unet.pt`` (see its MODEL_CARD.md). Inference runs on the whole image at
native resolution (the network is fully convolutional); bf16 autocast where the CPU supports it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np
import torch

from v2c.scan import Scan
from v2c.segment.data import FeatureConfig, scan_features
from v2c.segment.instances import InstanceConfig, extract_instances, feature_evidence
from v2c.segment.net import UNet, bf16_supported, load_weights
from v2c.segment.types import Segmentation

WEIGHTS_DIR = Path(__file__).parent / "weights"
DEFAULT_WEIGHTS = WEIGHTS_DIR / "unet.pt"


@dataclass(frozen=True)
class LearnedConfig:
    weights: Path | None = None  # None = DEFAULT_WEIGHTS
    bf16: bool | None = None  # None = where the CPU supports it
    features: FeatureConfig = field(default_factory=FeatureConfig)
    instances: InstanceConfig = field(default_factory=InstanceConfig)


def weights_available(path: Path | None = None) -> bool:
    """True when the weights file exists (callers fall back to the geometric segmenter otherwise)."""
    return Path(path or DEFAULT_WEIGHTS).is_file()


@lru_cache(maxsize=4)
def _model(path: str) -> UNet:
    model, _ = load_weights(path)
    return model.to(memory_format=torch.channels_last)


def predict(scan: Scan, cfg: LearnedConfig = LearnedConfig()) -> tuple[np.ndarray, np.ndarray]:
    """(class probabilities (18, H, W) float32, boundary probability (H, W) float32) of a scan."""
    probs, bnd, _ = predict_with_features(scan, cfg)
    return probs, bnd


@torch.no_grad()
def predict_with_features(scan: Scan, cfg: LearnedConfig = LearnedConfig()
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``predict`` plus the network's input features (9, H, W) float32 (``data.compute_features``)."""
    path = Path(cfg.weights or DEFAULT_WEIGHTS)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: segmentation weights not found (train them with `v2c train`)")
    model = _model(str(path))
    feat = scan_features(scan, cfg.features)
    x = torch.from_numpy(feat[None]).contiguous(memory_format=torch.channels_last)
    bf16 = bf16_supported() if cfg.bf16 is None else cfg.bf16
    with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
        lab, bnd = model(x)
    probs = torch.softmax(lab[0].float(), dim=0).numpy()
    return probs, torch.sigmoid(bnd[0, 0].float()).numpy(), feat


def segment_learned(scan: Scan, weights: str | Path | None = None, config: LearnedConfig | None = None
                    ) -> Segmentation:
    """Segment a scan with the U-Net. Pixels outside mask.png / the ROI (when given) stay background.

    weights: a weights file (default the shipped one). Raises FileNotFoundError when it does not exist.
    """
    cfg = config or LearnedConfig()
    if weights is not None:
        cfg = LearnedConfig(weights=Path(weights), bf16=cfg.bf16, features=cfg.features, instances=cfg.instances)
    probs, bnd, feat = predict_with_features(scan, cfg)
    return instances_from_prediction(scan, probs, bnd, cfg.instances, feat=feat)


def instances_from_prediction(scan: Scan, probs: np.ndarray, bnd: np.ndarray, cfg: InstanceConfig,
                              feat: np.ndarray | None = None) -> Segmentation:
    """Instances of a scan from the network's class probabilities (18, H, W) and boundary probability (H, W).

    feat: the network input features (9, H, W), for the optional depth / normal boundary evidence of ``cfg``."""
    labels = probs.argmax(axis=0).astype(np.uint8)
    region = None
    if scan.mask is not None or scan.roi is not None:
        region = scan.roi_mask()
        if scan.mask is not None:
            region &= scan.mask
            # with a part mask, a masked pixel is part even where the network says background
            fg = probs[1:].argmax(axis=0).astype(np.uint8) + 1
            labels = np.where(region, fg, 0).astype(np.uint8)
    evidence = feature_evidence(feat, cfg) if feat is not None else None
    return extract_instances(labels, bnd, region=region, probs=probs, cfg=cfg, method="learned", evidence=evidence)
