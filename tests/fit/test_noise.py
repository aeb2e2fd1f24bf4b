"""Recovery under mocap damage: noise, drift, dropped frames and a clock offset (issue 27's figures)."""

from __future__ import annotations

import numpy as np
import pytest

from riderlive.fit.identify import Status
from riderlive.fit.noise import Mocap, mocap
from riderlive.fit.problem import TakePair
from riderlive.fit.solve import FitOptions, fit
from riderlive.rules.params import load_preset
from tests.fit.takes import pair
from tests.fit.test_recovery import CASES, HELD_OUT, TRAINING, correlations


def test_the_damage_is_what_it_says() -> None:
    clean = pair("trot", load_preset("english"), seconds=10.0)
    damaged = mocap(clean.rider, clean.horse.scale, seed=3)
    assert not any(n.startswith(("hair.", "cloth.")) for n in damaged.names)
    assert 0.85 < len(damaged.t) / len(clean.rider.t) < 0.95  # 10 % dropped
    kept = np.isin(np.round((damaged.t + 0.2) * 120).astype(int), np.round(clean.rider.t * 120).astype(int))
    assert kept.all()  # the rider's clock reads 0.2 s behind
    rows = np.round((damaged.t + 0.2) * 120).astype(int)
    c = damaged.names.index("head.rz")
    error = damaged.values[:, c] - clean.rider.values[rows, clean.rider.names.index("head.rz")]
    se = 0.3 / np.sqrt(len(error))  # four standard errors either way
    assert abs(error.std() - 0.3) < 4 * se / np.sqrt(2) and abs(error.mean()) < 4 * se
    c = damaged.names.index("cog.ty")
    error = damaged.values[:, c] - clean.rider.values[rows, clean.rider.names.index("cog.ty")]
    slope = np.polyfit(damaged.t, error, 1)[0]
    assert abs(abs(slope) - 0.02) < 0.002  # metres per second (the take is in metres)
    assert Mocap().dropped == 0.10


@pytest.mark.slow
@pytest.mark.parametrize("truth_name", ["english", "child"])
def test_identified_within_5_percent_and_the_held_out_take_follows(truth_name: str) -> None:
    truth, start = load_preset(truth_name), CASES[truth_name]()
    pairs = []
    for seed, what in enumerate(TRAINING):
        clean = pair(what, truth, seconds=12.0)
        pairs.append(TakePair(clean.horse, mocap(clean.rider, clean.horse.scale, seed)))
    solution = fit(pairs, start, FitOptions(drift=True))
    assert all(abs(o - 0.2) < 0.5 / 120 for o in solution.offsets)
    true, identified = truth.flat(), 0
    for k, p in enumerate(solution.params):
        status, value, want = solution.identification.status[k], solution.values[k], true[p.name]
        if status is Status.IDENTIFIED:
            identified += 1
            assert abs(value - want) <= 0.05 * abs(want) if want != 0.0 else abs(value) <= 5e-3, (p.name, value, want)
        elif status not in (Status.FITTED_IN_GROUP,):
            assert value == solution.start_values[k], p.name
    assert identified >= 25
    fitted = set(pairs[0].rider.names)
    r = {n: v for n, v in correlations(truth, solution.preset, HELD_OUT).items() if n in fitted}
    assert min(r.values()) >= 0.97, {n: v for n, v in r.items() if v < 0.97}
