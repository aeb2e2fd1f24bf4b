"""The channel vocabulary: tables, look-up and the simulated bone families."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from riderlive.channels import HORSE, RIDER, Kind, UnknownChannelError, is_known, lookup


def test_tables_are_unique_and_follow_node_attr() -> None:
    names = [c.name for c in HORSE + RIDER]
    assert len(names) == len(set(names))
    for channel in HORSE + RIDER:
        assert channel.name == f"{channel.node}.{channel.attr}"
    assert lookup("lower_back.rz").kind is Kind.ROTATION and lookup("cog.ty").unit == "length"


@given(st.sampled_from(["tail", "braid"]), st.integers(0, 99), st.sampled_from(["tx", "ry", "qw", "fan"]))
def test_bone_families_are_known(family: str, index: int, attr: str) -> None:
    name = f"{family}_{index:02d}.{attr}"
    assert is_known(name)
    expected = {"tx": Kind.TRANSLATION, "ry": Kind.ROTATION, "qw": Kind.ATTRIBUTE, "fan": Kind.TRANSLATION}[attr]
    assert lookup(name).kind is expected


@pytest.mark.parametrize(
    "name", ["tail_1.tx", "tail_001.tx", "tail_00.tw", "mane_00.tx", "tail_ref.rx", "lower_back", ""]
)
def test_unknown_names(name: str) -> None:
    assert not is_known(name)
    with pytest.raises(UnknownChannelError):
        lookup(name)
