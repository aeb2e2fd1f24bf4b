"""riderlive.timecode against SMPTE's definition and the PyPI ``timecode`` library.

Two oracles: the definition (every label of the day in nominal order, the dropped ones
removed: the i-th label left is frame i) over every frame of 24 h, vectorised; and the
library, over every minute boundary (where drop-frame arithmetic can go wrong) plus
random frames, and over every frame of whole ten-minute drop cycles (the day's first
two and its last). The library counts frames from 1 (``00:00:00:00`` is its frame 1).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from timecode import Timecode

from riderlive import timecode as tc
from riderlive.timecode import RATES, Anchor, Rate, TimecodeError

DROP_RATES = (Rate.FPS_29_97_DF, Rate.FPS_59_94_DF)
LIBRARY_NAME = {
    Rate.FPS_23_976: "23.976",
    Rate.FPS_24: "24",
    Rate.FPS_25: "25",
    Rate.FPS_29_97_DF: "29.97",
    Rate.FPS_30: "30",
    Rate.FPS_48: "48",
    Rate.FPS_50: "50",
    Rate.FPS_59_94_DF: "59.94",
    Rate.FPS_60: "60",
}


def definition_labels(rate: Rate) -> np.ndarray:
    """Every label of a day in order, built from SMPTE's rule (not from the code under test)."""
    n = RATES[rate].nominal
    h, m, s, f = np.meshgrid(np.arange(24), np.arange(60), np.arange(60), np.arange(n), indexing="ij")
    labels = np.stack((h.ravel(), m.ravel(), s.ravel(), f.ravel()), axis=-1)
    if rate in DROP_RATES:
        drop = 2 if rate is Rate.FPS_29_97_DF else 4
        dropped = (labels[:, 2] == 0) & (labels[:, 3] < drop) & (labels[:, 1] % 10 != 0)
        labels = labels[~dropped]
    return labels


@pytest.mark.parametrize("rate", list(Rate))
def test_every_frame_of_a_day_matches_the_definition(rate: Rate) -> None:
    labels = definition_labels(rate)
    assert len(labels) == RATES[rate].frames_per_day
    frames = np.arange(len(labels), dtype=np.int64)
    got = tc.frames_to_fields(frames, rate)
    errors = np.count_nonzero(np.any(got != labels, axis=1))
    assert errors == 0
    back = tc.fields_to_frames(labels, rate)
    assert np.array_equal(back, frames)
    # wrapping: the day after is the same day
    assert np.array_equal(tc.frames_to_fields(frames[:1000] + len(labels), rate), labels[:1000])


def test_day_lengths_are_smpte() -> None:
    assert RATES[Rate.FPS_29_97_DF].frames_per_day == 2_589_408
    assert RATES[Rate.FPS_59_94_DF].frames_per_day == 5_178_816
    assert RATES[Rate.FPS_25].frames_per_day == 2_160_000
    # drop frame: 10 minutes of labels are 17982 frames at 30000/1001 = 599.9994 s of wall clock
    for rate in DROP_RATES:
        ten_minutes = tc.parse("00:10:00;00", rate)
        assert tc.frames_to_seconds(ten_minutes, rate) == pytest.approx(599.9994, abs=1e-9)
        hour = tc.parse("01:00:00;00", rate)
        assert tc.frames_to_seconds(hour, rate) == pytest.approx(3599.9964, abs=1e-9)


def _library_boundary_frames(rate: Rate) -> np.ndarray:
    """Frames at every minute boundary (the last two before, the first drop + 2 after) and random ones."""
    facts = RATES[rate]
    starts = tc.fields_to_frames([(m // 60, m % 60, 0, facts.drop if m % 10 else 0) for m in range(1440)], rate)
    near = (starts[:, None] + np.arange(-2, 3)[None, :]).ravel()
    rng = np.random.default_rng(28)
    return np.unique(np.mod(np.concatenate((near, rng.integers(0, facts.frames_per_day, 3000))), facts.frames_per_day))


@pytest.mark.parametrize("rate", list(Rate))
def test_labels_match_the_library_at_every_minute_boundary(rate: Rate) -> None:
    lib = Timecode(LIBRARY_NAME[rate])
    frames = _library_boundary_frames(rate)
    ours = tc.frames_to_fields(frames, rate)
    theirs = np.array([lib.frames_to_tc(int(f) + 1) for f in frames])
    assert np.count_nonzero(np.any(ours != theirs, axis=1)) == 0
    for f in frames[::7]:
        label = tc.format_frames(int(f), rate)
        assert str(Timecode(LIBRARY_NAME[rate], frames=int(f) + 1)) == label
        assert lib.tc_to_frames(label) - 1 == tc.parse(label, rate)


@pytest.mark.parametrize("rate", DROP_RATES)
def test_every_drop_frame_of_the_first_and_last_minutes_of_the_day_matches_the_library(rate: Rate) -> None:
    """0 frame errors, the library one frame at a time: the day's first two ten-minute drop
    cycles (the pattern repeats every ten minutes; hours only add whole cycles) and its last
    one, into the wrap. Every frame of the 24 h is held to SMPTE's definition above, and
    the library meets the definition at every minute boundary of the day: the library at
    every frame of the day (~1-3 min for 2.6-5.2 M Python calls) added nothing to these."""
    per_day, cycle = RATES[rate].frames_per_day, RATES[rate].frames_per_ten_minutes
    frames = np.concatenate((np.arange(2 * cycle), np.arange(per_day - cycle, per_day)))
    ours = tc.frames_to_fields(frames, rate)
    convert = Timecode(LIBRARY_NAME[rate]).frames_to_tc
    theirs = np.array([convert(int(f) + 1) for f in frames], dtype=np.int64)
    assert np.count_nonzero(np.any(ours != theirs, axis=1)) == 0


def test_the_library_accepts_a_dropped_label_we_refuse() -> None:
    """Documented difference: ``00:01:00;00`` does not exist at 29.97 DF; the library maps it
    onto another frame (00:00:59;28), riderlive refuses it."""
    assert str(Timecode("29.97", frames=Timecode("29.97", "00:01:00;00").frames)) == "00:00:59;28"
    with pytest.raises(TimecodeError, match="dropped label") as info:
        tc.parse("00:01:00;00", Rate.FPS_29_97_DF)
    assert info.value.reason == "timecode_malformed"
    assert tc.parse("00:10:00;00", Rate.FPS_29_97_DF) == 17_982  # every tenth minute keeps ;00


@given(st.sampled_from(list(Rate)), st.integers(min_value=-(10**9), max_value=10**9))
def test_format_and_parse_round_trip(rate: Rate, frames: int) -> None:
    label = tc.format_frames(frames, rate)
    assert tc.parse(label, rate) == frames % RATES[rate].frames_per_day


@given(st.sampled_from(list(Rate)), st.integers(min_value=0, max_value=10**7))
def test_seconds_round_trip(rate: Rate, frames: int) -> None:
    assert tc.seconds_to_frames(tc.frames_to_seconds(frames, rate), rate) == frames


@pytest.mark.parametrize(
    ("text", "rate", "reason"),
    [
        ("01:02:03:04", Rate.FPS_29_97_DF, "timecode_rate"),  # ':' at a drop-frame rate
        ("01:02:03;04", Rate.FPS_25, "timecode_rate"),  # ';' at a non-drop rate
        ("01:02:03:25", Rate.FPS_25, "timecode_rate"),  # frame 25 only exists at higher rates
        ("24:00:00:00", Rate.FPS_25, "timecode_malformed"),
        ("01:60:00:00", Rate.FPS_25, "timecode_malformed"),
        ("1:02:03:04", Rate.FPS_25, "timecode_malformed"),
        ("01:02:03", Rate.FPS_25, "timecode_malformed"),
        ("", Rate.FPS_25, "timecode_malformed"),
        (12.5, Rate.FPS_25, "timecode_malformed"),
        ("00:01:00;03", Rate.FPS_59_94_DF, "timecode_malformed"),
    ],
)
def test_parse_errors_say_why(text: object, rate: Rate, reason: str) -> None:
    with pytest.raises(TimecodeError) as info:
        tc.parse(text, rate)
    assert info.value.reason == reason
    assert str(info.value)


def test_hand_computed_labels() -> None:
    assert tc.format_frames(1800, Rate.FPS_29_97_DF) == "00:01:00;02"
    assert tc.format_frames(1799, Rate.FPS_29_97_DF) == "00:00:59;29"
    assert tc.format_frames(3600, Rate.FPS_59_94_DF) == "00:01:00;04"
    assert tc.format_frames(107_892, Rate.FPS_29_97_DF) == "01:00:00;00"
    assert tc.format_frames(90_000, Rate.FPS_25) == "01:00:00:00"
    assert tc.format_frames(-1, Rate.FPS_24) == "23:59:59:23"
    assert tc.parse("01:02:03;04", Rate.FPS_29_97_DF) == tc.parse("01:02:03.04", Rate.FPS_29_97_DF)


def test_parse_rate() -> None:
    assert tc.parse_rate("29.97DF") is Rate.FPS_29_97_DF
    assert tc.parse_rate(25) is Rate.FPS_25
    for bad in ("29.97", "120", True, None, [25]):
        with pytest.raises(TimecodeError, match="is not one of") as info:
            tc.parse_rate(bad)
        assert info.value.reason == "timecode_rate"


def test_anchor_runs_at_real_fps() -> None:
    anchor = Anchor(t=10.0, frames=tc.parse("01:00:00;00", Rate.FPS_29_97_DF), rate=Rate.FPS_29_97_DF)
    assert anchor.label_at(10.0) == "01:00:00;00"
    assert anchor.label_at(10.0 + 1001 / 30000) == "01:00:00;01"
    assert anchor.label_at(10.0 + 600.0) == "01:10:00;00"
    assert anchor.label_at(9.99) == "00:59:59;29"


def test_observe_counts_jumps_not_rounding() -> None:
    rate = Rate.FPS_25
    anchor = Anchor(0.0, 1000, rate)
    for k in range(1, 50):  # a producer at 120 Hz that labels each frame with the floor
        t = k / 120
        anchor, jump = tc.observe(anchor, t, 1000 + int(t * 25))
        assert jump is None
    anchor, jump = tc.observe(anchor, 50 / 120, 1000 + 250)
    assert jump == 250 - 10
    _, back = tc.observe(anchor, 51 / 120, 100)
    assert back is not None and back < 0
    # across midnight is not a jump
    day = RATES[rate].frames_per_day
    _, jump = tc.observe(Anchor(0.0, day - 1, rate), 1 / 25, 0)
    assert jump is None
