"""The learned segmenter: U-Net label + boundary maps -> instances (``segment_learned``).

Weights default to ``v2c/segment/weights/unet.pt`` (see its MODEL_CARD.md). Inference runs at native resolution
(the network is fully convolutional) on the part's box (mask.png / ROI bounding box plus a context margin; the whole
image when neither is given), averaged with its horizontal mirror (a label-safe flip, ``data.CachedScans.crop``);
bf16 autocast where the CPU supports it. Outside the box the class is background and the boundary 0.

The network's arithmetic (`network_precision`) changes its output enough to change a reconstruction: bf16 rounds
to 8 bits of mantissa, and on real frames a pixel that moves from one instance to another changes the fits
downstream (docs/segmentation.md, "The network's arithmetic"). ``V2C_PRECISION=fp32`` (or ``LearnedConfig.bf16``
= False) gives every machine the fp32 network; the mode used is recorded in the VB-Rep's ``meta`` and the bench's
JSON.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from functools import lru_cache
from pathlib import Path

import numpy as np
import torch

from v2c.geometry.config import RansacConfig
from v2c.pick import PickConfig, flying_mask
from v2c.scan import Scan
from v2c.segment.data import MIRROR_SIGN_CHANNEL, FeatureConfig, scan_features
from v2c.segment.instances import InstanceConfig, extract_instances, feature_evidence
from v2c.segment.net import UNet, bf16_supported, load_weights
from v2c.segment.refine import RefineConfig, absorb_fragments, refine_instances, remerge, split_crease_strips
from v2c.segment.types import Segmentation
from v2c.segment.verify import VerifyConfig, needs_regions, split_unexplained, verify_instances

#: Environment variable choosing the network's arithmetic where ``LearnedConfig.bf16`` is None: "auto" (bf16
#: where the CPU has it natively, else fp32), "fp32" or "bf16".
PRECISION_ENV = "V2C_PRECISION"
PRECISIONS = ("auto", "fp32", "bf16")

WEIGHTS_DIR = Path(__file__).parent / "weights"
DEFAULT_WEIGHTS = WEIGHTS_DIR / "unet.pt"


@dataclass(frozen=True)
class LearnedConfig:
    """Settings of the learned segmenter: weights, inference, instance extraction and the geometric check."""

    weights: Path | None = None  # None = DEFAULT_WEIGHTS
    bf16: bool | None = None  # None = $V2C_PRECISION (`network_precision`; unset: where the CPU supports it)
    features: FeatureConfig = field(default_factory=FeatureConfig)
    instances: InstanceConfig = field(default_factory=InstanceConfig)
    refine: RefineConfig = field(default_factory=RefineConfig)  # plane-outlier split, coplanar merge (refine.py)
    verify: VerifyConfig = field(default_factory=VerifyConfig)  # split / merge along depth-only plane regions
    # (verify.py; runs the geometric segmenter)
    context_px: int = 32  # margin of image context around the mask / ROI box fed to the network (pixels);
    # < 0 runs the whole image
    mirror_tta: bool = True  # average the prediction with that of the mirrored input (2x network time)
    ground_region: bool = True  # without mask.png: the part is what stands above the RANSAC ground inside the ROI
    # (`geometric.part_region`, as the geometric segmenter does), not the network's background class
    flying_max_share: float = 0.5  # an instance more than this share of whose readings are flying pixels
    # (`v2c.pick.flying_mask`: the ramp a sensor draws across a depth step) is no surface: its
    # pixels become background, last (fraction; 1 keeps every instance). The real lying sugar
    # box's ROI: a 39-pixel plane, 31 of them flying, along its end (docs/segmentation.md)


def network_precision(cfg: LearnedConfig | None = None) -> str:
    """The arithmetic the network runs in with ``cfg``, "bf16" or "fp32". ``cfg.bf16`` decides when set; else
    $V2C_PRECISION ("auto" when unset: bf16 where the CPU has it natively). Raises ValueError for another value of
    the variable, or for "bf16" on a CPU without native bf16."""
    if cfg is not None and cfg.bf16 is not None:
        return "bf16" if cfg.bf16 else "fp32"
    raw = os.environ.get(PRECISION_ENV, "auto")
    want = raw.strip().lower()
    if want not in PRECISIONS:
        raise ValueError(f"{PRECISION_ENV}={raw!r}: expected one of {', '.join(PRECISIONS)}")
    if want == "bf16" and not bf16_supported():
        raise ValueError(f"{PRECISION_ENV}=bf16: this CPU has no native bf16 (use fp32 or auto)")
    if want == "auto":
        return "bf16" if bf16_supported() else "fp32"
    return want


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
def predict_with_features(
    scan: Scan, cfg: LearnedConfig = LearnedConfig()
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``predict`` plus the network's input features (9, H, W) float32 (``data.compute_features``)."""
    path = Path(cfg.weights or DEFAULT_WEIGHTS)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: segmentation weights not found (train them with `v2c train`)")
    model = _model(str(path))
    feat = scan_features(scan, cfg.features)
    h, w = feat.shape[1:]
    y0, y1, x0, x1 = _box(scan, cfg.context_px, (h, w))
    x = torch.from_numpy(np.ascontiguousarray(feat[None, :, y0:y1, x0:x1]))
    bf16 = network_precision(cfg) == "bf16"
    with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
        lab, bnd = model(x.contiguous(memory_format=torch.channels_last))
        prob = torch.softmax(lab[0].float(), dim=0)
        edge = torch.sigmoid(bnd[0, 0].float())
        if cfg.mirror_tta:
            xm = torch.flip(x, dims=[3])
            xm[:, MIRROR_SIGN_CHANNEL] = -xm[:, MIRROR_SIGN_CHANNEL]
            lab_m, bnd_m = model(xm.contiguous(memory_format=torch.channels_last))
            prob = 0.5 * (prob + torch.flip(torch.softmax(lab_m[0].float(), dim=0), dims=[2]))
            edge = 0.5 * (edge + torch.flip(torch.sigmoid(bnd_m[0, 0].float()), dims=[1]))
    probs = np.zeros((prob.shape[0], h, w), np.float32)
    probs[0] = 1.0
    probs[:, y0:y1, x0:x1] = prob.numpy()
    boundary = np.zeros((h, w), np.float32)
    boundary[y0:y1, x0:x1] = edge.numpy()
    return probs, boundary, feat


def _box(scan: Scan, context_px: int, shape: tuple[int, int]) -> tuple[int, int, int, int]:
    """(y0, y1, x0, x1) of the network's input window: the mask / ROI bounding box grown by context_px."""
    h, w = shape
    if context_px < 0 or (scan.mask is None and scan.roi is None):
        return 0, h, 0, w
    region = scan.roi_mask()
    if scan.mask is not None:
        region = region & scan.mask
    ys, xs = np.nonzero(region)
    if len(ys) == 0:
        return 0, h, 0, w
    return (
        max(int(ys.min()) - context_px, 0),
        min(int(ys.max()) + context_px + 1, h),
        max(int(xs.min()) - context_px, 0),
        min(int(xs.max()) + context_px + 1, w),
    )


def segment_learned(
    scan: Scan,
    weights: str | Path | None = None,
    config: LearnedConfig | None = None,
    *,
    refine: RefineConfig | None = None,
    ransac: RansacConfig | None = None,
) -> Segmentation:
    """Segment a scan with the U-Net. Pixels outside mask.png / the ROI (when given) stay background.

    weights: a weights file (default the shipped one). Raises FileNotFoundError when it does not exist.
    refine: replaces ``config.refine`` when given; ransac: the instance points, RANSAC and type-selection
    settings of the geometric check (`refine.refine_instances`; default `RansacConfig()`).
    """
    cfg = config or LearnedConfig()
    if weights is not None:
        cfg = replace(cfg, weights=Path(weights))
    if refine is not None:
        cfg = replace(cfg, refine=refine)
    probs, bnd, feat = predict_with_features(scan, cfg)
    region = None
    if cfg.ground_region and scan.mask is None and scan.roi is not None:
        from v2c.segment.geometric import GeometricConfig, part_region

        region = part_region(scan, GeometricConfig())[0]
    seg = instances_from_prediction(scan, probs, bnd, cfg.instances, feat=feat, part=region)
    seg = refine_instances(seg, scan.depth, scan.K, probs, cfg.refine, normals=feat[3:6], ransac=ransac)
    if needs_regions(seg, scan.depth, scan.K, cfg.verify):
        from v2c.segment.geometric import segment_geometric

        seg = verify_instances(seg, segment_geometric(scan), scan.depth, scan.K, cfg.verify, ransac)
        # the pieces that verification left (pieces it cut off, instances it did not merge) are judged once more
        if cfg.refine.remerge:
            seg = remerge(seg, scan.depth, scan.K, cfg.refine, ransac=ransac)
        else:
            seg = absorb_fragments(seg, scan.depth, scan.K, cfg.refine, ransac=ransac)
        if cfg.refine.crease_after_verify:  # the merged faces host strips along their creases
            cut = split_crease_strips(seg, scan.depth, scan.K, cfg.refine, ransac=ransac or RansacConfig())
            if cut is not seg and cfg.refine.remerge:
                cut = remerge(cut, scan.depth, scan.K, cfg.refine, ransac=ransac)
            seg = cut
    # last: an instance that no one primitive explains holds two surfaces (docs/segmentation.md)
    seg = split_unexplained(seg, scan.depth, scan.K, cfg.verify, ransac)
    return without_flying(seg, scan.depth, scan.K, cfg.flying_max_share)


def without_flying(
    seg: Segmentation, depth: np.ndarray, K: np.ndarray, max_share: float, pick: PickConfig | None = None
) -> Segmentation:
    """``seg`` without the instances more than ``max_share`` of whose valid pixels (depth > 0) are flying pixels
    (`v2c.pick.flying_mask` with ``pick``, default `PickConfig()`): their pixels become background; every instance
    keeps its id (and with it its seeded random draws downstream), its label and its score. ``seg`` itself when
    none is."""
    if max_share >= 1.0:
        return seg
    inst = np.asarray(seg.instances)
    d = np.asarray(depth, np.float64)
    valid = d > 0
    fly = flying_mask(d, K, pick or PickConfig())
    n_ids = len(seg.labels)
    n = np.bincount(inst[valid].ravel(), minlength=n_ids)
    f = np.bincount(inst[valid & fly].ravel(), minlength=n_ids)
    drop = (n > 0) & (f > max_share * n)
    drop[0] = False
    if not drop.any():
        return seg
    return replace(seg, instances=np.where(drop[inst], 0, inst))


def instances_from_prediction(
    scan: Scan,
    probs: np.ndarray,
    bnd: np.ndarray,
    cfg: InstanceConfig,
    feat: np.ndarray | None = None,
    part: np.ndarray | None = None,
) -> Segmentation:
    """Instances of a scan from the network's class probabilities (18, H, W) and boundary probability (H, W).

    feat: the network input features (9, H, W), for the optional depth / normal boundary evidence of ``cfg``;
    part: (H, W) bool part pixels that stand in for mask.png when the scan has none."""
    labels = probs.argmax(axis=0).astype(np.uint8)
    region = None
    mask = scan.mask if scan.mask is not None else part
    if mask is not None or scan.roi is not None:
        region = scan.roi_mask()
        if mask is not None:
            region &= mask
            # with a part mask, a masked pixel is part even where the network says background
            fg = probs[1:].argmax(axis=0).astype(np.uint8) + 1
            labels = np.where(region, fg, 0).astype(np.uint8)
    evidence = feature_evidence(feat, cfg) if feat is not None else None
    return extract_instances(
        labels,
        bnd,
        region=region,
        probs=probs,
        cfg=cfg,
        method="learned",
        evidence=evidence,
        unmeasured=np.asarray(scan.depth) <= 0,
    )
