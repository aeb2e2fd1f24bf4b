"""Dynamixel Protocol 2.0: hardware tables, the packet codec and a bus emulator.

- :mod:`~riderlive.dynamixel.tables`: instructions, error bits, X-series control tables.
- :mod:`~riderlive.dynamixel.protocol`: pure packet encode/decode, CRC-16, byte stuffing.
- :mod:`~riderlive.dynamixel.emulator`: an emulated bus on a pseudo-terminal that the
  unmodified ``dynamixel_sdk.PortHandler`` opens by path; its parts are
  ``emulator_servo`` (register memory, watchdog, shutdown), ``emulator_registers``
  (struct layouts), ``emulator_motion`` (profile and thermal model),
  ``emulator_instructions`` (what each instruction does), ``emulator_faults`` (fault
  injection) and ``emulator_cli`` (``riderlive servo-emu``).
"""

from __future__ import annotations
