"""Names of the generator's part families and which of them training may see (no heavy imports: the CLI reads it).

`PROCEDURAL_FAMILIES` are the six hand-written families of parts.py (today's default mix), `FEATURE_FAMILIES` the
feature-based ones of features.py. `LEAVE_OUT_FAMILIES` are never used for training or for choosing a threshold:
the unseen benchmark suite is built on them. `TRAIN_FAMILIES` are all the others (plus the corpus's train split,
family "cad", which is not a generator family).
"""

from __future__ import annotations

PROCEDURAL_FAMILIES: tuple[str, ...] = ("block", "shaft", "flange", "knob", "turned", "bracket")
FEATURE_FAMILIES: tuple[str, ...] = (
    "feat_prismatic",
    "feat_plate",
    "feat_turned",
    "feat_hex",
    "feat_knob",
    "feat_block",
)
#: Families no training run and no threshold choice may see (the unseen suite's generator families).
LEAVE_OUT_FAMILIES: tuple[str, ...] = ("feat_hex", "feat_knob", "feat_block")
#: Families training may draw from: every generator family that is not left out.
TRAIN_FAMILIES: tuple[str, ...] = tuple(
    f for f in (*PROCEDURAL_FAMILIES, *FEATURE_FAMILIES) if f not in LEAVE_OUT_FAMILIES
)
#: Names `v2c synth --families` expands to a group of families.
FAMILY_GROUPS: dict[str, tuple[str, ...]] = {
    "procedural": PROCEDURAL_FAMILIES,
    "features": tuple(f for f in FEATURE_FAMILIES if f not in LEAVE_OUT_FAMILIES),
    "train": TRAIN_FAMILIES,
    "leave-out": LEAVE_OUT_FAMILIES,
}
