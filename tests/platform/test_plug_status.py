"""The platform plug's status report (riderlive/platform/plug_status.py): closeness, faults, joints."""

from __future__ import annotations

import pytest

from riderlive.platform.link_vocab import Fault
from riderlive.platform.mechanism.config import PLATFORM_DIR
from riderlive.platform.mechanism.pipeline import Aim, PlatformModel
from riderlive.platform.plug_status import closeness, fault_names, joints


def test_closeness_is_0_mid_range_and_1_at_a_limit() -> None:
    assert closeness(0.0, 0.2, 0.1) == 0.0
    assert closeness(0.0, 0.2, 0.15) == pytest.approx(0.5)
    assert closeness(0.0, 0.2, 0.0) == 1.0 and closeness(0.0, 0.2, 0.2) == 1.0
    assert closeness(0.0, 0.2, -0.5) == 1.0  # past a limit: still 1
    assert closeness(0.1, 0.1, 0.1) == 1.0  # no range at all


def test_fault_names() -> None:
    assert fault_names(0) == []
    assert fault_names(Fault.LINK_TIMEOUT | Fault.PARK_TIMEOUT) == ["link_timeout", "park_timeout"]


def test_joints_at_park_and_at_a_level_pose() -> None:
    g = PlatformModel.load(PLATFORM_DIR / "stewart_compact.toml").geometry
    parked = joints(g, None)
    assert parked["base"] == [list(b) for b in g.base] and len(parked["top"]) == len(g.platform)
    pose = (0.01, -0.02, 0.5, 0.0, 0.0, 0.0)  # level: each top joint is the pose's origin plus its offset
    aimed = joints(g, Aim([0.0] * 6, pose, (), 1.0))
    for top, p in zip(aimed["top"], g.platform, strict=True):
        assert top == pytest.approx([pose[0] + p[0], pose[1] + p[1], pose[2] + p[2]], abs=1e-12)
