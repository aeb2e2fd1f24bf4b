"""The exposition format written in one place: every label value and help text read back
as written (by a reader of the format's grammar, independent of the writer), values in the
format's spelling, each family's HELP and TYPE once before its samples."""

from __future__ import annotations

import math
import re

from hypothesis import example, given
from hypothesis import strategies as st

from riderlive.prometheus import Exposition, Kind, escape_label, number, sample

NAME = re.compile(r"[a-zA-Z_:][a-zA-Z0-9_:]*")


def read_labels(text: str) -> dict[str, str]:
    """``a="x",b="y"`` -> {a: x, b: y}, unescaping ``\\\\``, ``\\"``, ``\\n`` (the format's grammar)."""
    out: dict[str, str] = {}
    i = 0
    while i < len(text):
        key = NAME.match(text, i)
        assert key is not None and text[key.end() : key.end() + 2] == '="', text[i:]
        i, value = key.end() + 2, []
        while text[i] != '"':
            if text[i] == "\\":
                value.append({"\\": "\\", '"': '"', "n": "\n"}[text[i + 1]])
                i += 2
            else:
                value.append(text[i])
                i += 1
        out[key.group()] = "".join(value)
        i += 1
        if i < len(text):
            assert text[i] == ",", text[i:]
            i += 1
    return out


def read_sample(line: str) -> tuple[str, dict[str, str], float]:
    """One sample line -> (name, labels, value)."""
    name = NAME.match(line)
    assert name is not None
    rest = line[name.end() :]
    labels: dict[str, str] = {}
    if rest.startswith("{"):
        end = rest.rindex("} ")
        labels, rest = read_labels(rest[1:end]), rest[end + 1 :]
    assert rest.startswith(" ") and " " not in rest[1:], line
    spelled = rest[1:]
    assert spelled in ("+Inf", "-Inf", "NaN") or re.fullmatch(r"-?\d+(\.\d+)?(e[+-]?\d+)?", spelled), spelled
    return name.group(), labels, float(spelled.replace("Inf", "inf"))


label_values = st.text(st.characters(codec="utf-8"), max_size=30)


@given(st.dictionaries(st.from_regex(NAME, fullmatch=True), label_values, max_size=4), label_values)
@example({"client": 'a"b\\c\nd'}, "x")
def test_a_label_value_reads_back_as_written(labels: dict[str, str], _: str) -> None:
    name, read, value = read_sample(sample("riderlive_x_total", 3, labels))
    assert (name, read, value) == ("riderlive_x_total", labels, 3.0)
    assert "\n" not in sample("riderlive_x_total", 3, labels)


@given(st.floats(allow_nan=True, allow_infinity=True) | st.integers(-(2**62), 2**62) | st.booleans())
def test_a_value_is_spelled_as_the_format_reads_it(value: float | bool) -> None:
    _, _, read = read_sample(sample("x", value))
    if isinstance(value, float) and math.isnan(value):
        assert math.isnan(read)
    else:
        assert read == float(value)
    if isinstance(value, bool | int):
        assert number(value) == str(int(value))  # counters stay integers


def test_hand_spelled_values() -> None:
    assert [number(v) for v in (True, 0, 7, 0.25, math.inf, -math.inf)] == ["1", "0", "7", "0.25", "+Inf", "-Inf"]
    assert number(math.nan) == "NaN"
    assert escape_label('say "hi"\\\n') == 'say \\"hi\\"\\\\\\n'


@given(st.text(max_size=40))
def test_help_text_stays_on_its_line(help_text: str) -> None:
    out = Exposition()
    out.one("x_total", Kind.COUNTER, help_text, 1)
    lines = out.text().split("\n")[:-1]  # the format's lines end with \n only
    assert len(lines) == 3 and lines[0].startswith("# HELP x_total ") and lines[1] == "# TYPE x_total counter"


def test_families_come_with_help_and_type_once_before_their_samples() -> None:
    out = Exposition()
    out.one("a_total", Kind.COUNTER, "A.", 2)
    out.by_label("b", Kind.GAUGE, "B.", "path", [("/ws/rider", 1), ("/ws/horse", 0)])
    out.family("c", Kind.GAUGE, "C, none yet.", [])
    assert out.text() == (
        "# HELP a_total A.\n# TYPE a_total counter\na_total 2\n"
        '# HELP b B.\n# TYPE b gauge\nb{path="/ws/rider"} 1\nb{path="/ws/horse"} 0\n'
        "# HELP c C, none yet.\n# TYPE c gauge\n"
    )
    assert Exposition().text() == ""
