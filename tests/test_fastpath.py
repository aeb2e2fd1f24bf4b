"""riderlive.fastpath: a compiled kernel's disk cache follows every source compiled into it; batch checks."""

from __future__ import annotations

import importlib
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from riderlive import fastpath

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
            fastpath._file_digest.cache_clear()
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
