"""Fit speed and accuracy: 60 s of 120 Hz (walk, trot, canter 18 s each and the jump shot) refitted.

    .venv/bin/python bench/bench_fit.py [--truth english] [--start kuhnel2003] [--noise] [--loaded] [--no-baseline]

Pinned to one core, BLAS on one thread. The riders are baked by ``--truth`` from the
procedural horse; ``--noise`` damages them as mocap would (``riderlive.fit.noise``: 0.3 deg
and 3 mm Gaussian, 2 cm/s drift, 10 % dropped frames, a 0.2 s clock offset) and fits with
drift removal. Printed: the fit's wall and CPU seconds (this process), its iterations, the
largest error of an identified parameter against the truth, and the held-out gallop's
smallest r per channel.

Baseline, same run, same takes, same offsets, same fitted parameters from the same start:
``scipy.optimize.least_squares`` (trust-region reflective, bounds) with a two-point
finite-difference Jacobian of the same residuals (``riderlive.fit.problem.residuals``, the
engine's batch path): the plain fit the dual-number Jacobian and the normal equations
replace. Its ratio and the largest difference between the two fits' values are printed.

``--loaded``: two busy processes (``bench.serving.burn``) run beside it, on every core.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np
from scipy.optimize import least_squares

from bench.serving import busy_cores
from riderlive.fit.identify import Status
from riderlive.fit.noise import mocap
from riderlive.fit.problem import TakePair, align, residuals
from riderlive.fit.solve import FitOptions, Solution, fit
from riderlive.fit.vector import from_vector
from riderlive.rules.params import RuleParams, load_preset
from tests.fit.takes import pair
from tests.fit.test_recovery import HELD_OUT, correlations

TAKES = (("walk", 18.0), ("trot", 18.0), ("canter", 18.0), ("jump", 0.0))


def takes(truth: RuleParams, noise: bool) -> list[TakePair]:
    out = []
    for seed, (what, seconds) in enumerate(TAKES):
        clean = pair(what, truth, seconds=seconds or 8.0)
        out.append(TakePair(clean.horse, mocap(clean.rider, clean.horse.scale, seed)) if noise else clean)
    return out


def baseline(s: Solution, pairs: list[TakePair], drift: bool) -> tuple[float, float, np.ndarray]:
    """The plain finite-difference fit of the same problem: (wall s, CPU s, values of the fitted parameters)."""
    aligned = [align(p, o, drift) for p, o in zip(pairs, s.offsets, strict=True)]
    free = s.identification.free
    names = [p.name for p in s.params]
    x0 = s.start_values.copy()
    lower = np.array([s.params[k].lower for k in free])
    upper = np.array([s.params[k].upper for k in free])

    def r(values: np.ndarray) -> np.ndarray:
        x = x0.copy()
        x[free] = values
        preset = from_vector(s.start, names, x)
        return np.concatenate([c for a in aligned for c in residuals(a, preset)])

    start = np.clip(x0[free], lower, upper)
    wall, cpu = time.perf_counter(), time.process_time()
    result = least_squares(r, start, jac="2-point", bounds=(lower, upper), method="trf", x_scale="jac")
    return time.perf_counter() - wall, time.process_time() - cpu, result.x


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--truth", default="english")
    parser.add_argument("--start", default="kuhnel2003")
    parser.add_argument("--noise", action="store_true")
    parser.add_argument("--loaded", action="store_true")
    parser.add_argument("--no-baseline", action="store_true")
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[-1]})  # one core
    truth, start = load_preset(args.truth), load_preset(args.start)
    pairs = takes(truth, args.noise)
    seconds = sum(float(p.rider.t[-1] - p.rider.t[0]) for p in pairs)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    with busy_cores(2 if args.loaded else 0) as state:
        fit([pairs[-1]], start)  # imports and first-use costs out of the way
        wall, cpu = time.perf_counter(), time.process_time()
        solution = fit(pairs, start, FitOptions(drift=args.noise))
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        true = truth.flat()
        errors = [
            abs(solution.values[k] - true[p.name]) / (abs(true[p.name]) or 1.0)
            for k, p in enumerate(solution.params)
            if solution.identification.status[k] is Status.IDENTIFIED
        ]
        fitted = set(pairs[0].rider.names)
        r = {n: v for n, v in correlations(truth, solution.preset, HELD_OUT).items() if n in fitted}
        print(f"bench_fit: truth {args.truth}, start {args.start}, {'mocap noise' if args.noise else 'clean'}; {state}")
        print(f"  takes: {seconds:.1f} s of rider at 120 Hz, {solution.rows:,} residuals; load average {load:.1f}")
        print(
            f"  fit (dual-number Jacobian, normal equations): {wall:.2f} s wall, {cpu:.2f} s CPU, "
            f"{solution.iterations} iterations, offsets {', '.join(f'{o:+.4f}' for o in solution.offsets)} s"
        )
        print(
            f"  identified {len(errors)} of {len(solution.params)}: largest error {max(errors) * 100:.3f} %; "
            f"held-out {HELD_OUT} r min {min(r.values()):.5f}"
        )
        if not args.no_baseline:
            b_wall, b_cpu, values = baseline(solution, pairs, args.noise)
            free = solution.identification.free
            diff = np.max(np.abs(values - solution.values[free]) / np.maximum(np.abs(solution.values[free]), 1e-3))
            print(
                f"  baseline (least_squares, 2-point finite differences, same problem from the same start, "
                f"offsets given): {b_wall:.2f} s wall, {b_cpu:.2f} s CPU"
            )
            print(
                f"  ratio baseline / fit: {b_wall / wall:.1f}x wall, {b_cpu / cpu:.1f}x CPU; values agree to {diff:.1e}"
            )


if __name__ == "__main__":
    main()
