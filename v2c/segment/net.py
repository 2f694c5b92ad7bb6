"""The segmentation network: a small U-Net with a label head (18 classes) and a face-boundary head.

CPU-sized: 1.23 M parameters at the default widths 16-128 (CPU training), 2.76 M at the shipped weights' 24-192
(a weights file carries its widths). Input: the (C, H, W) stack of ``v2c.segment.data``; output at
full resolution: label logits (18, H, W) and boundary logits (1, H, W). H and W need not be multiples of 16: the
input is padded and the output cropped.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from v2c.labels import NUM_CLASSES
from v2c.segment.data import NUM_INPUTS


@dataclass(frozen=True)
class NetConfig:
    """U-Net architecture: input channels, channels per level and output classes."""

    in_channels: int = NUM_INPUTS
    widths: tuple[int, ...] = (16, 32, 64, 128, 128)  # channels per level; level k works at 1 / 2^k resolution
    num_classes: int = NUM_CLASSES


def _block(cin: int, cout: int) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(cin, cout, 3, padding=1, bias=False),
        nn.BatchNorm2d(cout),
        nn.ReLU(inplace=True),
        nn.Conv2d(cout, cout, 3, padding=1, bias=False),
        nn.BatchNorm2d(cout),
        nn.ReLU(inplace=True),
    )


class UNet(nn.Module):
    """U-Net: encoder of ``len(widths)`` levels (max-pool 2x between), bilinear-upsampling decoder, two heads."""

    def __init__(self, cfg: NetConfig = NetConfig()) -> None:
        super().__init__()
        self.cfg = cfg
        w = cfg.widths
        self.enc = nn.ModuleList([_block(cfg.in_channels, w[0])] + [_block(w[i - 1], w[i]) for i in range(1, len(w))])
        self.dec = nn.ModuleList([_block(w[i + 1] + w[i], w[i]) for i in range(len(w) - 1)])
        self.head_label = nn.Conv2d(w[0], cfg.num_classes, 1)
        self.head_boundary = nn.Conv2d(w[0], 1, 1)

    @property
    def stride(self) -> int:
        """Total downsampling of the encoder (pixels); `forward` pads the input to multiples of it."""
        return 2 ** (len(self.cfg.widths) - 1)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """x: (B, C, H, W) -> (label logits (B, 18, H, W), boundary logits (B, 1, H, W))."""
        h, w = x.shape[-2:]
        s = self.stride
        ph, pw = (-h) % s, (-w) % s
        if ph or pw:
            x = F.pad(x, (0, pw, 0, ph), mode="replicate")
        skips = []
        for i, blk in enumerate(self.enc):
            if i:
                x = F.max_pool2d(x, 2)
            x = blk(x)
            skips.append(x)
        for i in range(len(self.dec) - 1, -1, -1):
            x = F.interpolate(x, size=skips[i].shape[-2:], mode="bilinear", align_corners=False)
            x = self.dec[i](torch.cat([x, skips[i]], dim=1))
        lab, bnd = self.head_label(x), self.head_boundary(x)
        return lab[..., :h, :w], bnd[..., :h, :w]


def save_weights(model: UNet, path: str | Path, meta: dict) -> None:
    """Save the state dict (fp32 -> fp16 to halve the file) with the config and ``meta`` (data, schedule)."""
    sd = {k: (v.half() if v.is_floating_point() else v) for k, v in model.state_dict().items()}
    cfg = asdict(model.cfg)
    torch.save({"state_dict": sd, "config": cfg, "meta": meta}, Path(path))


def load_weights(path: str | Path, device: str = "cpu") -> tuple[UNet, dict]:
    """Load a model saved by ``save_weights`` (eval mode, fp32). Returns (model, meta)."""
    ck = torch.load(Path(path), map_location=device, weights_only=True)
    cfg = dict(ck["config"])
    cfg["widths"] = tuple(cfg["widths"])
    model = UNet(NetConfig(**cfg))
    model.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in ck["state_dict"].items()})
    model.eval()
    return model, ck.get("meta", {})


def bf16_supported() -> bool:
    """True when this CPU has native bf16 (avx512_bf16 / AMX): bf16 autocast is then ~2-3x faster."""
    try:
        return bool(torch.backends.mkldnn.is_available() and torch.ops.mkldnn._is_mkldnn_bf16_supported())
    except (AttributeError, RuntimeError):
        return False
