"""Open Sound Control 1.0 encoding, the little VMC needs: messages of ``s``/``i``/``f`` and bundles.

Pure (bytes in, bytes out). Big-endian, every part padded to 4 bytes; strings are
ASCII, NUL-terminated. :class:`MessageTemplate` encodes a message whose address and
leading string are fixed once, so a frame only packs its numbers.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

BUNDLE_TAG = b"#bundle\x00"
IMMEDIATELY = 1
"""The OSC time tag meaning "now" (receivers apply the bundle on arrival)."""

Arg = str | int | float


def string(text: str) -> bytes:
    """An OSC string: ASCII, NUL-terminated, padded with NULs to a multiple of 4."""
    raw = text.encode("ascii") + b"\x00"
    return raw + b"\x00" * (-len(raw) % 4)


def _tag(arg: Arg) -> str:
    if isinstance(arg, str):
        return "s"
    if isinstance(arg, bool) or not isinstance(arg, int | float):
        raise TypeError(f"OSC argument must be str, int or float, got {type(arg).__name__}")
    return "i" if isinstance(arg, int) else "f"


def message(address: str, args: Sequence[Arg] = ()) -> bytes:
    """One OSC message: address, type tags, arguments (``i`` int32, ``f`` float32, ``s`` string)."""
    tags = "".join(_tag(a) for a in args)
    out = [string(address), string("," + tags)]
    for tag, arg in zip(tags, args, strict=True):
        if tag == "s":
            out.append(string(str(arg)))
        elif tag == "i":
            out.append(struct.pack(">i", arg))
        else:
            out.append(struct.pack(">f", arg))
    return b"".join(out)


def element(encoded: bytes) -> bytes:
    """A message as a bundle element: its int32 size, then the message."""
    return struct.pack(">i", len(encoded)) + encoded


def bundle(messages: Sequence[bytes], timetag: int = IMMEDIATELY) -> bytes:
    """An OSC bundle of encoded messages."""
    return bundle_of_elements([element(m) for m in messages], timetag)


class MessageTemplate:
    """``address (s)name (f)x N``: the fixed head encoded once; :meth:`encode` packs the floats.

    ``encode`` returns the element as it goes into a bundle: int32 size, then the message.
    """

    def __init__(self, address: str, name: str, floats: int) -> None:
        head = string(address) + string(",s" + "f" * floats) + string(name)
        self._pack = struct.Struct(f">i{len(head)}s{floats}f").pack
        self._size = len(head) + 4 * floats
        self._head = head

    def encode(self, *values: float) -> bytes:
        return self._pack(self._size, self._head, *values)


def bundle_of_elements(elements: Sequence[bytes], timetag: int = IMMEDIATELY) -> bytes:
    """A bundle of elements already prefixed with their size (:meth:`MessageTemplate.encode`)."""
    return BUNDLE_TAG + struct.pack(">Q", timetag) + b"".join(elements)
