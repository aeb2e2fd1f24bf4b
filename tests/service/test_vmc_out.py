"""VMC out for real: the service sends to python-osc receivers on loopback UDP; bad targets are refused."""

from __future__ import annotations

import ast
import socket
import time
from pathlib import Path

import numpy as np
import pytest

from riderlive.channels import HORSE_NAMES
from riderlive.cli import main
from riderlive.horse import DEFAULT_SCALE
from riderlive.realtime.record import RecordLayout
from riderlive.rules import RiderModel
from riderlive.service.config import VmcSection
from riderlive.service.poses import RecordPoses
from riderlive.service.vmc_out import VmcError, VmcSender
from riderlive.skeleton import HORSE_RIG, HUMANOID
from tests.service.conftest import BASE_CONFIG
from tests.service.live_server import LiveServer

pytest.importorskip("pythonosc")
from tests.vmc.receiver import VmcReceiver


def test_the_service_sends_the_rider_and_the_horse_each_to_its_port_and_counts_every_bundle(
    receivers: tuple[VmcReceiver, VmcReceiver], tmp_path: Path
) -> None:
    """One live server for both: the bundles' content, and every bundle the rate asked for
    (per target) sent or counted (``sent + dropped + error + skipped``)."""
    rider, horse = receivers
    config = BASE_CONFIG + (
        f'\n[vmc]\ntarget = "127.0.0.1:{rider.port}"\nhorse_target = "localhost:{horse.port}"\nrate = 100.0\n'
    )
    server = LiveServer(config, tmp_path)
    try:
        assert rider.wait_for(41) and horse.wait_for(41)
        state = server.get("/api/state").json()["vmc"]
        assert state["target"] == f"127.0.0.1:{rider.port}" and state["decimation"] == 2  # 200 Hz tick / 100
        assert server.metric("riderlive_vmc_bundles_total", 'outcome="sent"') >= 80
    finally:
        server.stop()
    final = next(line for line in server.log if "VMC out:" in line)
    status = ast.literal_eval(final.split("VMC out: ", 1)[1].strip())
    assert rider.wait_for(status["sent"] // 2, timeout=2.0) and horse.wait_for(status["sent"] // 2, timeout=2.0)
    period = status["decimation"] / 200.0  # tick.rate 200 in BASE_CONFIG
    wanted = round(dict(rider.bundles[-1])["/VMC/Ext/T"][0] / period) + 1  # chosen ticks, first bundle to last
    assert status["sent"] + status["dropped"] + status["error"] + status["skipped"] == 2 * wanted  # two targets
    assert len(rider.bundles) + len(horse.bundles) == status["sent"] and status["dropped"] == status["error"] == 0
    bundles = rider.bundles[1:41]
    times = [dict(b)["/VMC/Ext/T"][0] for b in bundles]
    steps = np.diff(times)
    assert np.all(steps > 0.0)
    np.testing.assert_allclose(steps / 0.01, np.round(steps / 0.01), atol=1e-3)  # whole 10 ms steps
    names = [args[0] for address, args in bundles[0] if address == "/VMC/Ext/Bone/Pos"]
    assert set(names) == {unity for unity, _ in HUMANOID.values()}
    horse_names = [args[0] for address, args in horse.bundles[1] if address == "/VMC/Ext/Bone/Pos"]
    assert horse_names == list(HORSE_RIG.names)
    for address, args in bundles[-1]:
        if address.endswith("/Pos"):
            assert abs(np.linalg.norm(args[4:8]) - 1.0) < 1e-6


def _records(frames: int, rate: float) -> list[np.ndarray]:
    """Output-ring records of a trotting horse and its rider, as the tick writes them."""
    from riderlive.horse import generate_gait

    table = generate_gait("trot", frames / rate, rate, seed=2)
    horse = np.column_stack([table.column(n) for n in HORSE_NAMES])
    rider = RiderModel(scale=DEFAULT_SCALE).evaluate_batch(horse)
    out = []
    for k in range(frames):
        record = np.zeros(RecordLayout.rider.stop)
        record[RecordLayout.seq.start] = k
        record[RecordLayout.engine_t.start] = k / rate
        record[RecordLayout.horse.slice] = horse[k]
        record[RecordLayout.rider.slice] = rider[k]
        out.append(record)
    return out


def test_no_bundle_is_lost_on_loopback_at_120_hz(receivers: tuple[VmcReceiver, VmcReceiver]) -> None:
    """Two seconds at 120 Hz (the bench runs 60 s): every bundle sent arrives, in order."""
    rider, horse = receivers
    config = VmcSection(target=f"127.0.0.1:{rider.port}", horse_target=f"127.0.0.1:{horse.port}", rate=120.0)
    sender = VmcSender.open(RecordPoses(DEFAULT_SCALE), config, tick_rate=120.0)
    records = _records(240, 120.0)
    start = time.perf_counter()
    try:
        for k, record in enumerate(records):
            delay = start + k / 120.0 - time.perf_counter()
            if delay > 0:
                time.sleep(delay)  # pacing the sender at 120 Hz, not waiting for an event
            sender.publish([record])
    finally:
        sender.close()
    assert sender.counts["sent"] == 480 and sender.counts["dropped"] == 0 and sender.counts["error"] == 0
    assert rider.wait_for(241, timeout=1.0) is False  # nothing extra
    assert len(rider.bundles) == 240 and len(horse.bundles) == 240
    times = [dict(b)["/VMC/Ext/T"][0] for b in rider.bundles]
    np.testing.assert_allclose(times, np.arange(240) / 120.0, atol=1e-5)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--vmc", "nohost.invalid:39539"], "cannot resolve host 'nohost.invalid'"),
        (["--vmc", "127.0.0.1"], "expected HOST:PORT"),
        (["--vmc", "127.0.0.1:70000"], "expected HOST:PORT with a port 1..65535"),
        (["--vmc", "127.0.0.1:39539", "--vmc-horse", "127.0.0.1:39539"], "need different VMC targets"),
        (["--vmc", "127.0.0.1:39539", "--vmc-rate", "0"], "vmc.rate"),
    ],
)
def test_bad_vmc_targets_stop_serve_before_it_starts(
    argv: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(["serve", "--port", "0", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err
    assert "listening" not in err and not list(tmp_path.iterdir())


def test_a_local_port_in_use_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as busy:
        busy.bind(("0.0.0.0", 0))
        port = busy.getsockname()[1]
        config = tmp_path / "service.toml"
        config.write_text(f'[vmc]\ntarget = "127.0.0.1:39539"\nlocal_port = {port}\n')
        assert main(["serve", "--port", "0", "--config", str(config)]) == 2
        assert f"VMC local port {port}: Address already in use" in capsys.readouterr().err
        with pytest.raises(VmcError, match="Address already in use"):
            VmcSender.open(RecordPoses(DEFAULT_SCALE), VmcSection(target="127.0.0.1:39539", local_port=port), 120.0)
