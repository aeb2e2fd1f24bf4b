"""Dynamixel Protocol 2.0: hardware tables, the packet codec and a bus emulator.

- :mod:`riderlive.dynamixel.tables`: instructions, error bits, X-series control tables.
- :mod:`riderlive.dynamixel.protocol`: pure packet encode/decode, CRC-16, byte stuffing.
- :mod:`riderlive.dynamixel.emulator`: an emulated bus of servos on a pseudo-terminal
  that the unmodified ``dynamixel_sdk.PortHandler`` opens by path.
"""

from __future__ import annotations
