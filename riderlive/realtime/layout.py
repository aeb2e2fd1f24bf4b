"""Record layouts of the shared-memory rings between the web and tick processes.

Every record is a row of little-endian float64 (times in engine seconds: perf_counter
minus the service's start).

Input ring (web -> tick), one row per accepted horse frame::

    0 producer   id of the producer connection (replay uses its own id)
    1 t          the producer's time of the frame
    2 received   engine time the web process decoded it
    3..          the horse channels in channels.HORSE order, in service length units

Output ring (tick -> web), one row per tick::

    0 seq        tick number (0, 1, 2...; a gap means skipped deadlines)
    1 engine_t   the tick's deadline, engine seconds
    2 source_t   source time shown (producer time for input, engine time otherwise)
    3 driver     Driver code: 0 procedural, 1 input, 2 neutral
    4 producer   producer id for input, -1 otherwise
    5 input_rx   engine receive time of the newest input frame taken this tick, or -1
    6 done       engine time the tick finished computing
    7 lateness   seconds the tick woke after its deadline
    8..          horse channels (channels.HORSE order), then rider channels (channels.RIDER)
"""

from __future__ import annotations

from riderlive.channels import HORSE_NAMES, RIDER_NAMES
from riderlive.realtime.pacing import LATENESS_BUCKETS

N_HORSE = len(HORSE_NAMES)
N_RIDER = len(RIDER_NAMES)

IN_PRODUCER, IN_T, IN_RECEIVED, IN_VALUES = 0, 1, 2, 3
INPUT_WIDTH = IN_VALUES + N_HORSE

(OUT_SEQ, OUT_ENGINE_T, OUT_SOURCE_T, OUT_DRIVER, OUT_PRODUCER, OUT_INPUT_RX, OUT_DONE, OUT_LATENESS) = range(8)
OUT_HORSE = 8
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
    *(f"lateness_bucket_{i}" for i in range(len(LATENESS_BUCKETS) + 1)),
)
"""Tick counters in shared memory (written by the tick process only)."""
