"""Protocol 2.0 instruction semantics over a set of emulated servos: no I/O.

:func:`dispatch` takes a decoded instruction and the servos that hear the bus, runs it
on them and returns their replies in the order they would go on the wire. The bus
(emulator.py) owns the pty, the timing and the reply faults.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from riderlive.dynamixel.emulator.protocol import InstructionPacket, encode_status, fast_status_chunks, le_int
from riderlive.dynamixel.emulator.servo import CLEAR_FIRMWARE, EmulatedServo
from riderlive.dynamixel.tables import BROADCAST_ID, Instruction, Item, StatusError

READ_INSTRUCTIONS = frozenset(
    {
        Instruction.READ,
        Instruction.SYNC_READ,
        Instruction.BULK_READ,
        Instruction.FAST_SYNC_READ,
        Instruction.FAST_BULK_READ,
    }
)


@dataclass(frozen=True)
class Reply:
    """What one servo puts on the wire for an instruction."""

    servo: EmulatedServo
    data: bytes
    waits_return_delay: bool = True
    """False for the links of a fast-read chain after the first (they follow at once)."""
    chained: bool = False
    """Part of a Fast Sync/Bulk Read packet: if it is lost, the rest of the chain is too."""


def dispatch(
    packet: InstructionPacket, active: dict[int, EmulatedServo], now: float, reboot_time_s: float = 0.0
) -> list[Reply]:
    """Run ``packet`` on the servos that hear it; return their replies, in wire order."""
    inst, params = packet.instruction, packet.params
    if packet.id != BROADCAST_ID:
        servo = active[packet.id]
        answers = replies_to(servo, inst)  # the level in force when the packet arrived
        error, data, after = unicast(servo, inst, params, now, reboot_time_s)
        chunks = []
        if answers:
            chunks.append(Reply(servo, encode_status(packet.id, error, data)))
        if after is not None:
            after()
        return chunks
    if inst == Instruction.PING:
        return [Reply(s, encode_status(s.id, s.status_error(), s.ping_params())) for _, s in sorted(active.items())]
    if inst in (Instruction.SYNC_READ, Instruction.FAST_SYNC_READ):
        if len(params) < 5:
            return []
        address, length = le_int(params[0:2]), le_int(params[2:4])
        requests = [(servo_id, address, length) for servo_id in params[4:]]
        return group_read(requests, active, now, fast=inst == Instruction.FAST_SYNC_READ)
    if inst in (Instruction.BULK_READ, Instruction.FAST_BULK_READ):
        if len(params) % 5 or not params:
            return []
        requests = [
            (params[i], le_int(params[i + 1 : i + 3]), le_int(params[i + 3 : i + 5])) for i in range(0, len(params), 5)
        ]
        return group_read(requests, active, now, fast=inst == Instruction.FAST_BULK_READ)
    if inst == Instruction.SYNC_WRITE and len(params) >= 4:
        address, length = le_int(params[0:2]), le_int(params[2:4])
        body = params[4:]
        for i in range(0, len(body) - length, length + 1):
            target = active.get(body[i])
            if target is not None:
                target.write(address, body[i + 1 : i + 1 + length], now)
    elif inst == Instruction.BULK_WRITE:
        i = 0
        while i + 5 <= len(params):
            length = le_int(params[i + 3 : i + 5])
            target = active.get(params[i])
            if target is not None:
                target.write(le_int(params[i + 1 : i + 3]), params[i + 5 : i + 5 + length], now)
            i += 5 + length
    else:
        for servo in active.values():
            if inst == Instruction.FACTORY_RESET and servo.get(Item.FIRMWARE_VERSION) >= CLEAR_FIRMWARE:
                continue  # firmware >= 42 ignores a broadcast factory reset (a whole rig wiped at once)
            _, _, after = unicast(servo, inst, params, now, reboot_time_s)
            if after is not None:
                after()
    return []


def unicast(
    servo: EmulatedServo, inst: int, params: bytes, now: float, reboot_time_s: float = 0.0
) -> tuple[int, bytes, Callable[[], object] | None]:
    """Run one instruction on one servo: (ERR byte, reply params, what to do after replying)."""
    error, data = StatusError.NONE, b""
    after: Callable[[], object] | None = None
    if inst == Instruction.PING:
        data = servo.ping_params()
    elif inst == Instruction.READ:
        if len(params) != 4:
            error = StatusError.DATA_LENGTH
        else:
            error, data = servo.read(le_int(params[0:2]), le_int(params[2:4]), now)
    elif inst in (Instruction.WRITE, Instruction.REG_WRITE):
        if len(params) < 3:
            error = StatusError.DATA_LENGTH
        elif inst == Instruction.WRITE:
            error = servo.write(le_int(params[0:2]), params[2:], now)
        else:
            error = servo.reg_write(le_int(params[0:2]), params[2:])
    elif inst == Instruction.ACTION:
        error = servo.action(now)
    elif inst == Instruction.REBOOT:
        after = functools.partial(servo.reboot, now, reboot_time_s)
    elif inst == Instruction.CLEAR:
        error = servo.clear(params, now)
    elif inst == Instruction.FACTORY_RESET:
        if len(params) != 1:
            error = StatusError.DATA_LENGTH
        else:
            after = functools.partial(servo.factory_reset, params[0], now)
    else:
        error = StatusError.INSTRUCTION
    return servo.status_error(error), data, after


def replies_to(servo: EmulatedServo, inst: int) -> bool:
    """Whether the servo's Status Return Level (68) lets it reply to ``inst``."""
    level = servo.get(Item.STATUS_RETURN_LEVEL)
    return inst == Instruction.PING or level == 2 or (level == 1 and inst in READ_INSTRUCTIONS)


def group_read(
    requests: Sequence[tuple[int, int, int]], active: dict[int, EmulatedServo], now: float, *, fast: bool
) -> list[Reply]:
    """SYNC/BULK_READ (plain: a status per servo; fast: one chained packet)."""
    replies: list[tuple[EmulatedServo | None, int, bytes]] = []
    for servo_id, address, length in requests:
        servo = active.get(servo_id)
        if servo is None or not replies_to(servo, Instruction.SYNC_READ) or (fast and not servo.fast_read):
            replies.append((None, servo_id, bytes(length)))
            continue
        error, data = servo.read(address, length, now)
        replies.append((servo, servo.status_error(error), data if not error else bytes(length) if fast else b""))
    if not fast:
        return [Reply(s, encode_status(s.id, err, data)) for s, err, data in replies if s is not None]
    entries = [(servo_id, err, data) for (_, err, data), (servo_id, _, _) in zip(replies, requests, strict=True)]
    chunks = []
    for index, ((servo, _, _), data) in enumerate(zip(replies, fast_status_chunks(entries), strict=True)):
        if servo is None:
            break  # the chain breaks: nobody continues the packet
        chunks.append(Reply(servo, data, waits_return_delay=index == 0, chained=True))
    return chunks
