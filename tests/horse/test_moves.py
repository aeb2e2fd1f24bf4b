"""The movement tables: stages cover the move, it ends standing, hooves stay above ground."""

from __future__ import annotations

import numpy as np
import pytest

from riderlive.horse import MOVE_TABLE, Move
from riderlive.horse.curves import ARRAY, SCALAR
from riderlive.horse.layers import BODY_CHANNELS
from riderlive.horse.moves import Support, Transfer, _leg_channels

HOOF_HEIGHTS = [1, 4, 7, 10]


@pytest.mark.parametrize("move", list(Move))
def test_stages_cover_the_move_and_it_ends_standing(move: Move) -> None:
    spec = MOVE_TABLE[move]
    ends = [(start, end) for _, start, end in spec.stages]
    assert ends[0][0] == 0.0 and ends[-1][1] == pytest.approx(spec.duration)
    assert all(a[1] == b[0] for a, b in zip(ends, ends[1:], strict=False))
    end = spec.spline.at(spec.duration, SCALAR)
    assert len(end) == BODY_CHANNELS
    np.testing.assert_allclose(end, 0.0, atol=1e-12)


@pytest.mark.parametrize("move", list(Move))
def test_hooves_never_below_ground_and_scalar_equals_array(move: Move) -> None:
    spec = MOVE_TABLE[move]
    tau = np.linspace(-0.5, spec.duration + 0.5, 2001)
    values = np.array(spec.spline.at(tau, ARRAY)).T
    assert values[:, HOOF_HEIGHTS].min() >= -1e-12
    scalar = np.array([spec.spline.at(float(t), SCALAR) for t in tau[::50]])
    np.testing.assert_allclose(scalar, values[::50], atol=1e-12)


def test_a_plan_must_alternate_support_and_transfer() -> None:
    with pytest.raises(ValueError, match="alternates"):
        _leg_channels((Support(0.0, 1.0, 0.0, 0.0), Support(1.5, 2.0, 0.0, 0.0)), 1.0)
    with pytest.raises(ValueError, match="alternates"):
        _leg_channels((Transfer(0.1), Support(1.5, 2.0, 0.0, 0.0)), 1.0)
