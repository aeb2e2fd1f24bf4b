"""The safety board's typed slots: the same segment layout, read and written by attribute."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from hypothesis import given
from hypothesis import strategies as st

from riderlive.devices.board import MAX_DEVICES, GuardianReport, SafetyBoard
from riderlive.devices.lifecycle import DeviceState

OLD_HEADER = (
    "web_pid",
    "web_beat",
    "tick_pid",
    "tick_generation",
    "tick_beat",
    "tick_clean_exit",
    "guardian_pid",
    "guardian_beat",
    "guardian_ready",
    "guardian_done",
    "guardian_taking",
    "guardian_busy",
    "guardian_takeovers",
    "guardian_standby",
    "shutdown",
    "handback_from",
    "tick_io_until",
    "tick_io_since",
    "tick_io_waited",
    *(f"guardian_d{d}" for d in range(MAX_DEVICES)),
)
"""The board's header (the segment every process of a service shares): the slots before the
typed slots, with the hand-back's two (``guardian_taking``, ``handback_from``) since, and the
tick's declared device waits (``devices/iowait.py``) after them."""


@pytest.fixture
def boards() -> Iterator[tuple[SafetyBoard, SafetyBoard]]:
    owner = SafetyBoard()
    other = SafetyBoard(owner.name)  # another process's view: attached by name
    yield owner, other
    other.close()
    owner.close()


def test_the_segment_keeps_its_layout_and_every_slot_names_its_writer(boards: tuple[SafetyBoard, SafetyBoard]) -> None:
    owner, _ = boards
    assert owner.names[: len(OLD_HEADER)] == OLD_HEADER
    assert owner.names[len(OLD_HEADER)] == "d0.state"
    for slot in SafetyBoard.slots():
        assert slot.writer and slot.doc, slot.name
        assert owner.names[slot.index] == slot.name
    with pytest.raises(KeyError, match="no slot 'tick_heartbeat'"):
        SafetyBoard.slot("tick_heartbeat")


def test_a_write_by_attribute_is_read_by_the_attached_board_with_its_type(
    boards: tuple[SafetyBoard, SafetyBoard],
) -> None:
    owner, other = boards
    owner.tick_pid, owner.tick_generation, owner.tick_beat = 4321, 7, 12.5
    assert (other.tick_pid, other.tick_generation, other.tick_beat) == (4321, 7, 12.5)
    assert type(other.tick_pid) is int and type(other.tick_beat) is float
    with pytest.raises(TypeError):  # no string keys left: a misspelt slot fails at once, by attribute
        other["tick_pid"]  # type: ignore[index]
    other.guardian_takeovers += 1
    other.guardian_takeovers += 1
    assert owner.guardian_takeovers == 2


@given(pid=st.integers(0, 2**31 - 1), beat=st.floats(0.0, 1e9, allow_nan=False))
def test_int_and_float_slots_round_trip(pid: int, beat: float) -> None:
    board = SafetyBoard()
    try:
        board.guardian_pid, board.guardian_beat = pid, beat
        assert (board.guardian_pid, board.guardian_beat) == (pid, beat)
    finally:
        board.close()


def test_reports_and_devices_sit_after_the_header(boards: tuple[SafetyBoard, SafetyBoard]) -> None:
    owner, other = boards
    owner.publish(1, DeviceState.RUNNING, [0.5, -0.25])
    owner.report(MAX_DEVICES - 1, GuardianReport.OUTPUTS_OFF)
    assert other.device(1) == (DeviceState.RUNNING, [0.5, -0.25]) and other.device(0) is None
    assert other.reported(MAX_DEVICES - 1) is GuardianReport.OUTPUTS_OFF
    slot = other.names.index(f"guardian_d{MAX_DEVICES - 1}")  # where the segment's layout puts it
    assert other.values[slot] == float(GuardianReport.OUTPUTS_OFF)
    assert all(other.reported(d) is GuardianReport.NONE for d in range(MAX_DEVICES - 1))
    with pytest.raises(IndexError, match="devices 0-3"):
        owner.report(MAX_DEVICES, GuardianReport.PARKING)
    owner.clear_reports()
    assert other.reported(MAX_DEVICES - 1) is GuardianReport.NONE
