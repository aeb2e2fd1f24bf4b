"""The platform plug's status report (pure): firmware, link, actuators, workspace, limits, joints.

:func:`report` is the ``status()`` of :class:`~riderlive.platform.device.PlatformPlug`
(REST ``/api/devices``, ``/api/platform``, the page's platform panel) made from what the
plug last knew: positions in actuator units (m of stroke, or deg of crank), poses in the
platform's base frame (m, deg), the saddle pose as the tick handed it (m, deg).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from riderlive.platform import link
from riderlive.platform.link_vocab import Fault, Flag
from riderlive.platform.mechanism import pipeline
from riderlive.platform.mechanism.geometry import Geometry, rotation
from riderlive.platform.mechanism.pipeline import PlatformModel, PlatformState
from riderlive.platform.serial_link import SerialPlatformLink


def fault_names(bits: int) -> list[str]:
    """The firmware's fault bits by name (``link_vocab.Fault``), lower case."""
    return [str(f.name).lower() for f in Fault if bits & f]


def closeness(lower: float, upper: float, q: float) -> float:
    """0 in the middle of an actuator's soft range ``[lower, upper]``, 1 at (or past) a soft limit."""
    half = 0.5 * (upper - lower)
    mid = lower + half
    return min(1.0, abs(q - mid) / half) if half > 0 else 1.0


def joints(geometry: Geometry, aim: pipeline.Aim | None) -> dict[str, list[list[float]]]:
    """Base joints and platform joints at the last aimed pose (the park pose before one), base frame, m."""
    pose = geometry.park if aim is None else aim.pose
    r = rotation(pose[3], pose[4], pose[5])
    top = [[pose[k] + sum(r[k][j] * p[j] for j in range(3)) for k in range(3)] for p in geometry.platform]
    return {"base": [list(b) for b in geometry.base], "top": top}


def report(
    *,
    model: PlatformModel,
    serial: SerialPlatformLink,
    hello: link.HelloReply | None,
    positions: Sequence[float],
    measured: Sequence[float] | None,
    state: PlatformState,
    aim: pipeline.Aim | None,
    saddle: Sequence[float],
    faults_at_connect: list[str],
) -> dict[str, Any]:
    """Firmware state and faults, the link's counters both sides, workspace use, limits hit,
    and per actuator the position sent, the one measured and its closeness to a soft limit."""
    g = model.geometry
    t = serial.telemetry
    read: Sequence[float | None] = measured or [None] * len(positions)
    actuators = [
        {
            "name": f"a{i + 1}",
            "target": q,
            "measured": m,
            "closeness": closeness(g.lower[i], g.upper[i], q),
            "lower": g.lower[i],
            "upper": g.upper[i],
        }
        for i, (q, m) in enumerate(zip(positions, read, strict=True))
    ]
    return {
        "platform": {
            "geometry": g.kind.value,
            "unit": g.unit,
            "firmware": None
            if hello is None
            else {
                "device": hello.device,
                "version": list(hello.firmware),
                "profile": hello.profile,
                "state": serial.state.label,
                "faults": fault_names(t.faults) if t else [],
                "flags": [str(f.name).lower() for f in Flag if t and t.flags & f],
                "counters": serial.device_counters(),
            },
            "link": {"health": serial.health.value, "counters": dict(serial.counters)},
            "actuators": actuators,
            "workspace_use": max((closeness(g.lower[i], g.upper[i], q) for i, q in enumerate(positions)), default=0.0),
            "scale": 1.0 if aim is None else aim.scale,
            "pose": None if aim is None else [p - h for p, h in zip(aim.pose, g.home, strict=True)],
            "saddle": list(saddle),
            "limits_hit": {**state.safety.counters, "scaled_back_frames": state.scaled_back},
            "cueing": {"intensity": model.cueing.params.intensity, "preset": model.cueing.params.preset},
            "faults_at_connect": faults_at_connect,
            "joints": joints(g, aim),
        }
    }
