"""firmware_proto's own C tests (ASan + UBSan), a bounded fuzz run and the cross build, from pytest."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

from riderlive.platform.firmware_host import FIRMWARE_DIR


def make(*targets: str, timeout: float = 240) -> str:
    result = subprocess.run(
        ["make", "-j2", "--no-print-directory", "-C", str(FIRMWARE_DIR), *targets],
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )
    assert result.returncode == 0, f"make {' '.join(targets)} failed:\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}"
    return result.stdout + result.stderr


def test_c_tests_pass_under_sanitizers() -> None:
    out = make("test")
    results = dict(re.findall(r"^(test_\w+): (\d+) checks, 0 failed$", out, re.M))
    assert set(results) == {"test_vectors", "test_device", "test_config_bounds", "test_motion", "test_estop_edges"}, (
        out[-2000:]
    )
    assert int(results["test_vectors"]) >= 300 and int(results["test_device"]) >= 3000
    # the e-stop edge at every point of a step: none lost, the outputs never back on
    masked = re.search(r"masked \(the board\): (\d+) points a step x 2 kinds of edge: (\d+) lost, (\d+) with", out)
    assert masked is not None and int(masked[1]) >= 17 and masked.groups()[1:] == ("0", "0"), out[-2000:]
    # every accepted CONFIG parks within 5 s
    parks = [int(ms) for ms in re.findall(r"slowest park (\d+) ms", out)]
    assert len(parks) == 3 and max(parks) <= 5000, out[-2000:]
    assert "runtime error" not in out and "AddressSanitizer" not in out


def test_fuzz_target_bounded_run(tmp_path: Path) -> None:
    """A short run of `make fuzz` (libFuzzer where clang has it) and of the seeded stream;
    10^7 inputs belong to the bench (docs/performance.md)."""
    out = make("fuzz", "FUZZ_RUNS=20000", f"CORPUS={tmp_path}")
    assert re.search(r"Done 20000 runs|fuzz_stream: 20000 inputs, no crash", out), out[-2000:]
    out = make("fuzz-stream", "FUZZ_RUNS=1500")
    assert "fuzz_stream: 1500 inputs, no crash" in out


def test_cross_build_for_the_mega_fits_a_small_mcu() -> None:
    if shutil.which("avr-gcc") is None:
        pytest.fail("avr-gcc is missing: ./install.sh installs gcc-avr and avr-libc")
    out = make("cross", "PROFILE=platform6")
    sizes = {
        what.strip(): (int(flash), int(ram))
        for what, flash, ram in re.findall(r"^(.*?):\s+flash\s+(\d+) B\s+static RAM\s+(\d+) B$", out, re.M)
    }
    core = next(v for k, v in sizes.items() if k.startswith("core"))
    firmware = next(v for k, v in sizes.items() if k.startswith("firmware"))
    print(out)
    assert core[0] <= 32 * 1024 and core[1] <= 4 * 1024, sizes  # the aim of issue 14
    assert firmware[0] <= 248 * 1024 and firmware[1] <= 8 * 1024 - 1024, sizes  # the Mega, 1 KiB left for the stack
