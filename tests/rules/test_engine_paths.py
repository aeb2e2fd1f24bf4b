"""The scalar and batch paths evaluate the same rules to the same numbers."""

from __future__ import annotations

import numpy as np

from riderlive.channels import HORSE, RIDER
from riderlive.rules.engine import RiderModel


def test_batch_shape_and_agreement_small() -> None:
    rng = np.random.default_rng(1)
    horse = rng.normal(scale=8.0, size=(500, len(HORSE)))
    model = RiderModel()
    batch = model.evaluate_batch(horse)
    assert batch.shape == (500, len(RIDER))
    scalar = np.array([model.evaluate(row.tolist()) for row in horse])
    np.testing.assert_allclose(scalar, batch, rtol=0, atol=1e-9)
