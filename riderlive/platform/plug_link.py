"""The platform plug's edge to its serial link: units, CONFIG values, and errors.

What :class:`~riderlive.platform.device.PlatformPlug` needs between the pure pipeline
(actuator positions in m of stroke, or deg of crank for a rotary arm) and the link's
integers (counts of 0.01 mm, or 0.01 deg; docs/platform-link.md):

- :func:`position_units` and :func:`target_counts`: positions to the link's counts;
- :func:`config_values`: the CONFIG frames that tighten the firmware to a platform file;
- :func:`lifecycle_errors`: the link's exceptions as the device lifecycle's
  (``PortLost``, ``PortBusy``, ``NoReply``, ``Mismatch``, ``Rejected``), counted.

Pure but for :func:`lifecycle_errors`, which only translates what its block raises.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

import numpy as np

from riderlive.devices.lifecycle import Mismatch, NoReply, PortBusy, PortLost, Rejected
from riderlive.platform import link
from riderlive.platform.link_vocab import ConfigKey
from riderlive.platform.mechanism.pipeline import FloatArray, PlatformModel
from riderlive.platform.serial_link import CommandRefused, NoAnswer, PlatformLinkError, VersionMismatch
from riderlive.platform.serial_link import PortBusy as LinkBusy
from riderlive.platform.serial_link import PortLost as LinkLost


def position_units(model: PlatformModel) -> float:
    """Link units (mm or deg) per actuator position unit (m of stroke, or deg of crank)."""
    return 1.0 if model.geometry.kind.rotary else 1000.0


def target_counts(positions: Sequence[float] | FloatArray, units: float) -> tuple[int, ...]:
    """Actuator positions (m of stroke or deg) -> the link's counts (0.01 mm or 0.01 deg)."""
    values = positions.tolist() if isinstance(positions, np.ndarray) else positions  # NumPy scalars are slow here
    return link.to_counts([q * units for q in values])


def config_values(model: PlatformModel, units: float, heartbeat_ms: int) -> list[tuple[ConfigKey, int, int]]:
    """CONFIG frames that tighten the firmware to the platform file: ``(key, actuator, value)``
    in counts, counts/s, counts/s^2 (the heartbeat timeout in ms); ``units`` from
    :func:`position_units`. Soft limits round inward, speed and acceleration down."""
    scale = units * link.COUNTS_PER_UNIT
    g = model.geometry
    values = [(ConfigKey.HEARTBEAT_TIMEOUT_MS, 0, heartbeat_ms)]
    for i in range(g.legs):
        values += [
            (ConfigKey.SOFT_MIN, i, math.ceil(g.lower[i] * scale - 1e-6)),
            (ConfigKey.SOFT_MAX, i, math.floor(g.upper[i] * scale + 1e-6)),
            (ConfigKey.VELOCITY_LIMIT, i, math.floor(g.max_speed[i] * scale)),
            (ConfigKey.ACCELERATION_LIMIT, i, math.floor(g.max_accel[i] * scale)),
        ]
    return values


@contextmanager
def lifecycle_errors(counters: Counter[str]) -> Iterator[None]:
    """The link's errors raised in the block as the lifecycle's; a vanished port counted in
    ``counters["port_lost"]``."""
    try:
        yield
    except LinkLost as exc:
        counters["port_lost"] += 1
        raise PortLost(str(exc)) from exc
    except LinkBusy as exc:
        raise PortBusy(str(exc)) from exc
    except VersionMismatch as exc:
        raise Mismatch(0, str(exc)) from exc
    except NoAnswer as exc:
        raise NoReply(None, str(exc)) from exc
    except CommandRefused as exc:
        raise Rejected(0, type(exc.status).__name__.lower(), str(exc)) from exc
    except PlatformLinkError as exc:  # pragma: no cover - every subclass is listed above
        raise NoReply(None, str(exc)) from exc
