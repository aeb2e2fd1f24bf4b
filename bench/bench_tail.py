"""Strand physics timings: the single-source compiled step against the code it replaced, in the same run.

    PYTHONPATH=$PWD .venv/bin/python bench/bench_tail.py [--rounds 3] [--baseline COMMIT]

What is timed, per internal step (1/240 s), as CPU microseconds of one thread (time
spent waiting for a core on a shared machine does not count; each figure is the best
of several blocks, and the best over ``--rounds`` child processes):

- the skinned tail + braid (+ the two cloth flaps since issue 17): the whole step
  (posing, 2 strands and 2 x 11-bone chains, 4 and 4 with the flaps,
  the state objects), and posing alone;
- the reference tail, 400 and 4000 strands x 12 vertices (posing + solver).

The baseline is the previous implementation (hand-written numba twins in
``riderlive/physics/kernels.py`` for the skinned tail, NumPy for the reference),
measured from git in the same run: ``git archive BASELINE riderlive config`` is
unpacked into ``~/.cache/riderlive-bench/<commit>`` (kept, so its numba cache
survives between runs) and the same measuring code runs in a child process with
that tree first on ``sys.path``, alternating with a child on this tree. Both trees'
kernels are compiled or loaded before anything is timed.

Targets (issue 18): skinned tail + braid <= the baseline's step (0.020 ms on a quiet
machine), reference 400 strands <= the baseline's (0.8 ms).
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import subprocess
import sys
import tarfile
import time
from collections.abc import Callable
from io import BytesIO
from pathlib import Path

BASELINE = "e7afd0b"
"""The last commit with the hand-written kernels (main before issue 18)."""
REPO = Path(__file__).resolve().parent.parent
CACHE = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "riderlive-bench"


def per_call_us(fn: Callable[[], object], calls: int, blocks: int) -> float:
    """Best over ``blocks`` of this thread's CPU time per call, microseconds."""
    samples = []
    for _ in range(blocks):
        start = time.thread_time()
        for _ in range(calls):
            fn()
        samples.append((time.thread_time() - start) / calls * 1e6)
    return min(samples)


def measure(blocks: int) -> dict[str, float]:
    """The figures, for whichever ``riderlive`` is importable (the API used here is the same in both trees)."""
    import numpy as np

    from riderlive.horse import ProceduralHorse
    from riderlive.physics.config import PhysicsConfig
    from riderlive.physics.drive import Drive
    from riderlive.physics.reference import ReferenceModel
    from riderlive.physics.skinned import SkinnedModel

    drive = Drive(np.asarray(ProceduralHorse("gallop").sample(0.5)))
    out: dict[str, float] = {}
    sk = SkinnedModel.build(PhysicsConfig())
    state = sk.initial(drive)
    for _ in range(120):  # let the strands fall onto the body; compiles or loads the kernels
        state = sk.step(state, drive)
    out["skinned"] = per_call_us(lambda: sk.step(state, drive), 3000, blocks)
    out["posing"] = per_call_us(lambda: sk.anchors(drive), 3000, blocks)
    for n in (400, 4000):
        ref = ReferenceModel.build(PhysicsConfig.model_validate({"reference": {"strands": n}}))
        ref_state = ref.initial(drive)
        for _ in range(120):  # fallen onto the body, so collisions do work
            ref_state = ref.step(ref_state, drive)
        out[f"reference {n}"] = per_call_us(
            functools.partial(ref.step, ref_state, drive), 30 if n == 400 else 3, blocks
        )
    return out


def baseline_tree(commit: str) -> Path:
    """The baseline's ``riderlive`` and ``config`` unpacked from git (once per commit)."""
    sha = subprocess.run(["git", "-C", str(REPO), "rev-parse", commit], check=True, capture_output=True, text=True)
    tree = CACHE / sha.stdout.strip()
    if not (tree / "riderlive").is_dir():
        archive = subprocess.run(
            ["git", "-C", str(REPO), "archive", commit, "riderlive", "config"], check=True, capture_output=True
        )
        tree.mkdir(parents=True, exist_ok=True)
        with tarfile.open(fileobj=BytesIO(archive.stdout)) as tar:
            tar.extractall(tree, filter="data")
    return tree


def child(tree: Path, blocks: int) -> dict[str, float]:
    """Run :func:`measure` in a fresh interpreter with ``tree`` first on the path."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    code = f"import json, sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); "
    code += f"from bench_tail import measure; print(json.dumps(measure({blocks})))"
    done = subprocess.run([sys.executable, "-c", code], env=env, cwd=tree, check=True, capture_output=True, text=True)
    figures: dict[str, float] = json.loads(done.stdout.strip().splitlines()[-1])
    return figures


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=3, help="child processes per tree, alternating")
    parser.add_argument("--blocks", type=int, default=5)
    parser.add_argument("--baseline", default=BASELINE)
    args = parser.parse_args()
    trees = {"baseline": baseline_tree(args.baseline), "single source": REPO}
    for tree in trees.values():  # compile or load both trees' kernels before timing anything
        child(tree, 1)
    best: dict[str, dict[str, float]] = {name: {} for name in trees}
    for _ in range(args.rounds):
        for name, tree in trees.items():
            for key, value in child(tree, args.blocks).items():
                best[name][key] = min(best[name].get(key, float("inf")), value)
    print(f"per internal step, CPU us, best of {args.rounds} processes x {args.blocks} blocks")
    print(f"baseline: {args.baseline} from git (the hand-written kernels and the NumPy reference tail)")
    print(f"{'':40s} {'single source':>14s} {'baseline':>10s} {'ratio':>7s}")
    labels = {
        "skinned": "skinned tail + braid (+ flaps), whole step",
        "posing": "  of which posing (anchors)",
        "reference 400": "reference tail, 400 strands x 12",
        "reference 4000": "reference tail, 4000 strands x 12",
    }
    for key, label in labels.items():
        new, old = best["single source"][key], best["baseline"][key]
        print(f"{label:40s} {new:14.1f} {old:10.1f} {new / old:7.2f}")
    print("ratio < 1: the single-source compiled step is faster than the code it replaced")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
