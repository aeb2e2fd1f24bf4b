"""Reading the fit's takes (the I/O edge): horse takes as ``bake`` reads them, rider takes and mocap.

- A horse take: CSV, JSONL or Parquet with the rules' thirteen horse channels (or a saddle
  take, rebuilt into a horse as ``bake`` does); its length unit from its sidecar, an explicit
  ``--scale`` or the hoof heights (:func:`riderlive.frameunits.resolve_scale`, whose warning
  is returned).
- A rider take: CSV, JSONL or Parquet of rider channels (``channels.RIDER``; the rider parts
  and the saddle, if present, are left out and said so); lengths in the horse take's unit
  unless its sidecar records its own ``length_scale`` (then converted). Or a BVH, mapped to
  rider channels by a bone map (:mod:`riderlive.fit.bonemap`), lengths converted from the
  map's unit.
- Times must increase; a take without ``t`` runs at ``rate`` Hz. Each file's sha256 goes
  into the report and the preset's provenance.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from riderlive.channels import RIDER_INDEX, RIDER_PART_NAMES, SADDLE_NAMES, Kind, lookup
from riderlive.fit.problem import HORSE_READ, FitInputError, HorseTake, RiderTake
from riderlive.framefile import FrameTable, read_frames
from riderlive.frameunits import recorded_scale, resolve_scale
from riderlive.rules.kuhnel2003 import RULE_INPUTS

DEFAULT_RATE = 120.0
"""Hz of a take without a ``t`` column."""
IGNORED: frozenset[str] = frozenset((*RIDER_PART_NAMES, *SADDLE_NAMES))
"""Known channels a rider take may carry that the fit does not read."""


def sha256(path: str) -> str:
    digest = hashlib.sha256()
    with Path(path).open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _times(table: FrameTable, path: str, rate: float) -> np.ndarray:
    t = table.times(rate)
    if len(t) < 2:
        raise FitInputError(f"{path}: {len(t)} frame(s): a take needs at least two")
    if not np.all(np.diff(t) > 0.0):
        raise FitInputError(f"{path}: the t column must increase from frame to frame")
    return t


def read_horse(path: str, scale: float | None = None, rate: float = DEFAULT_RATE) -> tuple[HorseTake, list[str]]:
    """The horse take at ``path`` and the reader's notes (a unit warning)."""
    table = read_frames(path)
    notes: list[str] = []
    from riderlive.saddle.takes import horse_take, is_saddle_take

    if is_saddle_take(table):
        from riderlive.horse import DEFAULT_SCALE

        table, _ = horse_take(table, rate=rate)
        length_scale = scale if scale is not None else DEFAULT_SCALE
        notes.append(f"{path}: a saddle take, rebuilt into a horse (docs/saddle.md)")
    else:
        missing = [n for n in RULE_INPUTS if n not in table.names]
        if missing:
            raise FitInputError(f"{path}: not a horse take: missing {', '.join(missing)}")
        length_scale, warning = resolve_scale(path, table, scale)
        if warning and scale is None:  # a guessed unit would fit wrong numbers: the user must say
            raise FitInputError(
                f"{warning.replace('reading it in thesis rig units: ', '')} (or record it in the sidecar)"
            )
        if warning:
            notes.append(warning)
    t = _times(table, path, rate)
    columns = {n: np.ascontiguousarray(table.column(n)) for n in HORSE_READ if n in table.names}
    for name, column in columns.items():
        if not np.all(np.isfinite(column)):
            raise FitInputError(f"{path}: {name} has {int((~np.isfinite(column)).sum())} non-finite value(s)")
    return HorseTake(Path(path).name, t, columns, length_scale, sha256(path)), notes


def read_rider(
    path: str, horse_scale: float, rate: float = DEFAULT_RATE, bonemap: str | None = None
) -> tuple[RiderTake, list[str]]:
    """The rider take at ``path`` in the horse's length unit (``horse_scale`` rig units) and the notes."""
    if Path(path).suffix.lower() == ".bvh":
        from riderlive.fit.bonemap import read_bvh_rider

        return read_bvh_rider(path, horse_scale, bonemap)
    table = read_frames(path)
    notes: list[str] = []
    unknown = [n for n in table.names if n not in RIDER_INDEX and n not in IGNORED]
    if unknown:
        raise FitInputError(f"{path}: not rider channels: {', '.join(unknown)} (channels.RIDER lists the known ones)")
    names = tuple(n for n in table.names if n in RIDER_INDEX)
    left_out = [n for n in table.names if n in IGNORED]
    if left_out:
        notes.append(f"{path}: left out (not fitted): {', '.join(left_out)}")
    if not names:
        raise FitInputError(f"{path}: no rider channel to fit")
    t = _times(table, path, rate)
    values = np.column_stack([table.column(n) for n in names]).astype(np.float64)
    own = recorded_scale(path)
    if own is not None and own != horse_scale:
        factor = own / horse_scale
        for c, name in enumerate(names):
            if lookup(name).kind is Kind.TRANSLATION:
                values[:, c] *= factor
        notes.append(f"{path}: lengths converted from length_scale {own:g} to the horse's {horse_scale:g}")
    elif own is None:
        notes.append(f"{path}: no length_scale recorded: lengths read in the horse take's unit")
    return RiderTake(Path(path).name, t, names, values, sha256(path)), notes
