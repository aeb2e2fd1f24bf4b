"""Recovery: riders baked by each shipped preset, refitted from another preset, give the preset back."""

from __future__ import annotations

import numpy as np
import pytest

from riderlive.channels import RIDER_NAMES
from riderlive.fit.identify import Status
from riderlive.fit.solve import fit
from riderlive.rules.params import RuleParams, load_preset
from tests.fit.takes import pair, rider_table

TRAINING = ("walk", "trot", "canter", "jump")
HELD_OUT = "gallop"


def literal_start() -> RuleParams:
    """English numbers with Appendix B's literal readings and no jump layer: errata and [jump] are held,
    never fitted (chosen with the starting preset)."""
    literal = load_preset("kuhnel2003_literal").flat()
    return load_preset("english").with_values({k: v for k, v in literal.items() if k.startswith(("errata.", "jump."))})


CASES = {
    "kuhnel2003": lambda: load_preset("child"),
    "english": lambda: load_preset("kuhnel2003"),
    "child": lambda: load_preset("english"),
    "kuhnel2003_literal": literal_start,
}


def correlations(truth: RuleParams, fitted: RuleParams, take: str) -> dict[str, float]:
    """Per rider channel, r between the fitted and the true preset's bake of ``take`` (1.0 where both are
    constant and equal to 1e-9)."""
    a, b = rider_table(take, truth), rider_table(take, fitted)
    out = {}
    for name in RIDER_NAMES:
        x, y = a.column(name), b.column(name)
        if np.ptp(x) < 1e-12:
            out[name] = 1.0 if np.max(np.abs(x - y)) < 1e-9 else 0.0
        else:
            out[name] = float(np.corrcoef(x, y)[0, 1])
    return out


@pytest.mark.slow
@pytest.mark.parametrize("truth_name", sorted(CASES))
def test_every_identified_parameter_comes_back(truth_name: str) -> None:
    truth, start = load_preset(truth_name), CASES[truth_name]()
    solution = fit([pair(w, truth) for w in TRAINING], start)
    true = truth.flat()
    assert max(abs(o) for o in solution.offsets) < 1e-6  # seconds: the takes share one clock
    identified = 0
    for k, p in enumerate(solution.params):
        status, value, want = solution.identification.status[k], solution.values[k], true[p.name]
        if status is Status.IDENTIFIED:
            identified += 1
            tolerance = 0.01 * abs(want) if want != 0.0 else 1e-3
            assert abs(value - want) <= tolerance, (p.name, value, want)
        elif status in (Status.NO_EFFECT, Status.HELD_IN_GROUP):
            assert value == solution.start_values[k], p.name  # never a value the takes do not show
    assert identified >= 45
    r = correlations(truth, solution.preset, HELD_OUT)
    assert min(r.values()) >= 0.99, {n: v for n, v in r.items() if v < 0.99}


def test_the_terrain_lean_is_not_identified_on_flat_ground() -> None:
    truth = load_preset("english")
    solution = fit([pair("trot", truth, seconds=4.0)], load_preset("kuhnel2003"))
    names = [p.name for p in solution.params]
    for key in ("terrain.upright", "terrain.uphill_lean", "terrain.downhill_lean"):
        assert solution.identification.status[names.index(key)] is Status.NO_EFFECT
        assert solution.preset.flat()[key] == load_preset("kuhnel2003").flat()[key]
