"""Wire formats of the websockets, the way in: horse and saddle frames, subscriptions (docs/protocol.md).

Decoding is pure and validates once at the edge: a bad frame raises
:class:`BadFrame` with a ``reason`` (counted in metrics) and a message for the client.
Times are the producer's seconds (``|t| <= MAX_TIME``), values in the producer's units
(the ingest scales lengths). The way out, rider frames for a :class:`Subscription`, is
:mod:`riderlive.service.rider_frames`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import msgpack
import orjson

from riderlive.channels import HORSE_INDEX, HORSE_NAMES, RIDER_NAMES

PROTOCOL_VERSION = 1

SKELETONS = ("rider", "horse")
"""Skeletons a ``pose`` subscription can ask for, in the order frames carry them."""
POSE_FLOATS_PER_BONE = 7
"""tx ty tz (local position, metres) then qx qy qz qw (local rotation from the rest)."""

MAX_TIME = 1e10
"""Largest producer time ``|t|`` in seconds (317 years: Unix time fits; float64 still resolves 2 us)."""


class BadFrame(ValueError):
    """A rejected message; ``reason`` is a short metric label."""

    def __init__(self, reason: str, message: str) -> None:
        self.reason = reason
        super().__init__(message)


def message_bytes(data: str | bytes, max_bytes: int) -> int:
    """The size of a message in bytes (text counts as UTF-8); exact up to ``max_bytes``."""
    if isinstance(data, bytes) or len(data) > max_bytes or 4 * len(data) <= max_bytes:
        return len(data)  # a character is 1 to 4 bytes of UTF-8: no need to encode
    return len(data.encode("utf-8", "surrogatepass"))


def parse_message(data: str | bytes, max_bytes: int) -> dict[str, Any]:
    """JSON text or msgpack binary -> a dict, or :class:`BadFrame`. ``max_bytes`` counts bytes."""
    size = message_bytes(data, max_bytes)
    if size > max_bytes:
        raise BadFrame("oversize", f"message of {size}+ bytes exceeds {max_bytes} bytes")
    try:
        obj = orjson.loads(data) if isinstance(data, str) else msgpack.unpackb(data, raw=False, strict_map_key=True)
    except (orjson.JSONDecodeError, ValueError, msgpack.ExtraData, msgpack.FormatError, msgpack.StackError) as exc:
        raise BadFrame("malformed", f"cannot decode message: {exc}") from None
    if not isinstance(obj, dict):
        raise BadFrame("malformed", "a message must be an object (a JSON object or a msgpack map)")
    return obj


def _number(value: Any, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise BadFrame("wrong_type", f"{what} must be a number, got {type(value).__name__}")
    number = float(value)
    if not math.isfinite(number):
        raise BadFrame("not_finite", f"{what} must be finite, got {value!r}")
    return number


@dataclass(frozen=True)
class HorseFrame:
    """A decoded horse frame: producer time and {channel index: value} in the producer's units."""

    t: float
    values: dict[int, float]


def decode_horse_frame(obj: dict[str, Any], order: Sequence[int] | None = None) -> HorseFrame:
    """A horse frame message: ``t`` plus ``values`` (a map by name) or ``v`` (a list in ``order``)."""
    return decode_frame(obj, order)


def decode_frame(
    obj: dict[str, Any],
    order: Sequence[int] | None = None,
    index: dict[str, int] = HORSE_INDEX,
    names: Sequence[str] = HORSE_NAMES,
    what: str = "horse",
) -> HorseFrame:
    """A frame message of the channels ``names`` (``index``: name -> column; ``what`` names
    them in errors): ``t`` plus ``values`` (a map by name) or ``v`` (a list in ``order``)."""
    if "t" not in obj:
        raise BadFrame("missing_t", "a frame needs its time 't' in seconds")
    t = _number(obj["t"], "t")
    if not -MAX_TIME <= t <= MAX_TIME:
        raise BadFrame("out_of_range", f"'t' = {t!r} s is outside [-{MAX_TIME:g}, {MAX_TIME:g}]")
    out: dict[int, float] = {}
    if "values" in obj:
        values = obj["values"]
        if not isinstance(values, dict):
            raise BadFrame("wrong_type", "'values' must be an object of channel: number")
        for name, value in values.items():
            column = index.get(name) if isinstance(name, str) else None
            if column is None:
                raise BadFrame("unknown_channel", f"unknown {what} channel {name!r}")
            out[column] = _number(value, name)
    elif "v" in obj:
        array = obj["v"]
        columns = tuple(range(len(names))) if order is None else tuple(order)
        if not isinstance(array, list) or len(array) != len(columns):
            raise BadFrame("wrong_type", f"'v' must be a list of {len(columns)} numbers (the declared channels)")
        for column, value in zip(columns, array, strict=True):
            out[column] = _number(value, names[column])
    else:
        raise BadFrame("missing_values", "a frame needs 'values' (object) or 'v' (list)")
    return HorseFrame(t, out)


def channel_order(names: Any, index: dict[str, int] = HORSE_INDEX, what: str = "horse") -> tuple[int, ...]:
    """Validate a declared list of channel names (the order of ``v``); ``index``: name -> column."""
    if not isinstance(names, list) or not names:
        raise BadFrame("wrong_type", f"'channels' must be a non-empty list of {what} channel names")
    out = []
    for name in names:
        if not isinstance(name, str) or name not in index:
            raise BadFrame("unknown_channel", f"unknown {what} channel {name!r}")
        out.append(index[name])
    if len(set(out)) != len(out):
        raise BadFrame("wrong_type", "'channels' lists a channel twice")
    return tuple(out)


@dataclass(frozen=True)
class Subscription:
    """What one /ws/rider client receives."""

    rider: tuple[int, ...] = tuple(range(len(RIDER_NAMES)))
    """Indices into the published channels: the rider's, then any simulated bone chains."""
    horse: tuple[int, ...] = ()
    decimation: int = 1
    encoding: str = "json"
    bones: bool = False
    """Add the rider's per-bone quaternions (``riderlive.skeleton.bone_quaternions``)."""
    pose: tuple[str, ...] = ()
    """Skeletons (of :data:`SKELETONS`) whose full local pose, 7 floats per bone, each frame carries."""
    saddle: bool = False
    """Add the saddle pose of the tick's horse and, while a saddle input drives, its estimate."""
    timecode: bool = False
    """Add the frame's SMPTE timecode (JSON ``tc`` label; binary: frames in the header, docs/timecode.md)."""

    @property
    def key(self) -> tuple[Any, ...]:
        """Clients with the same key share one encoded frame per tick."""
        return (self.encoding, self.rider, self.horse, self.bones, self.pose, self.saddle, self.timecode)

    def describe(self, tick_rate: float, names: Sequence[str] = RIDER_NAMES) -> dict[str, Any]:
        return {
            "type": "subscribed",
            "channels": [names[i] for i in self.rider],
            "horse_channels": [HORSE_NAMES[i] for i in self.horse],
            "decimation": self.decimation,
            "rate": tick_rate / self.decimation,
            "encoding": self.encoding,
            "bones": self.bones,
            "pose": list(self.pose),
            "saddle": self.saddle,
            "timecode": self.timecode,
        }


def _pick(names: Any, table: dict[str, int], what: str) -> tuple[int, ...]:
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise BadFrame("wrong_type", f"'{what}' must be a list of channel names")
    unknown = [n for n in names if n not in table]
    if unknown:
        raise BadFrame("unknown_channel", f"unknown {what} {unknown[0][:64]!r}")
    if len(set(names)) != len(names):
        twice = next(n for n in names if names.count(n) > 1)
        raise BadFrame("wrong_type", f"'{what}' lists {twice!r} twice")
    return tuple(table[n] for n in names)


MAX_SUBSCRIBE_RATE = 10000.0
"""Hz; a ``rate`` at or above the tick rate gets every tick."""


def decode_subscription(
    obj: dict[str, Any], current: Subscription, tick_rate: float, index: dict[str, int] | None = None
) -> Subscription:
    """Apply a ``subscribe`` message; omitted fields keep their current value.

    ``index``: published channel name -> column (default: the rider channels).
    """
    from riderlive.channels import RIDER_INDEX

    table = RIDER_INDEX if index is None else index
    rider = _pick(obj["channels"], table, "channels") if "channels" in obj else current.rider
    horse = _pick(obj["horse_channels"], HORSE_INDEX, "horse_channels") if "horse_channels" in obj else current.horse
    decimation = current.decimation
    if "decimation" in obj:
        value = obj["decimation"]
        if isinstance(value, bool) or not isinstance(value, int):
            raise BadFrame("wrong_type", "'decimation' must be an integer 1..1000")
        if not 1 <= value <= 1000:
            raise BadFrame("out_of_range", f"'decimation' = {value!r} is outside [1, 1000]")
        decimation = value
    if "rate" in obj:
        rate = _number(obj["rate"], "rate")
        low = tick_rate / 1000.0
        if not low <= rate <= MAX_SUBSCRIBE_RATE:
            raise BadFrame("out_of_range", f"'rate' = {rate!r} Hz is outside [{low:g}, {MAX_SUBSCRIBE_RATE:g}]")
        decimation = min(1000, max(1, round(tick_rate / rate)))
    encoding = obj.get("encoding", current.encoding)
    if not isinstance(encoding, str) or encoding not in ("json", "binary"):
        raise BadFrame("wrong_type", "'encoding' must be 'json' or 'binary'")
    bones = obj.get("bones", current.bones)
    if not isinstance(bones, bool):
        raise BadFrame("wrong_type", "'bones' must be true or false")
    saddle = obj.get("saddle", current.saddle)
    if not isinstance(saddle, bool):
        raise BadFrame("wrong_type", "'saddle' must be true or false")
    timecode = obj.get("timecode", current.timecode)
    if not isinstance(timecode, bool):
        raise BadFrame("wrong_type", "'timecode' must be true or false")
    return Subscription(rider, horse, decimation, encoding, bones, _pose(obj, current.pose), saddle, timecode)


def decode_ping_id(obj: dict[str, Any]) -> str | int | float | None:
    """A ping's ``id`` (echoed in the pong): a number, a string of at most 64 characters, or none."""
    value = obj.get("id")
    if value is None or (isinstance(value, str) and len(value) <= 64):
        return value
    if isinstance(value, int) and not isinstance(value, bool) and -(2**63) <= value < 2**63:
        return value
    if isinstance(value, float):
        return _number(value, "id")
    raise BadFrame("wrong_type", "'id' must be a number or a string of at most 64 characters")


def _pose(obj: dict[str, Any], current: tuple[str, ...]) -> tuple[str, ...]:
    """``pose``: true (both skeletons), false (none) or a list of skeleton names."""
    if "pose" not in obj:
        return current
    value = obj["pose"]
    if isinstance(value, bool):
        return SKELETONS if value else ()
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise BadFrame("wrong_type", "'pose' must be true, false or a list of skeletons ('rider', 'horse')")
    unknown = [v for v in value if v not in SKELETONS]
    if unknown:
        raise BadFrame("unknown_skeleton", f"unknown skeleton {unknown[0]!r}; known: {', '.join(SKELETONS)}")
    return tuple(name for name in SKELETONS if name in value)
