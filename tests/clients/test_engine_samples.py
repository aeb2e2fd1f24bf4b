"""The Unity (C#) and Godot (GDScript) sample clients: short, and syntactically valid for their compilers.

C#: mono's ``mcs --parse`` (Debian mono-mcs, installed by install.sh; Unity's types are
not needed to parse). GDScript: gdtoolkit's parser and linter (PyPI, dev extra).
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
UNITY = ROOT / "clients" / "unity" / "RiderliveSkeleton.cs"
GODOT = ROOT / "clients" / "godot" / "riderlive_skeleton.gd"
BIN = ROOT / ".venv" / "bin"


@pytest.mark.parametrize("path", [UNITY, GODOT], ids=["unity", "godot"])
def test_samples_stay_small(path: Path) -> None:
    assert len(path.read_text().splitlines()) <= 150


@pytest.mark.skipif(shutil.which("mcs") is None, reason="mono's mcs is not installed (apt-get install mono-mcs)")
def test_the_unity_client_parses_as_csharp(tmp_path: Path) -> None:
    ok = subprocess.run(["mcs", "--parse", str(UNITY)], capture_output=True, text=True, timeout=60)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    broken = tmp_path / "Broken.cs"
    broken.write_text(UNITY.read_text().replace("void Update()", "void Update("))
    assert subprocess.run(["mcs", "--parse", str(broken)], capture_output=True, timeout=60).returncode != 0


@pytest.mark.skipif(not (BIN / "gdparse").exists(), reason="gdtoolkit is not installed (dev extra)")
def test_the_godot_client_parses_and_lints_as_gdscript(tmp_path: Path) -> None:
    done = subprocess.run([str(BIN / "gdlint"), str(GODOT)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stdout + done.stderr  # gdlint parses, then lints
    broken = tmp_path / "broken.gd"
    broken.write_text(GODOT.read_text().replace("func _apply(frame: PackedByteArray) -> void:", "func _apply(frame"))
    assert subprocess.run([str(BIN / "gdparse"), str(broken)], capture_output=True, timeout=60).returncode != 0
