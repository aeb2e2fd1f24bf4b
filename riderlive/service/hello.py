"""``/ws/rider``'s hello: what the service publishes and in which units (docs/protocol.md, "Hello"),
and the wire helpers it describes (pose floats, the length unit's symbol)."""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, Any

import numpy as np

from riderlive import __version__
from riderlive.channels import AXIS_CONVENTION, HORSE, RIDER, RIDER_PART_NAMES, RIDER_PARTS, SADDLE, lookup
from riderlive.realtime.record import ESTIMATE_FIELDS
from riderlive.realtime.saddle_input import GAITS, LOCKS
from riderlive.service.codecs import POSE_FLOATS_PER_BONE, PROTOCOL_VERSION, SKELETONS
from riderlive.skeleton import hello_skeletons
from riderlive.skeleton.rig import Pose
from riderlive.units import metres_per_unit

if TYPE_CHECKING:
    from riderlive.service.ports import PublishPort

HELLO_VERSION = 4
"""1: ``length_unit`` was a sentence. 2: it is a unit symbol (``"m"``), with ``metres_per_length_unit``,
``time_unit`` and ``pose``. 3: ``saddle`` (the saddle subscription). 4: ``engine_epoch`` (docs/protocol.md,
"Hello versions")."""


@functools.cache
def skeletons() -> dict[str, Any]:
    """``hello_skeletons()``, computed once per process (it is the same for every hello)."""
    return hello_skeletons()


def pose_floats(pose: Pose) -> np.ndarray:
    """A pose as the wire carries it: per bone ``tx ty tz qx qy qz qw`` (local, metres), flattened."""
    out = np.empty((len(pose.local_offsets), POSE_FLOATS_PER_BONE), dtype=np.float64)
    out[:, :3] = pose.local_offsets
    out[:, 3:] = pose.local_rotations
    return out.ravel()


def units(length_scale: float) -> tuple[str, float]:
    """The service length unit as a symbol (``m``, ``cm``, ``mm``, else ``"<k> m"``) and in metres."""
    metres = metres_per_unit(length_scale)
    for symbol, size in (("m", 1.0), ("cm", 0.01), ("mm", 0.001)):
        if abs(metres - size) <= 1e-12 * size:
            return symbol, size
    return f"{metres:g} m", metres


def hello(service: PublishPort) -> dict[str, Any]:
    """The hello a /ws/rider client gets first (docs/protocol.md, "Hello")."""
    config = service.config
    length_unit, metres = units(config.tick.length_scale)
    return {
        "type": "hello",
        "protocol": PROTOCOL_VERSION,
        "server": f"riderlive {__version__}",
        "session": service.session,
        "tick_rate": config.tick.rate,
        "engine_time": service.link.engine_time(),
        "engine_epoch": service.link.start,
        "channels": [{"name": c.name, "unit": c.unit, "meaning": c.meaning} for c in _channels(service)],
        "rider_part_channels": [{"name": c.name, "unit": c.unit, "meaning": c.meaning} for c in RIDER_PARTS],
        "horse_channels": [{"name": c.name, "unit": c.unit, "meaning": c.meaning} for c in HORSE],
        "axis_convention": AXIS_CONVENTION,
        "length_scale": config.tick.length_scale,
        "length_unit": length_unit,
        "metres_per_length_unit": metres,
        "rotation_unit": "deg",
        "time_unit": "s",
        "hello_version": HELLO_VERSION,
        "encodings": ["json", "binary"],
        "drivers": ["procedural", "input", "neutral"],
        "skeletons": skeletons(),
        "pose": {
            "skeletons": list(SKELETONS),
            "floats_per_bone": POSE_FLOATS_PER_BONE,
            "layout": ["tx", "ty", "tz", "qx", "qy", "qz", "qw"],
            "length_unit": "m",
            "frame": "local: position in the parent's frame, rotation from the rest (identity); skeletons.axes",
        },
        "saddle": _saddle_hello(service),
        "timecode": {"rate": service.timecode.rate.value, "subscribe": "timecode: true"},
    }


def _saddle_hello(service: PublishPort) -> dict[str, Any]:
    """What a ``saddle`` subscription carries (docs/protocol.md, "Saddle")."""
    point = service.config.saddle
    return {
        "channels": [{"name": c.name, "unit": c.unit, "meaning": c.meaning} for c in SADDLE],
        "point": {"forward": point.forward, "up": point.up, "unit": "m"},
        "estimate": list(ESTIMATE_FIELDS),
        "locks": list(LOCKS),
        "gaits": list(GAITS),
    }


def _channels(service: PublishPort) -> list[Any]:
    """The default subscription's channels (the rider parts are listed apart, by subscription only)."""
    parts = set(RIDER_PART_NAMES)
    return [*RIDER, *(lookup(name) for name in service.extra_channels if name not in parts)]
