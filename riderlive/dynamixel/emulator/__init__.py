"""An emulated Dynamixel bus on a pseudo-terminal that the unmodified ``dynamixel_sdk.PortHandler``
opens by path (CI has no servos; ``riderlive servo-emu`` runs one by hand).

| module | owns |
| --- | --- |
| ``bus.py`` | the bus thread on the pty master, wire timing, per-servo dispatch |
| ``protocol.py`` | Protocol 2.0 packets: encode/decode, CRC-16, byte stuffing (pure) |
| ``servo.py`` | one servo: register memory, Bus Watchdog, shutdown, the effects of writes |
| ``access.py`` | the e-manual's write checks (access, range, torque lock), pure |
| ``registers.py`` | struct layouts and the motion profile the registers ask for |
| ``motion.py`` | the profile and thermal model |
| ``instructions.py`` | what each instruction does and replies |
| ``faults.py`` | fault injection (silence, corruption, hardware errors, a vanished port) |
| ``cli.py`` | ``riderlive servo-emu`` |
"""

from __future__ import annotations

from riderlive.dynamixel.emulator.bus import DEFAULT_BAUD, EmulatedBus
from riderlive.dynamixel.emulator.servo import ServoSetup

__all__ = ["DEFAULT_BAUD", "EmulatedBus", "ServoSetup"]
