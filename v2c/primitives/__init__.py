"""Analytic primitives (plane, cylinder, cone, sphere, torus) in the camera frame, metres, radians.

``from_dict`` reads the primitives.json form ``{"type": ..., "params": {...}}``; every primitive's ``to_dict``
writes it back.
"""

from __future__ import annotations

from typing import Any

from v2c.primitives.base import Primitive
from v2c.primitives.cone import Cone
from v2c.primitives.cylinder import Cylinder
from v2c.primitives.plane import Plane
from v2c.primitives.sphere import Sphere
from v2c.primitives.torus import Torus

#: primitives.json type name -> class.
PRIMITIVE_CLASSES: dict[str, type[Primitive]] = {
    "plane": Plane,
    "cylinder": Cylinder,
    "cone": Cone,
    "sphere": Sphere,
    "torus": Torus,
}


def from_dict(d: dict[str, Any]) -> Primitive:
    """Primitive from ``{"type": ..., "params": {...}}``; ValueError for a non-analytic or unknown type."""
    t = str(d.get("type", ""))
    if t not in PRIMITIVE_CLASSES:
        raise ValueError(f"unknown or non-analytic primitive type {t!r}")
    return PRIMITIVE_CLASSES[t].from_params(d["params"])  # type: ignore[attr-defined]


__all__ = ["PRIMITIVE_CLASSES", "Cone", "Cylinder", "Plane", "Primitive", "Sphere", "Torus", "from_dict"]
