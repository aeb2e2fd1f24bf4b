"""A take's timecode and replaying from a timecode (riderlive/takes/stamp.py)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from riderlive import timecode as tc
from riderlive.takes.stamp import TakeTimecode, start_index, take_timecode
from riderlive.timecode import Rate, TimecodeError


def test_sidecar_round_trip() -> None:
    stamp = TakeTimecode(tc.parse("10:00:00;00", Rate.FPS_29_97_DF), Rate.FPS_29_97_DF, "producer")
    assert take_timecode(stamp.as_meta()) == stamp
    assert take_timecode({"rows": 3}) is None
    with pytest.raises(TimecodeError):
        take_timecode({"timecode": "10:00:00:00", "timecode_rate": "29.97df"})


def test_at_rate_is_the_same_instant() -> None:
    stamp = TakeTimecode(tc.parse("01:00:00:00", Rate.FPS_25), Rate.FPS_25, "host")
    assert stamp.at_rate(Rate.FPS_50).label == "01:00:00:00"
    # one hour of wall clock is 107892.1 frames at 29.97 DF: the frame labelled 01:00:00;00
    assert stamp.at_rate(Rate.FPS_29_97_DF).label == tc.format_frames(107_892, Rate.FPS_29_97_DF)


@given(st.integers(min_value=0, max_value=359), st.sampled_from([60.0, 120.0, 200.0]))
def test_start_is_within_half_a_row_of_the_label(frame: int, row_rate: float) -> None:
    rate = Rate.FPS_29_97_DF
    start = tc.parse("10:00:00;00", rate)
    t = 5.0 + np.arange(int(12 * row_rate)) / row_rate  # 12 s of rows; the take's own clock starts at 5 s
    stamp = TakeTimecode(start, rate, "producer")
    label = tc.format_frames(start + frame, rate)
    k = start_index(t, stamp, label, "take")
    offset = frame / float(tc.RATES[rate].fps)
    assert abs((t[k] - t[0]) - offset) <= 0.5 / row_rate + 1e-9


def test_start_errors() -> None:
    t = np.arange(240) / 120
    stamp = TakeTimecode(tc.parse("10:00:00:00", Rate.FPS_25), Rate.FPS_25, "host")
    with pytest.raises(ValueError, match="outside take"):
        start_index(t, stamp, "09:59:59:24", "take")
    with pytest.raises(ValueError, match="outside take"):
        start_index(t, stamp, "10:00:02:01", "take")
    with pytest.raises(ValueError, match="no timecode"):
        start_index(t, None, "10:00:00:00", "take")
    with pytest.raises(ValueError, match="another rate"):
        start_index(t, stamp, "10:00:01;00", "take")
    assert start_index(t, stamp, "10:00:01:00", "take") == 120
