"""What the tick drives besides the rings: the ``TickOutput`` protocol and the rig hookup.

A ``TickOutput`` is called once per tick with the rider frame (channels.RIDER order)
and the tick's deadline in ``perf_counter`` seconds; it returns a JSON-ready status
dict to publish (or None when it has nothing new). It must not block longer than its
share of the tick. The Dynamixel rig (``riderlive.dynamixel.driver.RigDriver``) is
adapted by :class:`RigOutput`.
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from typing import Any, Protocol


class TickOutput(Protocol):
    """A device driven by the tick (the rig, a motion platform...)."""

    def open(self) -> None: ...

    def tick(self, rider: Sequence[float], now: float) -> dict[str, Any] | None: ...

    def estop(self) -> None: ...

    def request_park(self) -> None: ...

    def is_parked(self) -> bool: ...

    def reset(self) -> None: ...

    def close(self) -> None: ...


PARKED_STATES = frozenset({"parked", "torque_off", "off", "disconnected", "closed", "fault", "estop"})
"""Rig states in which shutdown may stop ticking (the rig holds no pose any more)."""


class RigOutput:
    """Adapter for ``riderlive.dynamixel.driver.RigDriver(config, port)``.

    ``rig_file`` is a rig map (``config/rigs/*.toml``); ``port`` overrides its serial
    port (e.g. the emulator's pty). The driver module is imported here, inside the
    tick process, only when a rig is configured.
    """

    def __init__(self, rig_file: str, port: str | None) -> None:
        rig_module = importlib.import_module("riderlive.dynamixel.rig")
        driver_module = importlib.import_module("riderlive.dynamixel.driver")
        self._driver: Any = driver_module.RigDriver(rig_module.load_rig(rig_file), port)
        self._state = "closed"

    def open(self) -> None:
        self._driver.open()

    def tick(self, rider: Sequence[float], now: float) -> dict[str, Any] | None:
        status = self._driver.tick(rider, now)
        if status is None:
            return None
        data: dict[str, Any] = status.to_dict() if hasattr(status, "to_dict") else dict(status)
        state = data.get("state")
        self._state = str(getattr(state, "value", state)).lower()
        return data

    def estop(self) -> None:
        self._driver.estop()

    def request_park(self) -> None:
        self._driver.request_park()

    def is_parked(self) -> bool:
        return self._state in PARKED_STATES

    def reset(self) -> None:
        self._driver.reset()

    def close(self) -> None:
        self._driver.close()
