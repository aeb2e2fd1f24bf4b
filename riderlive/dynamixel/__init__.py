"""Dynamixel Protocol 2.0: the live bus over the ROBOTIS SDK, and an emulator to test it against.

- :mod:`~riderlive.dynamixel.tables`: instructions, error bits, X-series control tables (data).
- ``sdkbus``, ``driver``, ``readback``, ``bringup``, ``rig``, ``servo_map``: the live bus,
  spoken through ``dynamixel_sdk``, and the rig device over it.
- :mod:`~riderlive.dynamixel.emulator`: a bus of emulated servos on a pseudo-terminal, with
  the packet codec only it needs (the live path uses the SDK's).
"""

from __future__ import annotations
