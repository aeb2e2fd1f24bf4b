"""Record layout of the input ring between the web and tick processes.

Every record is a row of little-endian float64 (times in engine seconds: perf_counter
minus the service's start).

Input ring (web -> tick), one row per accepted horse or saddle frame::

    0 producer   id of the producer connection (replay uses its own id)
    1 t          the producer's time of the frame
    2 received   engine time the web process decoded it
    3 kind       InputKind: 0 horse frame, 1 saddle sample
    4..          horse: the horse channels in channels.HORSE order, in service length units;
                 saddle: the six channels.SADDLE values (service length units, degrees;
                 NaN for an axis the producer left out), the rest unused

Output ring (tick -> web): one row per tick, its layout in ``riderlive.realtime.record``
(:class:`~riderlive.realtime.record.RecordLayout`, made from the tick's setup).
"""

from __future__ import annotations

import enum

from riderlive.channels import HORSE_NAMES, RIDER_NAMES

N_HORSE = len(HORSE_NAMES)
N_RIDER = len(RIDER_NAMES)


class InputKind(enum.IntEnum):
    """What an input record carries (its ``kind`` column)."""

    HORSE = 0
    SADDLE = 1


IN_PRODUCER, IN_T, IN_RECEIVED, IN_KIND, IN_VALUES = 0, 1, 2, 3, 4
INPUT_WIDTH = IN_VALUES + N_HORSE

INPUT_CAPACITY = 4096
OUTPUT_CAPACITY = 4096
