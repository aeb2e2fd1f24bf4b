"""What the web process reports while no tick generation is serving (pure).

After a tick dies or is declared hung, and until the next generation's first heartbeat,
the status the dead tick last wrote is not the truth: its devices are in the guardian's
hands (or nobody's). :func:`down_status` keeps the dead status's settings (preset, gait,
mode: they are handed to the next generation) but says ``driver`` ``down``, ``tick_up``
false, ``restarting`` (the supervisor is failing over), no rig or platform detail, and
for each device what the guardian reports (``devices.board.GuardianReport``) or ``unknown``:

| guardian report | ``state`` | ``outputs_off_confirmed`` |
| --- | --- | --- |
| parking | ``parking`` | false |
| stopping | ``unknown`` (outputs off being sent) | false |
| outputs off | ``parked`` | true |
| unconfirmed, unreachable | ``unknown`` | false |
| not connected | ``disconnected`` | false |
| none (no guardian, or not acted yet) | ``unknown`` | false |
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from riderlive.devices.board import GuardianReport
from riderlive.devices.registry import DeviceSpec

UNKNOWN = "unknown"
"""A device state the web process cannot vouch for (not a ``DeviceState``: nobody drives it)."""
_SHOWN: dict[GuardianReport, tuple[str, str, bool]] = {
    GuardianReport.NONE: (UNKNOWN, "the tick is down; the guardian has not reported", False),
    GuardianReport.PARKING: ("parking", "the guardian is easing it to park, then outputs off", False),
    GuardianReport.STOPPING: (UNKNOWN, "the guardian is turning its outputs off", False),
    GuardianReport.OUTPUTS_OFF: ("parked", "stopped by the guardian: outputs off, read back", True),
    GuardianReport.UNCONFIRMED: (UNKNOWN, "the guardian sent outputs off; not confirmed", False),
    GuardianReport.UNREACHABLE: (UNKNOWN, "the guardian could not reach its port", False),
    GuardianReport.NOT_CONNECTED: ("disconnected", "the dead tick had not connected it", False),
}


def device_down(spec: DeviceSpec, report: GuardianReport, estop: bool) -> dict[str, Any]:
    """One device's summary (the keys of ``TickDevices.status()['devices']``) while the tick is down."""
    state, detail, off = _SHOWN[report]
    return {
        "name": spec.name,
        "kind": spec.kind,
        "state": state,
        "detail": detail,
        "fault": None,
        "armed_by": None,
        "outputs_off_confirmed": off,
        "estop": estop,
        "counters": {},
    }


def down_status(
    last: dict[str, Any],
    specs: Sequence[DeviceSpec],
    reports: Sequence[GuardianReport],
    *,
    estop: bool,
    reason: str | None,
    generation: int,
) -> dict[str, Any]:
    """The status while generation ``generation`` is not serving (see the module docstring)."""
    return {
        **last,
        "driver": "down",
        "tick_up": False,
        "restarting": True,
        "reason": reason,
        "generation": generation,
        "estop": estop,
        "rig": None,
        "platform": None,
        "devices": [device_down(spec, report, estop) for spec, report in zip(specs, reports, strict=True)],
        "phase_lock": None,
        "saddle": None,
    }
