"""Segmentation stage: surface instances with 18-class labels (`types.Segmentation`), the ground-truth oracle,
the learned and geometric segmenters, and the 2D edge graph of an instance map (`graph`)."""

from __future__ import annotations

import importlib
import warnings
from typing import TYPE_CHECKING, Any

from v2c.choices import DEFAULT_SEGMENTATION
from v2c.segment.types import Segmentation

if TYPE_CHECKING:
    from v2c.geometry.config import RansacConfig
    from v2c.scan import Scan
    from v2c.segment.refine import RefineConfig

#: method name -> (module, function) of each segmenter; modules are imported on first use.
SEGMENTERS: dict[str, tuple[str, str]] = {
    "oracle": ("v2c.segment.oracle", "segment_oracle"),
    "learned": ("v2c.segment.learned", "segment_learned"),
    "geometric": ("v2c.segment.geometric", "segment_geometric"),
}
#: The segmenters that check their instances geometrically (`v2c.segment.refine`) and so take ``refine`` and
#: ``ransac``.
REFINING = ("learned",)
#: The segmentation every entry point uses unless told otherwise (`v2c.choices`).
DEFAULT_METHOD = DEFAULT_SEGMENTATION


def segment(
    scan: Scan,
    method: str = DEFAULT_METHOD,
    *,
    refine: RefineConfig | None = None,
    ransac: RansacConfig | None = None,
    **kwargs: Any,
) -> Segmentation:
    """Segment ``scan`` with the named method ("learned", "geometric", "oracle").

    refine: the geometric check of the instances (`v2c.segment.refine.RefineConfig`); ransac: the instance points,
    RANSAC and type-selection settings it fits with (`v2c.geometry.RansacConfig`; a `v2c.fit.FitConfig` is one,
    so the fit stage's settings can be handed down). Both reach the segmenters that refine (`REFINING`); None
    keeps the segmenter's own (the defaults). Other keyword arguments go to the segmenter (``weights``,
    ``config``).

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
    if method in REFINING:
        kwargs = kwargs | {"refine": refine, "ransac": ransac}
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


def _learned_weights_found(kwargs: dict[str, Any]) -> bool:
    """True when the learned segmenter has a weights file: ``weights=``, ``config.weights`` or the shipped one."""
    from v2c.segment.learned import weights_available

    config = kwargs.get("config")
    given = kwargs.get("weights") or (config.weights if config is not None else None)
    # Weights named explicitly are never swapped for the fallback: a wrong path is an error the user must see.
    return given is not None or weights_available()


__all__ = ["DEFAULT_METHOD", "REFINING", "SEGMENTERS", "Segmentation", "segment"]
