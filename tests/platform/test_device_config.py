"""The platform's place in the service configuration, the registry and the live tuning body:
errors name file, key and range; nothing here needs the firmware."""

from __future__ import annotations

from pathlib import Path

import pydantic
import pytest
from hypothesis import given
from hypothesis import strategies as st

from riderlive.configfile import ConfigError
from riderlive.devices.device import Device
from riderlive.devices.latch import StopLatch
from riderlive.devices.registry import DeviceSpec, plan
from riderlive.platform.device import PlatformPlug
from riderlive.platform.mechanism.pipeline import PlatformModel
from riderlive.realtime import commands as cmd
from riderlive.realtime.output import TickDevices
from riderlive.service.config import load_config
from riderlive.service.devices_api import plan_devices
from riderlive.service.platform_api import PlatformTune
from tests.devices.memory_plug import MemoryPlug


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "service.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("section", "key", "needle"),
    [
        ('file = "stewart_compact"\nport = "/dev/x"\nheartbeat_ms = 5', "platform.heartbeat_ms", "20"),
        ('file = "stewart_compact"\nport = "/dev/x"\nspeed = 1', "platform.speed", "extra"),
        ('file = "stewart_compact"', "platform", "platform.port is required"),
        ('file = "stewart_compact"\nport = "/dev/x"\ndevice = "two words"', "platform.device", "pattern"),
    ],
)
def test_a_bad_platform_section_names_file_key_and_range(tmp_path: Path, section: str, key: str, needle: str) -> None:
    path = write(tmp_path, f"[platform]\n{section}\n")
    with pytest.raises(ConfigError) as err:
        load_config(path)
    text = str(err.value)
    assert str(path) in text and key in text and needle in text.lower() + needle.lower()


def test_the_service_plans_a_platform_beside_a_rig_or_alone(tmp_path: Path) -> None:
    config = load_config(write(tmp_path, '[platform]\nfile = "stewart_compact"\nport = "/dev/ttyACM0"\n'))
    (spec,) = plan_devices(config)
    assert (spec.kind, spec.name, spec.consumes, spec.port, spec.divider) == (
        "platform",
        "stewart_compact",
        ("saddle",),
        "/dev/ttyACM0",
        1,
    )
    assert spec.options == {"device": None, "heartbeat_ms": 200}  # lengths reach it in metres (TickFrame)
    assert DeviceSpec.from_json(spec.to_json()) == spec  # the guardian gets it as JSON
    both = load_config(
        write(
            tmp_path,
            '[rig]\nfile = "bench3"\nport = "/dev/ttyUSB0"\n[platform]\nfile = "stewart_compact"\nport = "/dev/x"\n',
        )
    )
    assert [s.kind for s in plan_devices(both)] == ["dynamixel", "platform"]
    assert plan_devices(load_config(None)) == ()


def test_a_bad_platform_file_is_refused_at_plan_time(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    text = (Path(__file__).resolve().parents[2] / "config/platforms/stewart_compact.toml").read_text()
    bad.write_text(text.replace("max_length = 0.535", "max_length = 0.40"))
    with pytest.raises(ConfigError, match=r"bad\.toml: actuators\.max_length"):
        plan("platform", str(bad), "/dev/x", 100.0)


@given(st.floats(min_value=0.0, max_value=100.0), st.floats(min_value=0.1, max_value=2.5))
def test_tuning_bodies_in_range_are_accepted(intensity: float, washout: float) -> None:
    body = PlatformTune.model_validate({"intensity": intensity, "washout_translation_hz": washout})
    assert body.changes() == {"intensity": intensity, "washout_translation_hz": washout}


@given(st.one_of(st.floats(max_value=-1e-9), st.floats(min_value=100.0 + 1e-9), st.text(max_size=5)))
def test_tuning_bodies_out_of_range_are_refused(intensity: object) -> None:
    with pytest.raises(pydantic.ValidationError):
        PlatformTune.model_validate({"intensity": intensity})
    with pytest.raises(pydantic.ValidationError):
        PlatformTune.model_validate({"intensity": 50, "volume": 3})


def test_a_device_without_live_parameters_refuses_a_tune() -> None:
    latch = StopLatch()
    try:
        devices = TickDevices([], latch)
        devices.devices = [Device(MemoryPlug("mem"), 0.01, latch)]
        devices.specs = [DeviceSpec("memory", "mem", None, "mem", 1, 0.01)]
        reply = devices.request(cmd.Tune("mem", {"intensity": 50.0}, "test", 1))
        assert not reply.ok and reply.refusal == "bad_config" and "no live parameters" in reply.message
        unknown = devices.request(cmd.Tune("nope", {"intensity": 50.0}, "test", 2))
        assert not unknown.ok and unknown.refusal == "unknown_device"
    finally:
        latch.close()


def test_a_platform_takes_live_cueing_and_refuses_a_contradiction() -> None:
    latch = StopLatch()
    try:
        plug = PlatformPlug(PlatformModel.load("stewart_compact"), "/dev/null")
        devices = TickDevices([], latch)
        devices.devices = [Device(plug, 0.01, latch)]
        devices.specs = [DeviceSpec("platform", "stewart_compact", "/dev/null", plug.name, 1, 0.01, ("saddle",))]
        assert devices.request(cmd.Tune(plug.name, {"intensity": 40.0}, "test", 1)).ok
        assert plug.status()["platform"]["cueing"]["intensity"] == 40.0
        worse = devices.request(cmd.Tune(plug.name, {"drift_cutoff_hz": 0.45, "washout_rotation_hz": 0.4}, "t", 2))
        assert not worse.ok and worse.refusal == "bad_config" and "drift_cutoff_hz" in worse.message
        assert plug.model.cueing.params.drift_cutoff_hz == 0.08  # unchanged
    finally:
        latch.close()
