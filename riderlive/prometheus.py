"""The Prometheus text exposition format (version 0.0.4), written in one place.

``GET /metrics`` joins the families of several modules (the web process's counters, the
latency histograms, supervision and devices, the platform, the kernel workers, the stage
link); each builds them with :class:`Exposition` instead of formatting lines by hand, so
that every label value is escaped (a client id or a device name may hold ``"``, ``\\`` or a
newline), every value is a number Prometheus reads (``+Inf``, ``-Inf``, ``NaN``; integers
without a fraction) and every family has its ``# HELP`` and ``# TYPE`` once, before its samples.

Pure: strings in, strings out.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

Labels = Mapping[str, object]


class Kind(enum.Enum):
    """A family's ``# TYPE``."""

    COUNTER = "counter"
    GAUGE = "gauge"
    HISTOGRAM = "histogram"


def escape_label(value: object) -> str:
    """A label value as the format quotes it: ``\\`` -> ``\\\\``, ``"`` -> ``\\"``, newline -> ``\\n``."""
    return str(value).replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")


def escape_help(text: str) -> str:
    """A ``# HELP`` text: ``\\`` -> ``\\\\``, newline -> ``\\n`` (quotes stay)."""
    return text.replace("\\", "\\\\").replace("\n", "\\n")


def number(value: float | bool) -> str:
    """A sample value: ``1`` / ``0`` for booleans, integers without a fraction, floats by
    ``repr`` (shortest round trip), ``+Inf`` / ``-Inf`` / ``NaN``."""
    if isinstance(value, bool | int):
        return str(int(value))
    if math.isnan(value):
        return "NaN"
    if math.isinf(value):
        return "+Inf" if value > 0 else "-Inf"
    return repr(float(value))


def sample(name: str, value: float | bool, labels: Labels | None = None) -> str:
    """One sample line: ``name{a="x",b="y"} value`` (labels in the given order)."""
    if not labels:
        return f"{name} {number(value)}"
    pairs = ",".join(f'{key}="{escape_label(v)}"' for key, v in labels.items())
    return f"{name}{{{pairs}}} {number(value)}"


@dataclass
class Exposition:
    """Families in the order added; :meth:`text` is the body of ``/metrics``."""

    lines: list[str] = field(default_factory=list)

    def family(self, name: str, kind: Kind, help_text: str, samples: Iterable[str]) -> None:
        """``# HELP``, ``# TYPE`` and ``samples`` (lines made by :func:`sample`)."""
        self.lines.append(f"# HELP {name} {escape_help(help_text)}")
        self.lines.append(f"# TYPE {name} {kind.value}")
        self.lines.extend(samples)

    def one(self, name: str, kind: Kind, help_text: str, value: float | bool) -> None:
        """A family of one unlabelled sample."""
        self.family(name, kind, help_text, [sample(name, value)])

    def by_label(
        self, name: str, kind: Kind, help_text: str, label: str, values: Iterable[tuple[object, float | bool]]
    ) -> None:
        """A family with one label: a sample per ``(label value, value)``."""
        self.family(name, kind, help_text, [sample(name, v, {label: key}) for key, v in values])

    def text(self) -> str:
        """The exposition: one line each, newline-terminated ("" when empty)."""
        return "".join(line + "\n" for line in self.lines)
