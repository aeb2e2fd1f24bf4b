"""``identify.weak``: what a fit's result is held for (docs/fit.md, "Identifiability")."""

from __future__ import annotations

import numpy as np

from riderlive.fit.identify import RUNAWAY, WEAK_UNCERTAINTY, Identification, Status, weak

ROWS = 10_000


def test_a_number_moved_beyond_runaway_scales_from_its_start_is_held_and_one_within_is_not() -> None:
    """Three identified numbers, each pinned to 0.1 % of its value (far below 1 %): the first
    within RUNAWAY scales of its start (a gain 0.0001 -> 2: scale 1), the second just beyond
    (a limit 17 -> 17 - 10.01 x 17), the third a run along a flat valley (0.0001 -> -8816)."""
    start = np.array([0.0001, 17.0, 0.0001])
    values = np.array([2.0, 17.0 - 1.001 * RUNAWAY * 17.0, -8816.0])
    sigma = 0.1 * WEAK_UNCERTAINTY * np.abs(values)
    cost = 0.5 * (ROWS - 3)  # a residual variance of 1: sigma = 1 / sqrt(diag)
    normal = np.diag(1.0 / sigma**2)
    ident = Identification((Status.IDENTIFIED,) * 3, ((),) * 3)
    held = weak(ident, normal, values, cost, ROWS, start=start)
    assert held.status == (Status.IDENTIFIED, Status.WEAK, Status.WEAK)
    # without a start, only the uncertainty counts: all three stay
    assert weak(ident, normal, values, cost, ROWS).status == (Status.IDENTIFIED,) * 3


def test_the_uncertainty_rule_is_unchanged_a_number_within_reach_but_in_the_noise_is_held() -> None:
    start, values = np.array([1.0, 1.0]), np.array([0.9, 0.9])
    sigma = np.array([0.5 * WEAK_UNCERTAINTY * 0.9, 2.0 * WEAK_UNCERTAINTY * 0.9])
    normal, cost = np.diag(1.0 / sigma**2), 0.5 * (ROWS - 2)
    ident = Identification((Status.IDENTIFIED, Status.IDENTIFIED), ((), ()))
    assert weak(ident, normal, values, cost, ROWS, start=start).status == (Status.IDENTIFIED, Status.WEAK)
