"""Rider and horse poses of tick records, solved once per record for every consumer.

``/ws/rider`` (``bones``, ``pose``) and VMC out both need the skeletons posed from the
same records; :class:`RecordPoses` solves each (record, skeleton) at most once and
keeps the last few. Records carry lengths in the service unit; the skeletons are in
metres: converted here, at this edge, by :mod:`riderlive.units`.
"""

from __future__ import annotations

import numpy as np

from riderlive.realtime.record import RecordLayout
from riderlive.skeleton import horse_pose, rider_pose
from riderlive.skeleton.rig import Pose
from riderlive.units import horse_lengths, metres_per_unit, rider_lengths

KEEP = 8
"""Records remembered per skeleton (a publish pass looks at the newest few)."""


class RecordPoses:
    def __init__(self, length_scale: float) -> None:
        factor = metres_per_unit(length_scale)
        self._rider_lengths, self._horse_lengths = rider_lengths(factor), horse_lengths(factor)
        self._rider: dict[int, Pose] = {}
        self._horse: dict[int, Pose] = {}

    def rider(self, record: np.ndarray) -> Pose:
        seq = RecordLayout.seq.count(record)
        pose = self._rider.get(seq)
        if pose is None:
            pose = rider_pose(self._rider_lengths.to_metres(RecordLayout.rider.of(record).tolist()))
            self._remember(self._rider, seq, pose)
        return pose

    def horse(self, record: np.ndarray) -> Pose:
        seq = RecordLayout.seq.count(record)
        pose = self._horse.get(seq)
        if pose is None:
            pose = horse_pose(self._horse_lengths.to_metres(RecordLayout.horse.of(record).tolist()))
            self._remember(self._horse, seq, pose)
        return pose

    @staticmethod
    def _remember(cache: dict[int, Pose], seq: int, pose: Pose) -> None:
        cache[seq] = pose
        if len(cache) > KEEP:
            del cache[next(iter(cache))]
