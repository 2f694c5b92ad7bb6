"""The 18-label scheme of SCAN_FORMAT.md: primitive type x view-corrected axis class.

Label 0 is background, 1-16 are (plane, cylinder, cone, torus) x (X, Y, Z, unaligned), 17 is sphere,
255 marks non-analytic faces (ignored in losses and metrics).
"""

from __future__ import annotations

from enum import Enum

import numpy as np

BACKGROUND = 0
SPHERE_LABEL = 17
IGNORE = 255
NUM_CLASSES = 18

#: Angle under which a primitive axis counts as aligned with a model axis (degrees), SCAN_FORMAT.md.
AXIS_ALIGN_TOL_DEG = 1.5


class PrimitiveType(str, Enum):  # noqa: UP042 - StrEnum would change str() of a member (its value, not its name)
    """The five analytic surface types; the value is the name used in primitives.json and labels."""

    PLANE = "plane"
    CYLINDER = "cylinder"
    CONE = "cone"
    TORUS = "torus"
    SPHERE = "sphere"


class AxisClass(str, Enum):  # noqa: UP042 - as PrimitiveType
    """Axis class of a primitive: aligned with the part's X, Y or Z axis, or U (unaligned)."""

    X = "X"
    Y = "Y"
    Z = "Z"
    U = "U"  # unaligned


_AXIS_TYPES = (PrimitiveType.PLANE, PrimitiveType.CYLINDER, PrimitiveType.CONE, PrimitiveType.TORUS)
_AXIS_ORDER = (AxisClass.X, AxisClass.Y, AxisClass.Z, AxisClass.U)


def label_of(ptype: PrimitiveType | str, axis: AxisClass | str | None) -> int:
    """18-class label of a primitive type and axis class (axis ignored for spheres)."""
    ptype = PrimitiveType(ptype)
    if ptype is PrimitiveType.SPHERE:
        return SPHERE_LABEL
    if axis is None:
        raise ValueError(f"{ptype.value} needs an axis class")
    return 1 + 4 * _AXIS_TYPES.index(ptype) + _AXIS_ORDER.index(AxisClass(axis))


def type_axis_of(label: int) -> tuple[PrimitiveType, AxisClass | None]:
    """Inverse of `label_of` for labels 1..17."""
    label = int(label)
    if label == SPHERE_LABEL:
        return PrimitiveType.SPHERE, None
    if not 1 <= label <= 16:
        raise ValueError(f"label {label} is not a primitive label (1..17)")
    k = label - 1
    return _AXIS_TYPES[k // 4], _AXIS_ORDER[k % 4]


def axis_class(axis: np.ndarray, axes_cam: np.ndarray, tol_deg: float = AXIS_ALIGN_TOL_DEG) -> AxisClass:
    """Axis class of a unit direction against the part frame.

    axis: (3,) direction (sign ignored); axes_cam: (3, 3) rows = the part's X, Y, Z unit axes, same frame.
    """
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    cos = np.abs(np.asarray(axes_cam, float) @ a)
    k = int(np.argmax(cos))
    if cos[k] >= np.cos(np.deg2rad(tol_deg)):
        return _AXIS_ORDER[k]
    return AxisClass.U


#: Lookup tables for vectorised use: TYPE_OF_LABEL[label] -> index into PrimitiveType order (-1 = none).
TYPE_NAMES = [t.value for t in PrimitiveType]
TYPE_OF_LABEL = np.full(256, -1, np.int16)
AXIS_OF_LABEL = np.full(256, -1, np.int16)
for _lab in range(1, 18):
    _t, _a = type_axis_of(_lab)
    TYPE_OF_LABEL[_lab] = TYPE_NAMES.index(_t.value)
    AXIS_OF_LABEL[_lab] = -1 if _a is None else _AXIS_ORDER.index(_a)
