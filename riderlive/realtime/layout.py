"""Record layouts of the shared-memory rings between the web and tick processes.

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

Output ring (tick -> web), one row per tick::

    0 seq        tick number (0, 1, 2...; a gap means skipped deadlines)
    1 engine_t   the tick's deadline, engine seconds
    2 source_t   source time shown (producer time for input, engine time otherwise)
    3 driver     Driver code: 0 procedural, 1 input, 2 neutral
    4 producer   producer id for input, -1 otherwise
    5 input_rx   engine receive time of the newest input frame taken this tick, or -1
    6 done       engine time the tick finished computing
    7 lateness   seconds the tick woke after its deadline
    8..13        the saddle pose of this tick's horse (channels.SADDLE, service length units)
    14..18       the saddle estimate (ESTIMATE_FIELDS; all NaN unless a saddle input drives)
    19..         horse channels (channels.HORSE order), then rider channels (channels.RIDER)
"""

from __future__ import annotations

import enum

from riderlive.channels import HORSE_NAMES, RIDER_NAMES, SADDLE_NAMES
from riderlive.realtime.pacing import LATENESS_BUCKETS

N_HORSE = len(HORSE_NAMES)
N_RIDER = len(RIDER_NAMES)
N_SADDLE = len(SADDLE_NAMES)


class InputKind(enum.IntEnum):
    """What an input record carries (its ``kind`` column)."""

    HORSE = 0
    SADDLE = 1


IN_PRODUCER, IN_T, IN_RECEIVED, IN_KIND, IN_VALUES = 0, 1, 2, 3, 4
INPUT_WIDTH = IN_VALUES + N_HORSE

(OUT_SEQ, OUT_ENGINE_T, OUT_SOURCE_T, OUT_DRIVER, OUT_PRODUCER, OUT_INPUT_RX, OUT_DONE, OUT_LATENESS) = range(8)
OUT_SADDLE = 8
ESTIMATE_FIELDS: tuple[str, ...] = ("lock", "gait", "stride_hz", "phase", "age")
"""The saddle estimate in a record: lock and gait as codes (``riderlive.realtime.saddle_input``),
stride frequency (Hz), phase (0-1), age (s since the last sample)."""
OUT_ESTIMATE = OUT_SADDLE + N_SADDLE
OUT_HORSE = OUT_ESTIMATE + len(ESTIMATE_FIELDS)
OUT_RIDER = OUT_HORSE + N_HORSE
OUTPUT_WIDTH = OUT_RIDER + N_RIDER

INPUT_CAPACITY = 4096
OUTPUT_CAPACITY = 4096

COUNTERS: tuple[str, ...] = (
    "ticks",
    "overruns",
    "skipped",
    "lateness_sum",
    "lateness_max",
    "step_max",
    "input_frames",
    "input_lapped",
    "input_out_of_order",
    "step_errors",
    "nonfinite_outputs",
    "physics_errors",
    "physics_skipped_steps",
    "state_resets",
    "outputs_clamped",
    "hands_full_reach",
    "realtime",
    "alive",
    "saddle_samples",
    "saddle_missing",
    "saddle_empty",
    "saddle_gaps",
    "saddle_glitches",
    "saddle_rebases",
    "saddle_locks",
    "saddle_losses",
    "saddle_stale",
    "phase_locked",
    "phase_lead",
    "phase_margin",
    "phase_resultant",
    "phase_slews",
    "phase_locks",
    "phase_losses",
    *(f"lateness_bucket_{i}" for i in range(len(LATENESS_BUCKETS) + 1)),
)
"""Tick counters in shared memory (written by the tick process only)."""
