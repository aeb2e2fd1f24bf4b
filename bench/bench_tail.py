"""Strand physics timings: the reference tail (400 and 4000 strands) and the skinned tail plus braid.

Prints CPU microseconds per internal step (1/240 s) on one core (the thread's CPU
clock, so waiting for a core on the shared machine does not count), best of
blocks, and the ratio to a baseline measured in the same run: one 12-vertex strand
stepped in plain Python floats (Verlet, 4 distance iterations, follow-the-leader; no
bending, no collisions), the cheapest honest way to simulate one strand without NumPy.
The skinned tail plus braid runs twice: compiled (numba kernels, the default) and on
the NumPy path, the second baseline (same results within 1e-12 per step).

    PYTHONPATH=$PWD /work/main/.venv/bin/python bench/bench_tail.py [--quick]
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable

import numpy as np

from riderlive.horse import ProceduralHorse
from riderlive.physics import chain, kernels, strands
from riderlive.physics.config import PhysicsConfig
from riderlive.physics.drive import Drive
from riderlive.physics.reference import ReferenceModel
from riderlive.physics.skinned import SkinnedModel


def per_call_us(fn: Callable[[], object], calls: int, blocks: int) -> float:
    """Best over ``blocks`` of the CPU time per call (this thread's CPU clock: time spent
    waiting for a core on a shared machine does not count; cache and frequency effects
    of the other work do, and only ever add, hence the minimum)."""
    samples = []
    for _ in range(blocks):
        start = time.thread_time()
        for _ in range(calls):
            fn()
        samples.append((time.thread_time() - start) / calls * 1e6)
    return min(samples)


def python_strand(n: int = 12, iterations: int = 4) -> Callable[[], None]:
    """The baseline: one strand in lists of floats."""
    rest = 0.08
    x = [[0.0, -rest * i, 0.0] for i in range(n)]
    x[5][0] += 0.05  # not at rest, so every projection does work
    prev = [p[:] for p in x]
    g = 9.81 / 240.0**2

    def step() -> None:
        for i in range(1, n):
            p, q = x[i], prev[i]
            nx, ny, nz = 2 * p[0] - q[0], 2 * p[1] - q[1] - g, 2 * p[2] - q[2]
            q[0], q[1], q[2] = p[0], p[1], p[2]
            p[0], p[1], p[2] = nx, ny, nz
        for _ in range(iterations):
            for i in range(n - 1):
                a, b = x[i], x[i + 1]
                dx, dy, dz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
                d = math.sqrt(dx * dx + dy * dy + dz * dz)
                f = (d - rest) / d
                if i == 0:
                    b[0] -= f * dx
                    b[1] -= f * dy
                    b[2] -= f * dz
                else:
                    h = 0.5 * f
                    a[0] += h * dx
                    a[1] += h * dy
                    a[2] += h * dz
                    b[0] -= h * dx
                    b[1] -= h * dy
                    b[2] -= h * dz
        for i in range(1, n):
            a, b = x[i - 1], x[i]
            dx, dy, dz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
            f = rest / math.sqrt(dx * dx + dy * dy + dz * dz)
            b[0], b[1], b[2] = a[0] + f * dx, a[1] + f * dy, a[2] + f * dz

    return step


def skinned_rows(drive: Drive, compiled: bool, blocks: int) -> list[tuple[str, float]]:
    """The skinned tail + braid's whole step and its parts, compiled or on the NumPy path."""
    sk = SkinnedModel.build(PhysicsConfig(), compiled=compiled)
    state = sk.initial(drive)
    for _ in range(120):  # let the strands fall onto the body; also compiles (or loads) the kernels
        state = sk.step(state, drive)
    anchors = sk.anchors(drive)
    step_strands = kernels.strand_step if compiled else strands.step
    step_chain = kernels.chain_step if compiled else chain.step
    calls = 3000 if compiled else 300
    return [
        (
            f"skinned tail + braid, whole step ({'compiled' if compiled else 'NumPy'})",
            per_call_us(lambda: sk.step(state, drive), calls, blocks),
        ),
        ("  posing (dock, rider, colliders)", per_call_us(lambda: sk.anchors(drive), calls, blocks)),
        (
            "  strand solver (2 strands)",
            per_call_us(
                lambda: step_strands(sk.strands, state.strands, anchors.pins, anchors.colliders), calls, blocks
            ),
        ),
        (
            "  bone chains (2 x 11 bones)",
            per_call_us(lambda: step_chain(sk.bones, state.bones, state.strands.x, anchors.up), calls, blocks),
        ),
    ]


def main() -> int:
    quick = "--quick" in sys.argv
    blocks = 3 if quick else 7
    horse = ProceduralHorse("gallop")
    drive = Drive(np.asarray(horse.sample(0.5)))
    baseline = per_call_us(python_strand(), 200, blocks)
    print(f"baseline: one strand in plain Python                 {baseline:8.1f} us/step")
    rows = []
    for n in (400, 4000):
        cfg = PhysicsConfig.model_validate({"reference": {"strands": n}})
        ref = ReferenceModel.build(cfg)
        state = ref.initial(drive)
        for _ in range(120):  # let the strands fall onto the body, so collisions do work
            state = ref.step(state, drive)
        calls = 20 if n == 400 else 3
        full = per_call_us(lambda ref=ref, state=state: ref.step(state, drive), calls, blocks)
        rows.append((f"reference {n} x 12 (posing + solver)", full))
    compiled = skinned_rows(drive, True, blocks)
    numpy_path = skinned_rows(drive, False, blocks)
    rows += compiled + numpy_path
    for label, us in rows:
        print(f"{label:52s} {us:8.1f} us/step  ({us / baseline:5.2f} x baseline)")
    print(f"skinned tail + braid, NumPy path / compiled          {numpy_path[0][1] / compiled[0][1]:8.1f} x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
