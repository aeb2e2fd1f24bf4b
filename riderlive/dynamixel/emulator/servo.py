"""One emulated X-series servo: register memory, access rules, watchdog and shutdown.

No I/O and no clock of its own: the bus passes ``now`` (seconds, monotonic) to every
call. Register semantics follow the ROBOTIS e-manual:

- Writes are checked before anything changes (:mod:`riderlive.dynamixel.emulator.access`):
  EEPROM items (address < 64) only with Torque Enable 0, read-only items and bytes outside
  any item refused (Access, Data Length), values outside a range (Data Range, Data Limit).
- A hardware error whose bit is in Shutdown (63) turns torque off; every status then
  carries the Alert bit and torque cannot be enabled again until REBOOT.
- Bus Watchdog (98, 20 ms units): with torque on, no instruction for longer than the
  set time stops the servo and sets the register to -1; goal writes then fail with Data
  Range until 0 is written to it.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, replace

from riderlive.dynamixel.emulator import motion
from riderlive.dynamixel.emulator.access import write_error
from riderlive.dynamixel.emulator.registers import BLOCKS, LAYOUTS, profile_of
from riderlive.dynamixel.models import MODELS, ModelSpec, model_spec
from riderlive.dynamixel.tables import (
    ALERT_BIT,
    BUS_WATCHDOG_UNIT_S,
    PULSES_PER_TURN,
    RETURN_DELAY_UNIT_S,
    Area,
    FactoryResetOption,
    HardwareError,
    Item,
    StatusError,
)

CONTROL_PERIOD_S = motion.SUBSTEP_S
"""The emulated servo's control loop period: its state changes in whole cycles."""
THERMAL_CHUNK_CYCLES = 10
"""Longest stretch integrated at once (control cycles) before checking the temperature."""
_OVERHEATING = int(HardwareError.OVERHEATING)
_WATCHDOG_ADDRESS = next(iter(MODELS.values())).items[Item.BUS_WATCHDOG].address

CLEAR_FIRMWARE = 42
"""Firmware from which X-series servos accept CLEAR and ignore a broadcast FACTORY_RESET."""
CLEAR_SIGNATURE = bytes((0x44, 0x58, 0x4C, 0x22))
"""The fixed bytes after CLEAR's option ("DXL\"")."""


@dataclass(frozen=True)
class ServoSetup:
    """How an emulated servo starts: its ID, model and where its horn is (pulses)."""

    id: int
    model: str
    position: int = 2048
    fast_read: bool | None = None
    """Whether it answers FAST_SYNC/BULK_READ; None: as the model's firmware does.
    False emulates an older firmware, which ignores those instructions."""


class EmulatedServo:
    """Register memory and behaviour of one servo. Not thread-safe: the bus locks."""

    def __init__(self, setup: ServoSetup, baud: int, now: float = 0.0) -> None:
        self.spec: ModelSpec = model_spec(setup.model)
        self.fast_read = self.spec.fast_sync_read if setup.fast_read is None else setup.fast_read
        self.memory = bytearray(self.spec.table_size)
        self._layout = LAYOUTS[self.spec.model]
        self._torque_address = self.spec.items[Item.TORQUE_ENABLE].address
        self._goal_address = self.spec.items[Item.GOAL_POSITION].address
        self._boot_time = now
        self._last_advance = now
        self._last_instruction = now
        self.watchdog_tripped = False
        self.registered: tuple[int, bytes] | None = None
        self._external_load = 0.0
        self._profile_cache: motion.Profile | None = None
        self._synced: tuple[object, ...] = ()
        self._outputs_stale = True
        self._output_limits = (0, 0, 0, 0)
        self.deaf_until = 0.0
        """The servo ignores the bus until this time (rebooting)."""
        self.thermal = motion.ThermalParams()
        self.state = motion.MotionState(position=float(setup.position), temperature=self.thermal.ambient_c)
        self.voltage = self.spec.nominal_voltage
        self._reset_registers(keep_eeprom=False)
        self.set(Item.ID, setup.id)
        self.set(Item.BAUD_RATE, self.spec.baud_code(baud))
        self._sync_outputs(now)

    # -- raw register access (no checks; for the bus, tests and fault injection) --------

    def get(self, item: Item) -> int:
        address, read_format, _, _ = self._layout[item]
        value: int = struct.unpack_from(read_format, self.memory, address)[0]
        return value

    def set(self, item: Item, value: int) -> None:
        self._put(item, value)
        self._profile_cache = None
        self._synced = ()
        self._outputs_stale = True

    def _put(self, item: Item, value: int) -> None:
        """Store without invalidating the cached profile (for the model's own outputs)."""
        address, _, write_format, mask = self._layout[item]
        struct.pack_into(write_format, self.memory, address, value & mask)

    @property
    def external_load(self) -> float:
        """Extra effort from outside (something pushing on the horn), 0..1; heats the servo."""
        return self._external_load

    @external_load.setter
    def external_load(self, value: float) -> None:
        self._external_load = value
        self._profile_cache = None

    @property
    def id(self) -> int:
        return self.get(Item.ID)

    @property
    def torque_on(self) -> bool:
        return self.memory[self._torque_address] == 1

    @property
    def hardware_error(self) -> int:
        return self.get(Item.HARDWARE_ERROR_STATUS)

    @property
    def return_delay_s(self) -> float:
        return self.get(Item.RETURN_DELAY_TIME) * RETURN_DELAY_UNIT_S

    def status_error(self, error: StatusError = StatusError.NONE) -> int:
        """The ERR byte for a reply: ``error`` plus the Alert bit while a hardware error stands."""
        return int(error) | (ALERT_BIT if self.hardware_error else 0)

    def _reset_registers(self, *, keep_eeprom: bool) -> None:
        for spec in self.spec:
            if keep_eeprom and spec.area is Area.EEPROM:
                continue
            self.set(spec.item, spec.default)
        self.registered = None
        self.watchdog_tripped = False
        self.set(Item.GOAL_POSITION, round(self.state.position))

    # -- time ----------------------------------------------------------------------------

    @property
    def last_instruction(self) -> float:
        """Clock time (s, the bus's clock) of the last instruction packet for this servo: the
        Bus Watchdog's span counts from it."""
        return self._last_instruction

    def feed_watchdog(self, now: float) -> None:
        """An instruction packet for this servo (or broadcast) arrived at ``now``."""
        watchdog = self.memory[_WATCHDOG_ADDRESS]
        if 0 < watchdog < 0x80 and now > self._last_instruction + watchdog * BUS_WATCHDOG_UNIT_S:
            self.advance(now)  # the deadline passed before this packet: trip first
        self._last_instruction = now

    def advance(self, now: float, *, outputs: bool = True) -> None:
        """Run the motion and thermal model up to ``now``; trip the watchdog on time.

        ``outputs=False`` leaves the present-value registers stale (a write needs only the
        model state); anything that reads registers advances with outputs.
        """
        watchdog = self.get(Item.BUS_WATCHDOG)
        if self.torque_on and watchdog > 0 and not self.watchdog_tripped:
            deadline = self._last_instruction + watchdog * BUS_WATCHDOG_UNIT_S
            if now > deadline:
                self._integrate(max(deadline, self._last_advance))
                self.watchdog_tripped = True
                self.set(Item.BUS_WATCHDOG, -1)
                self.state = replace(self.state, velocity=0.0)
                self.set(Item.GOAL_POSITION, round(self.state.position) + self.get(Item.HOMING_OFFSET))
                self.set(Item.GOAL_VELOCITY, 0)
        self._integrate(now)
        self._check_voltage()
        if outputs and self._outputs_stale:
            self._sync_outputs(self._last_advance)

    def _integrate(self, now: float) -> None:
        """Run whole control cycles (1 kHz, like the servo's own loop) up to ``now``."""
        cycles = int((now - self._last_advance) / CONTROL_PERIOD_S)
        if cycles <= 0:
            return
        limit = self.get(Item.TEMPERATURE_LIMIT)
        while cycles > 0:  # in pieces, so overheating shuts the servo down when it happens
            chunk = cycles
            if not self.hardware_error & _OVERHEATING:
                effort = motion.holding_effort(self._profile())
                crossing = motion.seconds_until_temperature(self.state, effort, limit, self.thermal)
                if crossing is not None:
                    chunk = min(cycles, max(1, math.ceil(crossing / CONTROL_PERIOD_S)))
                if self.state.moving:  # acceleration adds heat the estimate does not see
                    chunk = min(chunk, THERMAL_CHUNK_CYCLES)
            cycles -= chunk
            dt = chunk * CONTROL_PERIOD_S
            self._last_advance += dt
            self.state = motion.step(self.state, self._profile(), dt, self.thermal)
            if self.state.temperature >= limit and not self.hardware_error & _OVERHEATING:
                self.raise_hardware_error(HardwareError.OVERHEATING)
        self._outputs_stale = True

    def _profile(self) -> motion.Profile:
        if self._profile_cache is None:
            self._profile_cache = self._make_profile()
        return self._profile_cache

    def _make_profile(self) -> motion.Profile:
        profile, self._output_limits = profile_of(
            self.spec,
            self.memory,
            torque_on=self.memory[self._torque_address] == 1 and not self.watchdog_tripped,
            mode=self.get(Item.OPERATING_MODE),
            external_load=self.external_load,
        )
        return profile

    def _sync_outputs(self, now: float) -> None:
        """Write the model state into the read-only present-value registers."""
        state = self.state
        self._put(Item.REALTIME_TICK, int((now - self._boot_time) * 1000) % 32768)
        profile = self._profile()
        key = (state, profile, self.voltage)
        if key == self._synced:
            self._outputs_stale = False
            return  # nothing the registers show has changed
        self._synced = key
        self._outputs_stale = False
        offset, threshold, current_limit, pwm_limit = self._output_limits
        position = round(state.position) + offset
        velocity = motion.velocity_to_register(state.velocity)
        moving = abs(velocity) > threshold or (profile.torque_on and state.velocity != 0.0)
        signed_effort = math.copysign(state.effort, state.acceleration or 1.0)
        _, _, outputs = BLOCKS[self.spec.model]
        outputs.write(
            self.memory,
            {
                Item.MOVING: int(moving),
                Item.MOVING_STATUS: 0x01 if not moving and profile.torque_on else 0x00,
                Item.PRESENT_PWM: round(signed_effort * pwm_limit),
                Item.PRESENT_CURRENT: round(signed_effort * current_limit),
                Item.PRESENT_LOAD: round(signed_effort * 1000),
                Item.PRESENT_VELOCITY: velocity,
                Item.PRESENT_POSITION: position,
                Item.VELOCITY_TRAJECTORY: velocity,
                Item.POSITION_TRAJECTORY: position,
                Item.PRESENT_INPUT_VOLTAGE: round(self.voltage * 10),
                Item.PRESENT_TEMPERATURE: min(255, max(0, round(state.temperature))),
            },
        )

    # -- hardware errors -----------------------------------------------------------------

    def heat_to(self, temperature_c: float) -> None:
        """Set the winding temperature (fault injection); over the limit it overheats."""
        self.state = replace(self.state, temperature=temperature_c)
        if temperature_c >= self.get(Item.TEMPERATURE_LIMIT):
            self.raise_hardware_error(HardwareError.OVERHEATING)
        self._synced = ()
        self._sync_outputs(self._last_advance)

    def raise_hardware_error(self, bits: int) -> None:
        """Latch hardware error ``bits``; those enabled in Shutdown (63) turn torque off."""
        self.set(Item.HARDWARE_ERROR_STATUS, self.hardware_error | bits)
        if self.hardware_error & self.get(Item.SHUTDOWN):
            self.set(Item.TORQUE_ENABLE, 0)

    def set_supply(self, volts: float) -> None:
        """The supply voltage (V): outside Min/Max Voltage Limit (34/32, 0.1 V) the servo
        latches an Input Voltage error (and shuts down if Shutdown says so)."""
        self.voltage = volts
        self._synced = ()
        self._check_voltage()
        self._sync_outputs(self._last_advance)

    def _check_voltage(self) -> None:
        tenths = round(self.voltage * 10)
        inside = self.get(Item.MIN_VOLTAGE_LIMIT) <= tenths <= self.get(Item.MAX_VOLTAGE_LIMIT)
        if not inside and not self.hardware_error & HardwareError.INPUT_VOLTAGE:
            self.raise_hardware_error(HardwareError.INPUT_VOLTAGE)

    @property
    def shut_down(self) -> bool:
        return bool(self.hardware_error & self.get(Item.SHUTDOWN))

    # -- instructions ----------------------------------------------------------------------

    def read(self, address: int, length: int, now: float) -> tuple[StatusError, bytes]:
        """READ at ``now``: ``length`` bytes from ``address`` (gaps between items read as 0)."""
        if length < 1 or address + length > len(self.memory):
            return StatusError.ACCESS, b""
        self.advance(now)
        return StatusError.NONE, bytes(self.memory[address : address + length])

    def check_write(self, address: int, data: bytes) -> StatusError:
        """Why a WRITE of ``data`` at ``address`` would be refused (NONE if allowed): :func:`write_error`."""
        return write_error(self.spec, self.get, self.watchdog_tripped, address, data)

    def write(self, address: int, data: bytes, now: float) -> StatusError:
        """WRITE: check, then store ``data`` and apply side effects. Nothing changes on error."""
        error = self.check_write(address, data)
        if error is not StatusError.NONE:
            return error
        self.advance(now, outputs=False)
        cache = self._profile_cache
        if address == self._goal_address and len(data) == 4 and cache is not None:
            # The common case, a new goal position: patch the cached profile.
            self.memory[address : address + 4] = data
            goal = int.from_bytes(data, "little", signed=True) - self._output_limits[0]
            self._profile_cache = replace(cache, goal_position=float(goal))
            self._outputs_stale = True
            return StatusError.NONE
        torque_before = self.torque_on
        mode_before = self.get(Item.OPERATING_MODE)
        self.memory[address : address + len(data)] = data
        self._profile_cache = None
        self._synced = ()
        self._outputs_stale = True
        if self.torque_on and not torque_before:
            # Torque on holds where the horn is: the goal becomes the present position.
            self.set(Item.GOAL_POSITION, round(self.state.position) + self.get(Item.HOMING_OFFSET))
            self.state = replace(self.state, velocity=0.0)
        if self.get(Item.OPERATING_MODE) != mode_before:
            self.set(Item.GOAL_VELOCITY, 0)
        if self.watchdog_tripped and self.get(Item.BUS_WATCHDOG) == 0:
            self.watchdog_tripped = False
        return StatusError.NONE

    def reg_write(self, address: int, data: bytes) -> StatusError:
        """REG_WRITE: check and hold the write until ACTION."""
        error = self.check_write(address, data)
        if error is StatusError.NONE:
            self.registered = (address, bytes(data))
            self.set(Item.REGISTERED_INSTRUCTION, 1)
        return error

    def action(self, now: float) -> StatusError:
        """ACTION: apply the held REG_WRITE (Instruction error if there is none)."""
        if self.registered is None:
            return StatusError.INSTRUCTION
        address, data = self.registered
        self.registered = None
        self.set(Item.REGISTERED_INSTRUCTION, 0)
        return self.write(address, data, now)

    def reboot(self, now: float, duration_s: float) -> None:
        """REBOOT: RAM back to defaults (torque off), errors cleared, EEPROM kept."""
        self.advance(now)
        self._reset_registers(keep_eeprom=True)
        self._boot_time = now
        self.deaf_until = now + duration_s
        self._last_instruction = now
        self._sync_outputs(now)

    def factory_reset(self, option: int, now: float) -> StatusError:
        """FACTORY_RESET: every item to its default, keeping ID (and baud) if asked."""
        if option not in {int(o) for o in FactoryResetOption}:
            return StatusError.DATA_RANGE
        keep_id, keep_baud = self.id, self.get(Item.BAUD_RATE)
        self._reset_registers(keep_eeprom=False)
        if option in (FactoryResetOption.KEEP_ID, FactoryResetOption.KEEP_ID_AND_BAUD):
            self.set(Item.ID, keep_id)
        if option == FactoryResetOption.KEEP_ID_AND_BAUD:
            self.set(Item.BAUD_RATE, keep_baud)
        self._sync_outputs(now)
        return StatusError.NONE

    def clear(self, params: bytes, now: float) -> StatusError:
        """CLEAR (0x10), firmware >= 42: option 0x01 with the fixed ``44 58 4C 22`` resets the
        multi-turn count (Present Position back within one turn); only while not moving."""
        if self.get(Item.FIRMWARE_VERSION) < CLEAR_FIRMWARE:
            return StatusError.INSTRUCTION
        if len(params) != 5:
            return StatusError.DATA_LENGTH
        if params[0] != 0x01 or params[1:] != CLEAR_SIGNATURE:
            return StatusError.DATA_RANGE
        self.advance(now)
        if self.state.velocity != 0.0 or self.get(Item.MOVING):
            return StatusError.RESULT_FAIL
        turns = math.floor(self.state.position / PULSES_PER_TURN) * PULSES_PER_TURN
        self.state = replace(self.state, position=self.state.position - turns)
        self.set(Item.GOAL_POSITION, self.get(Item.GOAL_POSITION) - turns)
        self._synced = ()
        return StatusError.NONE

    def ping_params(self) -> bytes:
        return self.get(Item.MODEL_NUMBER).to_bytes(2, "little") + bytes((self.get(Item.FIRMWARE_VERSION),))

    def listens_at(self, baud: int) -> bool:
        """Whether the servo's Baud Rate (8) matches the bus speed."""
        return self.spec.baud_rates.get(self.get(Item.BAUD_RATE)) == baud
