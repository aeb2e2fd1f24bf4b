"""Fault injection for the emulated bus: what can go wrong, as data, and a text form.

Text form (the CLI's ``--fault``, also usable from tests)::

    KIND[:ID[:AMOUNT[:SEED]]][@SECONDS]

    drop:3:5          the next 5 replies of servo 3 are lost
    drop:3:0.1:7      each reply of servo 3 is lost with probability 0.1 (seed 7)
    corrupt:3:2       the next 2 replies of servo 3 arrive with a bad CRC
    lag:3:80          the next reply of servo 3 reaches the host over 80 ms, a byte at a time (a
                      serial path the host does not carry in time: a starved tty worker); the
                      bus handles nothing else meanwhile
    vanish:3@2.5      servo 3 stops answering (and hearing) 2.5 s after start
    reappear:3        servo 3 is back
    overheat:3        servo 3's temperature jumps above its limit (Overheating error)
    overload:3        servo 3 reports an Overload hardware error
    voltage:3         servo 3's supply drops below its Min Voltage Limit (Input Voltage error)
    voltage:3:13.5    servo 3's supply is 13.5 V (an error when outside its voltage limits)
    close@10          the pseudo-terminal disappears 10 s after start
    clear[:3]         remove reply faults (of one servo, or all)

An AMOUNT with a decimal point is a probability; otherwise a count.
"""

from __future__ import annotations

import enum
import random
from dataclasses import dataclass, field


class FaultKind(enum.StrEnum):
    DROP = "drop"
    CORRUPT = "corrupt"
    LAG = "lag"
    VANISH = "vanish"
    REAPPEAR = "reappear"
    OVERHEAT = "overheat"
    OVERLOAD = "overload"
    VOLTAGE = "voltage"
    CLOSE = "close"
    CLEAR = "clear"


NEEDS_ID = frozenset(FaultKind) - {FaultKind.CLOSE, FaultKind.CLEAR}
REPLY_FAULTS = frozenset({FaultKind.DROP, FaultKind.CORRUPT, FaultKind.LAG})


@dataclass(frozen=True)
class FaultSpec:
    """One fault to inject, ``at_s`` seconds after the emulator starts (CLI) or now (tests)."""

    kind: FaultKind
    servo_id: int | None = None
    count: int | None = None
    probability: float | None = None
    seed: int = 0
    at_s: float = 0.0
    volts: float | None = None
    """``voltage``: the supply voltage to set (None: below the servo's Min Voltage Limit)."""
    lag_ms: float = 0.0
    """``lag``: how long the reply takes to reach the host (ms)."""


def parse_fault(text: str) -> FaultSpec:
    """Parse the text form above; ValueError with the reason and the grammar on bad input."""
    grammar = "expected KIND[:ID[:AMOUNT[:SEED]]][@SECONDS], KIND one of " + ", ".join(k.value for k in FaultKind)
    body, _, when = text.strip().partition("@")
    parts = body.split(":")
    try:
        kind = FaultKind(parts[0].lower())
        at_s = float(when) if when else 0.0
        servo_id = int(parts[1]) if len(parts) > 1 else None
        count = probability = volts = None
        lag_ms = 0.0
        if len(parts) > 2 and kind is FaultKind.VOLTAGE:
            volts = float(parts[2])
        elif len(parts) > 2 and kind is FaultKind.LAG:
            lag_ms = float(parts[2])
        elif len(parts) > 2:
            if "." in parts[2]:
                probability = float(parts[2])
            else:
                count = int(parts[2])
        seed = int(parts[3]) if len(parts) > 3 else 0
    except ValueError:
        raise ValueError(f"bad fault {text!r}: {grammar}") from None
    if len(parts) > 4 or at_s < 0:
        raise ValueError(f"bad fault {text!r}: {grammar}")
    if kind in NEEDS_ID and servo_id is None:
        raise ValueError(f"bad fault {text!r}: {kind.value} needs a servo id")
    if probability is not None and not 0.0 <= probability <= 1.0:
        raise ValueError(f"bad fault {text!r}: probability must be within 0..1")
    if kind is FaultKind.LAG and not 0.0 < lag_ms <= 10_000.0:
        raise ValueError(f"bad fault {text!r}: lag needs a length in ms within 0..10000 (lag:ID:MS)")
    if kind in REPLY_FAULTS and count is None and probability is None:
        count = 1
    return FaultSpec(kind, servo_id, count, probability, seed, at_s, volts, lag_ms)


@dataclass
class ReplyFault:
    """Affects the next ``remaining`` replies, or each reply with ``probability``."""

    remaining: int | None = None
    probability: float = 0.0
    rng: random.Random = field(default_factory=random.Random)

    def fires(self) -> bool:
        if self.remaining is not None:
            if self.remaining <= 0:
                return False
            self.remaining -= 1
            return True
        return self.rng.random() < self.probability


@dataclass
class ServoFaults:
    """The reply faults currently set on one servo."""

    drop: ReplyFault | None = None
    corrupt: ReplyFault | None = None
    lag: ReplyFault | None = None
    lag_s: float = 0.0
    """How long a lagged reply takes to reach the host (s)."""
    vanished: bool = False

    def set_reply_fault(self, spec: FaultSpec) -> None:
        fault = ReplyFault(spec.count, spec.probability or 0.0, random.Random(spec.seed))
        if spec.kind is FaultKind.DROP:
            self.drop = fault
        elif spec.kind is FaultKind.LAG:
            self.lag, self.lag_s = fault, spec.lag_ms / 1000.0
        else:
            self.corrupt = fault


def corrupt(chunk: bytes) -> bytes:
    """``chunk`` with its last byte (a CRC byte) inverted: the receiver's CRC check fails."""
    return chunk[:-1] + bytes((chunk[-1] ^ 0xFF,)) if chunk else chunk
