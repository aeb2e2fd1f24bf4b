"""Rig maps: the shipped files load, bad ones fail naming file and key, the pure map math."""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.channels import RIDER_INDEX, RIDER_NAMES
from riderlive.configfile import ConfigError, read_toml
from riderlive.dynamixel.rig import (
    MAX_DEG,
    RIG_DIR,
    load_rig,
    longest_tick_wait_s,
    read_tick_seconds,
    rig_from_dict,
    wire_bytes_per_tick,
    wire_seconds_per_tick,
)
from riderlive.dynamixel.servo_map import ServoMap, deg_to_pulses, profile_acceleration, profile_velocity, pulses_to_deg
from riderlive.dynamixel.tables import HardwareError

FULL = RIG_DIR / "full_rider.toml"


def full_data() -> dict[str, Any]:
    return copy.deepcopy(read_toml(FULL))


def error_for(data: dict[str, Any]) -> ConfigError:
    with pytest.raises(ConfigError) as info:
        rig_from_dict(data, "rig.toml")
    return info.value


def test_shipped_rigs_load() -> None:
    full = load_rig(FULL)
    assert len(full.servos) == 24
    assert len(set(full.ids)) == 24
    bench = load_rig("bench3")  # a bare name is looked up in config/rigs
    assert bench.ids == (1, 2, 3)
    assert bench.servos["head"].park == 190.0
    assert full.bus.shutdown_mask == int(
        HardwareError.INPUT_VOLTAGE
        | HardwareError.OVERHEATING
        | HardwareError.ELECTRICAL_SHOCK
        | HardwareError.OVERLOAD
    )


def test_full_rider_covers_body_regions() -> None:
    channels = {s.channel.split(".")[0] for s in load_rig(FULL).servos.values()}
    for node in ("lower_back", "waist", "hip", "cog", "head", "lf_wrist", "rt_wrist", "lf_foot", "rt_knee"):
        assert node in channels


@pytest.mark.parametrize(
    ("mutate", "key", "fragment"),
    [
        (
            lambda d: d["servos"]["hip_side"].update(id=1),
            "servos.hip_side.id",
            "already used by servos.lower_back_pitch",
        ),
        (lambda d: d["servos"]["hip_side"].update(max_deg=400.0), "servos.hip_side.max_deg", "outside"),
        (lambda d: d["servos"]["hip_side"].update(min_deg=-5.0), "servos.hip_side.min_deg", "outside"),
        (
            lambda d: d["servos"]["hip_side"].update(channel="hip.rq"),
            "servos.hip_side.channel",
            "unknown rider channel",
        ),
        (lambda d: d["servos"]["hip_side"].update(model="XL320"), "servos.hip_side.model", "unknown servo model"),
        (lambda d: d["servos"]["hip_side"].update(min_deg=200.0, max_deg=190.0), "servos.hip_side.max_deg", "above"),
        (lambda d: d["servos"]["hip_side"].update(park_deg=250.0), "servos.hip_side.park_deg", "outside [min_deg"),
        (lambda d: d["servos"]["hip_side"].update(max_speed_dps=5000.0), "servos.hip_side.max_speed_dps", "no-load"),
        (lambda d: d["servos"]["hip_side"].update(gain=0.0), "servos.hip_side.gain", "never move"),
        (lambda d: d["servos"]["hip_side"].update(direction=2), "servos.hip_side.direction", ""),
        (lambda d: d["servos"]["hip_side"].update(gain=math.nan), "servos.hip_side.gain", "finite"),
        (lambda d: d["servos"]["hip_side"].update(colour="red"), "servos.hip_side.colour", "unknown key"),
        (lambda d: d["bus"].update(baud=1_234_567), "bus.baud", "not a baud rate"),
        (lambda d: d["bus"].update(bus_watchdog_ms=30), "bus.bus_watchdog_ms", "multiple of 20"),
        (lambda d: d["bus"].update(bus_watchdog_ms=20), "bus.bus_watchdog_ms", ">= 40"),
        (lambda d: d["bus"].update(protocol=1.0), "bus.protocol", "Protocol 2.0"),
        (lambda d: d["bus"].update(read_divider=0), "bus.read_divider", "greater than or equal to 1"),
        (lambda d: d.update(servos={}), "servos", "at least one servo"),
        (lambda d: d["bus"].update(tick_hz=400.0), "bus.tick_hz", "at most 308 ticks/s"),
        (lambda d: d["bus"].update(tick_hz=150.0), "bus.tick_hz", "a tick with a read takes 8.36 ms"),
    ],
)
def test_bad_rig_names_file_and_key(mutate: Any, key: str, fragment: str) -> None:
    data = full_data()
    mutate(data)
    err = error_for(data)
    assert err.source == "rig.toml"
    assert err.key == key
    assert fragment in err.message
    assert str(err).startswith(f"rig.toml: {key}: ")


def test_baud_the_model_cannot_do() -> None:
    data = read_toml(RIG_DIR / "bench3.toml")
    data["bus"]["baud"] = 57600
    data["bus"]["tick_hz"] = 40.0  # 12 ms of wire per tick at 57600, within 80 % of 25 ms
    load = rig_from_dict(data)  # XL330 has 57600
    assert load.bus.baud == 57600
    data["bus"]["baud"] = 2_500_000  # the SDK can set it, no X-series servo runs at it
    assert error_for(data).key == "bus.baud"


def test_missing_file_and_bad_toml(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="file not found"):
        load_rig(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[bus\nport = 1\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_rig(bad)


def test_model_names_are_case_insensitive() -> None:
    data = full_data()
    data["servos"]["hip_side"]["model"] = "xm430-w350"
    assert rig_from_dict(data).servos["hip_side"].model == "XM430-W350"


# --- unit conversions and the per-tick map ------------------------------------


@settings(deadline=None)  # a loaded CI box must not fail on time
@given(st.floats(0.0, MAX_DEG))
def test_degrees_round_trip_within_half_a_pulse(deg: float) -> None:
    assert abs(pulses_to_deg(deg_to_pulses(deg)) - deg) <= 360.0 / 4096 / 2 + 1e-9


@settings(deadline=None)
@given(st.floats(-1e6, 1e6))
def test_pulses_stay_in_register_range(deg: float) -> None:
    assert 0 <= deg_to_pulses(deg) <= 4095


def test_wire_budget_matches_the_protocol() -> None:
    # facts.md: 20 servos, 4-byte goals: sync write 14 + 5N bytes; fast reply 8 + (data + 4) N
    assert wire_bytes_per_tick(20, 1) == (14 + 100) + (14 + 20) + (8 + 19 * 20)
    assert wire_bytes_per_tick(20, 4, fast=False) == 114 + (34 + 26 * 20) / 4
    full = load_rig(FULL)  # 24 servos, 1 Mbps, read every 4 ticks: 134 + 502 / 4 bytes
    assert wire_seconds_per_tick(full) == pytest.approx(259.5e-5)
    assert read_tick_seconds(full) == pytest.approx(636e-5 + 2e-3)  # all 636 bytes + 2 x 1 ms latency


def test_longest_tick_wait_is_a_read_tick_plus_one_missed_reply() -> None:
    full = load_rig(FULL)  # max_reply_wait_ms 25 (default) above timeout_margin_ms 2: 25 + 2 x 1 ms latency
    assert longest_tick_wait_s(full) == pytest.approx(636e-5 + 2e-3 + 27e-3)
    data = read_toml(FULL)
    data["bus"]["timeout_margin_ms"] = 40.0  # a floor above the ceiling: the floor is the allowance
    assert longest_tick_wait_s(rig_from_dict(data)) == pytest.approx(636e-5 + 2e-3 + 42e-3)


def test_profile_units() -> None:
    # 0.229 rev/min per unit: 1 unit = 1.374 deg/s; 214.577 rev/min^2 per unit = 21.4577 deg/s^2
    assert profile_velocity(137.4) == 100
    assert profile_velocity(0.01) == 1  # never 0, which would mean "unlimited"
    assert profile_acceleration(2145.77) == 100
    assert profile_acceleration(0.0) == 0


def test_targets_follow_gain_direction_zero() -> None:
    rig = load_rig(FULL)
    smap = ServoMap(rig)
    rider = [0.0] * len(RIDER_NAMES)
    rider[RIDER_INDEX["head.rz"]] = 10.0
    rider[RIDER_INDEX["cog.ty"]] = 0.005
    targets = smap.targets(rider, smap.park)
    head = list(rig.servos).index("head_pitch")
    seat = list(rig.servos).index("seat_lift")
    assert targets[head] == pytest.approx(180.0 - 10.0)  # direction -1
    assert targets[seat] == pytest.approx(175.0 + 500.0 * 0.005)  # zero_deg 175, 500 deg/m
    rider[RIDER_INDEX["head.rz"]] = math.nan
    held = smap.targets(rider, [123.0] * len(smap))
    assert held[head] == 123.0


@settings(deadline=None)
@given(
    st.lists(st.floats(-1e4, 1e4), min_size=3, max_size=3),
    st.lists(st.floats(0.0, 359.0), min_size=3, max_size=3),
    st.floats(0.0, 0.1),
)
def test_limit_clamps_and_slews(targets: list[float], previous: list[float], dt: float) -> None:
    smap = ServoMap(load_rig("bench3"))
    goals, clamped = smap.limit(targets, previous, dt)
    for i, goal in enumerate(goals):
        step = smap.speed[i] * dt
        assert abs(goal - previous[i]) <= step + 1e-9
        inside = smap.low[i] - 1e-9 <= goal <= smap.high[i] + 1e-9
        # inside the limits, or moving toward them from outside at full slew
        assert inside or abs(abs(goal - previous[i]) - step) < 1e-9
        assert clamped[i] == (abs(goal - targets[i]) > 1e-9)
