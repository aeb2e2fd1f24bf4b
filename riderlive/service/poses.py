"""Rider and horse poses of tick records, solved once per record for every consumer.

``/ws/rider`` (``bones``, ``pose``) and VMC out both need the skeletons posed from the
same records; :class:`RecordPoses` solves each (record, skeleton) at most once and
keeps the last few. Records carry lengths in the service unit; the skeletons are in
metres (``length_scale / DEFAULT_SCALE`` converts).
"""

from __future__ import annotations

import numpy as np

from riderlive.channels import HORSE, RIDER, Kind
from riderlive.horse import DEFAULT_SCALE
from riderlive.realtime.record import RecordLayout
from riderlive.skeleton import horse_pose, rider_pose
from riderlive.skeleton.rig import Pose

_RIDER_LENGTHS = [i for i, c in enumerate(RIDER) if c.kind is Kind.TRANSLATION]
_HORSE_LENGTHS = [i for i, c in enumerate(HORSE) if c.kind is Kind.TRANSLATION]
KEEP = 8
"""Records remembered per skeleton (a publish pass looks at the newest few)."""


class RecordPoses:
    def __init__(self, length_scale: float) -> None:
        self.to_metres = length_scale / DEFAULT_SCALE
        self._rider: dict[int, Pose] = {}
        self._horse: dict[int, Pose] = {}

    def _values(self, values: np.ndarray, lengths: list[int]) -> list[float]:
        if self.to_metres != 1.0:
            values = values.copy()
            values[lengths] *= self.to_metres
        return values.tolist()  # type: ignore[no-any-return]

    def rider(self, record: np.ndarray) -> Pose:
        seq = RecordLayout.seq.count(record)
        pose = self._rider.get(seq)
        if pose is None:
            pose = rider_pose(self._values(RecordLayout.rider.of(record), _RIDER_LENGTHS))
            self._remember(self._rider, seq, pose)
        return pose

    def horse(self, record: np.ndarray) -> Pose:
        seq = RecordLayout.seq.count(record)
        pose = self._horse.get(seq)
        if pose is None:
            pose = horse_pose(self._values(RecordLayout.horse.of(record), _HORSE_LENGTHS))
            self._remember(self._horse, seq, pose)
        return pose

    @staticmethod
    def _remember(cache: dict[int, Pose], seq: int, pose: Pose) -> None:
        cache[seq] = pose
        if len(cache) > KEEP:
            del cache[next(iter(cache))]
