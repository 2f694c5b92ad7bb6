"""Segmentation stage: surface instances with 18-class labels (`types.Segmentation`), the ground-truth oracle,
the learned and geometric segmenters, and the 2D edge graph of an instance map (`graph`)."""

from __future__ import annotations

import importlib
import warnings

from v2c.segment.types import Segmentation

#: method name -> (module, function) of each segmenter; modules are imported on first use.
SEGMENTERS: dict[str, tuple[str, str]] = {
    "oracle": ("v2c.segment.oracle", "segment_oracle"),
    "learned": ("v2c.segment.learned", "segment_learned"),
    "geometric": ("v2c.segment.geometric", "segment_geometric"),
}


def segment(scan, method: str = "oracle", **kwargs) -> Segmentation:
    """Segment ``scan`` with the named method ("oracle", "learned", "geometric").

    "learned" with no weights named and none shipped falls back to the geometric
    segmenter with a warning; the returned `Segmentation.method` says which one ran.
    Raises ValueError for an unknown method or one whose module is not available yet.
    """
    if method == "learned" and not _learned_weights_found(kwargs):
        warnings.warn("no learned segmentation weights found: using the geometric segmenter instead", stacklevel=2)
        method = "geometric"
        kwargs = {k: v for k, v in kwargs.items() if k not in ("config", "weights")}
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


def _learned_weights_found(kwargs: dict) -> bool:
    """True when the learned segmenter has a weights file: ``weights=``, ``config.weights`` or the shipped one."""
    from v2c.segment.learned import weights_available

    given = kwargs.get("weights") or getattr(kwargs.get("config"), "weights", None)
    # Weights named explicitly are never swapped for the fallback: a wrong path is an error the user must see.
    return given is not None or weights_available()


__all__ = ["SEGMENTERS", "Segmentation", "segment"]
