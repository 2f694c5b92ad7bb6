"""Segmentation stage: surface instances with 18-class labels (`types.Segmentation`), the ground-truth oracle,
the learned and geometric segmenters, and the 2D edge graph of an instance map (`graph`)."""

from __future__ import annotations

import importlib

from v2c.segment.types import Segmentation

#: method name -> (module, function) of each segmenter; modules are imported on first use.
SEGMENTERS: dict[str, tuple[str, str]] = {
    "oracle": ("v2c.segment.oracle", "segment_oracle"),
    "learned": ("v2c.segment.learned", "segment_learned"),
    "geometric": ("v2c.segment.geometric", "segment_geometric"),
}


def segment(scan, method: str = "oracle", **kwargs) -> Segmentation:
    """Segment ``scan`` with the named method ("oracle", "learned", "geometric").

    Raises ValueError for an unknown method or one whose module is not available yet.
    """
    if method not in SEGMENTERS:
        raise ValueError(f"unknown segmentation method {method!r}; choose from {', '.join(SEGMENTERS)}")
    mod_name, fn_name = SEGMENTERS[method]
    try:
        mod = importlib.import_module(mod_name)
    except ModuleNotFoundError as e:
        if e.name != mod_name:
            raise
        raise ValueError(f"segmentation method {method!r} is not available yet ({mod_name} is missing)") from e
    fn = getattr(mod, fn_name, None)
    if fn is None:
        raise ValueError(f"segmentation method {method!r}: {mod_name} has no function {fn_name}()")
    return fn(scan, **kwargs)


__all__ = ["SEGMENTERS", "Segmentation", "segment"]
