"""riderlive.fastpath: a compiled kernel's disk cache follows every source compiled into it; batch checks."""

from __future__ import annotations

import importlib
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from riderlive import fastpath, fastpath_cache

HELPER = """
from riderlive.fastpath import inline
OFFSET = {offset}

@inline
def shifted(x):
    return x + {step}
"""
KERNEL = """
from riderlive.fastpath import kernel
from helper_mod import OFFSET, shifted

@kernel
def run(a):
    out = 0.0
    for x in a:
        out += shifted(x) + OFFSET
    return out
"""


def _package(tmp_path: Path, step: float, offset: float) -> None:
    (tmp_path / "helper_mod.py").write_text(HELPER.format(step=step, offset=offset))
    (tmp_path / "kernel_mod.py").write_text(KERNEL)


def test_the_stamp_covers_helpers_in_other_files_and_module_constants(tmp_path: Path) -> None:
    _package(tmp_path, 1.0, 0.0)
    sys.path.insert(0, str(tmp_path))
    try:
        stamps = []
        for step, offset in ((1.0, 0.0), (1.0, 0.0), (2.0, 0.0), (2.0, 5.0)):
            _package(tmp_path, step, offset)
            for name in ("helper_mod", "kernel_mod"):
                sys.modules.pop(name, None)
            fastpath_cache._file_digest.cache_clear()
            module = importlib.import_module("kernel_mod")
            stamps.append(fastpath.sources_stamp(module.run.py_func))
        assert stamps[0] == stamps[1]  # nothing changed
        assert stamps[1] != stamps[2]  # the helper's file changed (the kernel's file did not)
        assert stamps[2] != stamps[3]  # a constant the kernel reads changed
    finally:
        sys.path.remove(str(tmp_path))
        for name in ("helper_mod", "kernel_mod"):
            sys.modules.pop(name, None)


def test_an_edited_helper_is_recompiled_in_the_next_process(tmp_path: Path) -> None:
    """numba's own cache would reload the kernel compiled with the old helper; ours compiles it again."""
    run = textwrap.dedent("""
        import sys, numpy as np
        sys.path.insert(0, sys.argv[1])
        from kernel_mod import run
        print(run(np.zeros(3)))
    """)
    results = []
    for step in (1.0, 1.0, 2.0):
        _package(tmp_path, step, 0.0)
        done = subprocess.run([sys.executable, "-c", run, str(tmp_path)], capture_output=True, text=True, check=True)
        results.append(float(done.stdout.split()[-1]))
    assert results == [3.0, 3.0, 6.0]
    assert len(list((tmp_path / "__pycache__").glob("kernel_mod.run-*.nbi"))) == 1  # cached on disk


def test_batch_checks_its_arguments_before_running() -> None:
    kernel = fastpath.batch(lambda a, b: (a + b, a - b), 2, 2)
    columns = [np.zeros(5), np.zeros(5)]
    with pytest.raises(ValueError, match="expected 2 input columns"):
        kernel(columns[:1], np.zeros((2, 5)))
    with pytest.raises(ValueError, match="C-contiguous float64"):
        kernel(columns, np.zeros((5, 2)).T)
    with pytest.raises(ValueError, match="5 frames"):
        kernel([np.zeros(5), np.zeros(4)], np.zeros((2, 5)))


def mixed(a: float, b: float, c: float) -> tuple[float, ...]:
    """A scalar function with the operations the rules use (clamps, abs, products): 3 floats in, 5 out."""
    return (a + b, min(a * c, 2.0), abs(b) * 0.3 - c, max(-1.0, min(1.0, a - c)), (a - 2.0) * -b / 7.0)


CASE_FRAMES = (0, 1, 3, 5, 6, 7, 13, fastpath.BLOCK - 1, fastpath.BLOCK, 2 * fastpath.BLOCK + 3)
GAIN_IN = np.array([2.5, 1.0, -0.5])
GAIN_OUT, OFFSET_OUT = np.array([1.0, 0.4, -2.0, 3.0, 1.0]), np.array([0.0, 0.25, 1.0, -3.0, 0.5])
PYTHON_PATH = """
import sys
sys.modules["numba"] = None  # as if numba were not installed
import numpy as np
from riderlive import fastpath, fastpath_cache
from tests.test_fastpath import CASE_FRAMES, GAIN_IN, GAIN_OUT, OFFSET_OUT, case_columns, mixed
assert not fastpath.AVAILABLE
for block in (fastpath.BLOCK, 6):
    run = fastpath.batch(mixed, 3, 5, block=block)
    for n in CASE_FRAMES:
        for affine in (False, True):
            out = np.full((5, n), np.nan)
            run(case_columns(n), out, GAIN_IN, *((GAIN_OUT, OFFSET_OUT) if affine else ()))
            np.save(f"{sys.argv[1]}/{block}-{n}-{affine}.npy", out)
"""


def case_columns(n: int) -> list[np.ndarray]:
    """Three input columns of ``n`` frames, wide enough to reach both sides of every clamp."""
    return list(np.random.default_rng(n).uniform(-6.0, 6.0, (3, n)))


def offset_output(n: int, items: int) -> np.ndarray:
    """A C-contiguous (5, n) array starting ``items`` float64s past a 64-byte boundary: its rows start at
    every alignment, so the streaming stores meet unaligned starts and short tails."""
    buffer = np.full(5 * n + 16, np.nan)
    skip = (-(buffer.ctypes.data // 8) % 8) + items
    return buffer[skip : skip + 5 * n].reshape(5, n)


@pytest.fixture(scope="module")
def python_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The interpreted path's outputs for both block sizes: one process without numba, for both cases."""
    out = tmp_path_factory.mktemp("python_path")
    root = Path(__file__).resolve().parents[1]
    subprocess.run([sys.executable, "-c", PYTHON_PATH, str(out)], cwd=root, check=True)
    return out


@pytest.mark.parametrize("block", [fastpath.BLOCK, 6])
def test_batch_streams_exactly_the_python_path(block: int, python_path: Path) -> None:
    """The compiled kernel (streaming stores from 32-byte boundaries, single stores before and after) writes
    exactly what the same source writes interpreted, without numba: for every frame count (none, fewer
    than a store or a block, block edges), every row alignment, with and without the output gains."""
    run = fastpath.batch(mixed, 3, 5, block=block)
    for n in CASE_FRAMES:
        columns = case_columns(n)
        a, b, c = (column * gain for column, gain in zip(columns, GAIN_IN, strict=True))
        frames = zip(a.tolist(), b.tolist(), c.tolist(), strict=True)
        direct = np.array([mixed(*frame) for frame in frames]).reshape(n, 5).T  # Python floats
        for affine in (False, True):
            python = np.load(python_path / f"{block}-{n}-{affine}.npy")
            expected = direct * GAIN_OUT[:, None] + OFFSET_OUT[:, None] if affine else direct
            np.testing.assert_array_equal(python, expected)
            for items in range(4):
                out = offset_output(n, items)
                run(columns, out, GAIN_IN, *((GAIN_OUT, OFFSET_OUT) if affine else ()))
                np.testing.assert_array_equal(out, python, err_msg=f"{n} frames, start +{items}, affine {affine}")


def test_batch_writes_an_output_that_is_not_8_byte_aligned() -> None:
    """No 32-byte boundary is ever reached there: every value is stored singly, and still right."""
    n = 2 * fastpath.BLOCK + 3
    raw = bytearray(5 * n * 8 + 4)
    out = np.frombuffer(raw, dtype=np.float64, count=5 * n, offset=4).reshape(5, n)
    assert out.flags.c_contiguous and not out.flags.aligned
    run = fastpath.batch(mixed, 3, 5)
    run(case_columns(n), out)
    expected = np.empty((5, n))
    run(case_columns(n), expected)
    np.testing.assert_array_equal(out, expected)


def test_the_numba_internals_the_cache_uses_are_there_or_the_failure_names_the_version() -> None:
    """riderlive.fastpath_cache extends numba's FunctionCache; a numba without those internals fails
    here (and at the first kernel) with its version and the tested range, never with a stale cache."""
    import numba

    from riderlive import fastpath_cache

    version = tuple(int(p) for p in numba.__version__.split(".")[:2])
    lo, hi = fastpath_cache.TESTED
    assert lo <= version <= hi, f"numba {numba.__version__} is outside the tested {lo}-{hi} (pyproject.toml)"
    fastpath_cache.check_internals.cache_clear()
    fastpath_cache.check_internals()  # raises NumbaChanged naming numba's version when they moved


def test_a_moved_internal_is_reported_with_numba_s_version(monkeypatch: pytest.MonkeyPatch) -> None:
    import numba
    from numba.core import caching

    from riderlive import fastpath_cache

    monkeypatch.setattr(caching, "FunctionCache", type("FunctionCache", (), {}))  # a numba that reorganised it
    fastpath_cache.check_internals.cache_clear()
    try:
        with pytest.raises(fastpath_cache.NumbaChanged, match=rf"numba {numba.__version__} lacks .*load_overload"):
            fastpath_cache.check_internals()
    finally:
        fastpath_cache.check_internals.cache_clear()
