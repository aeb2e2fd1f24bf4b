"""OSC encoding, read back by python-osc's parser (an independent implementation)."""

from __future__ import annotations

import math
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.vmc import osc

osc_message = pytest.importorskip("pythonosc.osc_message")
osc_bundle = pytest.importorskip("pythonosc.osc_bundle")

text = st.text(st.characters(min_codepoint=32, max_codepoint=126), max_size=40)
args = st.lists(
    st.one_of(text, st.integers(-(2**31), 2**31 - 1), st.floats(allow_nan=False, allow_infinity=False, width=32)),
    max_size=12,
)


@settings(max_examples=50)
@given(address=text.map(lambda s: "/" + s), values=args)
def test_messages_parse_back_with_their_type_tags_and_values(address: str, values: list[str | int | float]) -> None:
    data = osc.message(address, values)
    assert len(data) % 4 == 0
    parsed = osc_message.OscMessage(data)
    assert parsed.address == address
    expected_tags = "".join("s" if isinstance(v, str) else "i" if isinstance(v, int) else "f" for v in values)
    assert data[len(osc.string(address)) :].startswith(osc.string("," + expected_tags))
    for got, want in zip(parsed.params, values, strict=True):
        if isinstance(want, float):
            assert got == struct.unpack(">f", struct.pack(">f", want))[0]
        else:
            assert got == want


def test_bundles_parse_back_in_order_and_apply_immediately() -> None:
    messages = [osc.message("/a", [1]), osc.message("/b", ["x", 2.5]), osc.message("/c")]
    parsed = osc_bundle.OscBundle(osc.bundle(messages))
    assert parsed.num_contents == 3
    assert [m.address for m in parsed] == ["/a", "/b", "/c"]
    assert list(parsed)[1].params == ["x", 2.5]
    assert parsed.dgram[8:16] == struct.pack(">Q", 1)  # the OSC time tag "immediately"


@settings(max_examples=50)
@given(name=text, values=st.lists(st.floats(-1e6, 1e6, width=32), min_size=7, max_size=7))
def test_a_template_encodes_exactly_what_the_generic_encoder_does(name: str, values: list[float]) -> None:
    template = osc.MessageTemplate("/VMC/Ext/Bone/Pos", name, 7)
    assert template.encode(*values) == osc.element(osc.message("/VMC/Ext/Bone/Pos", [name, *values]))


def test_arguments_other_than_str_int_float_are_refused() -> None:
    with pytest.raises(TypeError):
        osc.message("/x", [True])
    assert not math.isnan(osc_message.OscMessage(osc.message("/x", [0.5])).params[0])
