"""Devices near people: the one lifecycle every device the tick drives follows.

- :mod:`~riderlive.devices.lifecycle`: the state names, the transition table, typed
  errors, faults (pure).
- :mod:`~riderlive.devices.device`: :class:`Device`, the lifecycle run from the tick
  (arming with confirmation, latched e-stop, faults -> park -> outputs off, counters).
- :mod:`~riderlive.devices.plug`: the narrow interface a device plugs in (its
  transport, setup steps, arm, moves, outputs-off and read-back).
- :mod:`~riderlive.devices.latch`: the e-stop latch shared by processes, and the gate
  every goal write passes through.
- :mod:`~riderlive.devices.budget`: measured reply timeouts and error budgets.
- :mod:`~riderlive.devices.board`, :mod:`~riderlive.devices.guardian`: heartbeats and
  the dead-man process that parks devices whose controller died.
- :mod:`~riderlive.devices.registry`: which plug a device kind uses.

The Dynamixel rig plugs in through :mod:`riderlive.dynamixel.driver`; the motion
platform will through its own plug.
"""

from __future__ import annotations
