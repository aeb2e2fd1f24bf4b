"""``/VMC/Ext/T`` carries the frame's SMPTE timecode as an appended string (docs/vmc.md), read by python-osc."""

from __future__ import annotations

import pytest

from riderlive.channels import HORSE_NAMES, RIDER_NAMES
from riderlive.skeleton import HORSE_RIG, horse_pose, rider_pose, rider_rig
from riderlive.vmc.performer import horse_bundle, rider_bundle

osc_bundle = pytest.importorskip("pythonosc.osc_bundle")


def _time_args(data: bytes) -> list[object]:
    return next(list(m.params) for m in osc_bundle.OscBundle(data) if m.address == "/VMC/Ext/T")


def test_the_time_message_appends_the_label() -> None:
    rig = rider_rig()
    pose = rider_pose([rig.neutral[n] for n in RIDER_NAMES])
    stamped = rider_bundle(pose, (0.0, 1.4, 0.0), (0.0, 0.0, 0.0, 1.0), 2.5, "10:00:00;12")
    assert _time_args(stamped) == [2.5, "10:00:00;12"]
    plain = rider_bundle(pose, (0.0, 1.4, 0.0), (0.0, 0.0, 0.0, 1.0), 2.5)
    assert _time_args(plain) == [2.5]  # without a timecode the bundle is byte for byte the old one
    hp = horse_pose([0.0] * len(HORSE_NAMES))
    assert _time_args(horse_bundle(hp, HORSE_RIG.names, 1.0, "01:02:03:04")) == [1.0, "01:02:03:04"]
