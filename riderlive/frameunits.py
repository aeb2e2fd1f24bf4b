"""The length unit of a frame file: recorded beside it, read by every command.

A frame file's lengths are in *some* unit; the rules need thesis rig units, the tail
physics metres. The unit travels in a JSON sidecar with the file's stem
(``trot.csv`` -> ``trot.json``): ``"length_scale"`` is thesis rig units per the file's
length unit (25 for metres, 1 for thesis rig units). ``riderlive horse`` and recorded
takes write it; ``bake``, ``plot --bake``, ``tail``, replays and the examples read it.

Resolution (:func:`resolve_scale`): an explicit ``--scale`` wins (with a warning when
it contradicts the sidecar); then the sidecar; then 1 (thesis rig units), with a
warning when the file looks like metres (hoof heights of a horse in metres stay under
~2; in rig units they reach 2.5-7.5).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import orjson

from riderlive.channels import Kind, is_known, lookup
from riderlive.framefile import FrameTable

METRES = 25.0
"""``length_scale`` of a file in metres (``riderlive.horse.DEFAULT_SCALE``)."""
RIG_UNITS = 1.0
"""``length_scale`` of a file in thesis rig units: the default when nothing is recorded."""
HOOF_HEIGHTS = ("lfHoof.ty", "rfHoof.ty", "lbHoof.ty", "rbHoof.ty")
"""The channels that tell a take in metres (:func:`looks_like_metres`)."""


def sidecar_of(path: str) -> Path | None:
    """The sidecar of frame file ``path`` (None for stdin)."""
    return None if path == "-" else Path(path).with_suffix(".json")


def recorded_scale(path: str) -> float | None:
    """The ``length_scale`` recorded beside ``path``, or None."""
    sidecar = sidecar_of(path)
    try:
        meta: Any = orjson.loads(sidecar.read_bytes()) if sidecar else None
    except (OSError, orjson.JSONDecodeError):
        return None
    value = meta.get("length_scale") if isinstance(meta, dict) else None
    if isinstance(value, bool) or not isinstance(value, int | float) or not 0.0 < value < float("inf"):
        return None
    return float(value)


def record_scale(path: str, length_scale: float, **meta: object) -> None:
    """Write (or update) the sidecar of ``path`` with its ``length_scale``."""
    sidecar = sidecar_of(path)
    if sidecar is None:
        return
    try:
        current: Any = orjson.loads(sidecar.read_bytes())
    except (OSError, orjson.JSONDecodeError):
        current = {}
    data = {**(current if isinstance(current, dict) else {}), **meta, "length_scale": length_scale}
    sidecar.write_bytes(orjson.dumps(data, option=orjson.OPT_INDENT_2))


def looks_like_metres(table: FrameTable) -> bool:
    """Hoof heights that stay within -0.05..2 and rise above 1 cm: a horse in metres."""
    columns = [table.column(name) for name in HOOF_HEIGHTS if name in table.names]
    if not columns or len(table) == 0:
        return False
    heights = np.concatenate(columns)
    return bool(heights.min() >= -0.05 and 0.01 < heights.max() <= 2.0)


def resolve_scale(path: str, table: FrameTable, flag: float | None) -> tuple[float, str | None]:
    """(length scale to use, a warning or None); see the module docstring."""
    recorded = recorded_scale(path)
    if flag is not None:
        if recorded is not None and recorded != flag:
            return flag, f"--scale {flag:g} overrides length_scale {recorded:g} recorded in {sidecar_of(path)}"
        return flag, None
    if recorded is not None:
        return recorded, None
    if looks_like_metres(table):
        return RIG_UNITS, (
            f"{path} looks like metres (hoof heights under 2) but records no length_scale; "
            f"reading it in thesis rig units: pass --scale {METRES:g} if it is in metres"
        )
    return RIG_UNITS, None


def rescale_lengths(table: FrameTable, factor: float) -> FrameTable:
    """A copy of ``table`` with every length channel multiplied by ``factor``."""
    if factor == 1.0:
        return table
    values = table.values.copy()
    for j, name in enumerate(table.names):
        if is_known(name) and lookup(name).kind is Kind.TRANSLATION:
            values[:, j] *= factor
    return dataclasses.replace(table, values=values)
