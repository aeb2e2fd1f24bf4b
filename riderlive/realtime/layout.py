"""Record layout of the input ring between the web and tick processes.

Every record is a row of little-endian float64 (times in engine seconds: perf_counter
minus the service's start).

Input ring (web -> tick), one row per accepted horse or saddle frame::

    0 producer   id of the producer connection (replay uses its own id)
    1 t          the producer's time of the frame
    2 received   engine time the web process decoded it
    3 kind       InputKind: 0 horse frame, 1 saddle sample
    4 rebased    1: the service re-anchored the producer's clock at this frame (a pause, a
                 resume, a step back: ``service/clocks.py``), 0 otherwise
    5..          horse: the horse channels in channels.HORSE order, in service length units;
                 saddle: the six channels.SADDLE values (service length units, degrees;
                 NaN for an axis the producer left out), the rest unused

Output ring (tick -> web): one row per tick, its layout in ``riderlive.realtime.record``
(:class:`~riderlive.realtime.record.RecordLayout`, made from the tick's setup).
"""

from __future__ import annotations

import enum
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from riderlive.channels import HORSE_NAMES, RIDER_NAMES

N_HORSE = len(HORSE_NAMES)
N_RIDER = len(RIDER_NAMES)


class InputKind(enum.IntEnum):
    """What an input record carries (its ``kind`` column)."""

    HORSE = 0
    SADDLE = 1


IN_PRODUCER, IN_T, IN_RECEIVED, IN_KIND, IN_REBASED, IN_VALUES = 0, 1, 2, 3, 4, 5
INPUT_WIDTH = IN_VALUES + N_HORSE


class InputRecord(NamedTuple):
    """One input ring row, named (see the module docstring); :meth:`row` packs it, :meth:`of` reads one."""

    producer: int
    t: float
    received: float
    values: list[float]
    kind: InputKind = InputKind.HORSE
    rebased: bool = False

    def row(self) -> np.ndarray:
        row = np.full(INPUT_WIDTH, np.nan)
        row[[IN_PRODUCER, IN_T, IN_RECEIVED, IN_KIND, IN_REBASED]] = (
            self.producer,
            self.t,
            self.received,
            self.kind,
            1.0 if self.rebased else 0.0,
        )
        row[IN_VALUES : IN_VALUES + len(self.values)] = self.values
        return row

    @classmethod
    def of(cls, row: Sequence[float] | np.ndarray) -> InputRecord:
        return cls(
            int(row[IN_PRODUCER]),
            float(row[IN_T]),
            float(row[IN_RECEIVED]),
            np.asarray(row[IN_VALUES:], dtype=np.float64).tolist(),
            InputKind(int(row[IN_KIND])),
            bool(row[IN_REBASED] == 1.0),
        )


INPUT_CAPACITY = 4096
OUTPUT_CAPACITY = 4096
