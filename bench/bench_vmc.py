"""VMC out: the cost of one bundle against the websocket encode, and loss at 120 Hz on loopback.

    .venv/bin/python bench/bench_vmc.py [--seconds 60]

1. Per frame, in this process, on the records of a trotting horse and its rider: the
   websocket encode the hub does once per subscription (JSON and binary frame + wire
   bytes; the baseline), the ``pose`` skeleton floats, and VMC's work (both poses solved,
   the rider's and the horse's bundles encoded). Same run, same records.
2. ``riderlive serve --vmc`` at a 120 Hz tick sending 120 bundles a second (rider and
   horse) to two receivers on loopback UDP in this process for ``--seconds``; after a
   clean stop the service logs what it sent, and lost = sent - received.
"""

from __future__ import annotations

import argparse
import re
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from riderlive.channels import HORSE_NAMES
from riderlive.horse import DEFAULT_SCALE, generate_gait
from riderlive.realtime.record import RecordLayout
from riderlive.rules import RiderModel
from riderlive.service.codecs import Subscription
from riderlive.service.hello import pose_floats
from riderlive.service.poses import RecordPoses
from riderlive.service.rider_frames import encode_frame
from riderlive.service.wsprotocol import wire_frame
from riderlive.skeleton import HORSE_RIG
from riderlive.vmc.performer import horse_bundle, rider_bundle

ROOT = Path(__file__).resolve().parents[1]


def records(frames: int, rate: float = 120.0) -> list[np.ndarray]:
    table = generate_gait("trot", frames / rate, rate, seed=5)
    horse = np.column_stack([table.column(n) for n in HORSE_NAMES])
    rider = RiderModel(scale=DEFAULT_SCALE).evaluate_batch(horse)
    out = []
    for k in range(frames):
        record = np.zeros(RecordLayout.rider.stop)
        record[RecordLayout.seq.start], record[RecordLayout.engine_t.start] = k, k / rate
        record[RecordLayout.horse.slice] = horse[k]
        record[RecordLayout.rider.slice] = rider[k]
        out.append(record)
    return out


def per_frame(label: str, work, items: list[np.ndarray]) -> float:  # type: ignore[no-untyped-def]
    start = time.perf_counter()
    for record in items:
        work(record)
    cost = (time.perf_counter() - start) / len(items)
    print(f"  {label:<48} {cost * 1e6:8.1f} us/frame")
    return cost


def costs() -> None:
    items = records(1200)
    print(f"per frame, {len(items)} frames (2 shared cores; ratios matter, absolute numbers drift):")
    json_sub, binary_sub = Subscription(), Subscription(encoding="binary")
    base = per_frame(
        "websocket JSON frame + wire bytes (baseline)", lambda r: wire_frame(encode_frame(json_sub, r)), items
    )
    per_frame("websocket binary frame + wire bytes", lambda r: wire_frame(encode_frame(binary_sub, r)), items)

    def pose_frame(record: np.ndarray) -> None:
        poses = RecordPoses(DEFAULT_SCALE)
        floats = {"rider": pose_floats(poses.rider(record)), "horse": pose_floats(poses.horse(record))}
        wire_frame(encode_frame(Subscription(encoding="binary", pose=("rider", "horse")), record, None, floats))

    per_frame("websocket binary + pose (both skeletons solved)", pose_frame, items)
    saddle = HORSE_RIG.index["saddle"]

    def vmc(record: np.ndarray, poses: RecordPoses | None = None) -> None:
        poses = poses or RecordPoses(DEFAULT_SCALE)
        horse = poses.horse(record)
        rider_bundle(poses.rider(record), horse.world_positions[saddle], horse.world_rotations[saddle], 1.0)
        horse_bundle(horse, HORSE_RIG.names, 1.0)

    full = per_frame("VMC: both poses solved + rider and horse bundles", vmc, items)
    shared = RecordPoses(DEFAULT_SCALE)
    for record in items[:8]:
        shared.rider(record), shared.horse(record)
    encode = per_frame("VMC bundles only (poses already solved)", lambda r: vmc(r, shared), items[:8] * 150)
    print(f"  ratio VMC / websocket JSON encode: {full / base:.1f}x with the poses, {encode / base:.1f}x without")


class Receiver:
    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.2)
        self.port = self.sock.getsockname()[1]
        self.count = 0
        self.bad = 0
        self.stop = False
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self) -> None:
        from pythonosc.osc_bundle import OscBundle

        while not self.stop:
            try:
                data = self.sock.recv(65536)
            except TimeoutError:
                continue
            if OscBundle.dgram_is_bundle(data) and OscBundle(data).num_contents > 3:
                self.count += 1
            else:
                self.bad += 1


def loss(seconds: float) -> None:
    rider, horse = Receiver(), Receiver()
    with tempfile.TemporaryDirectory() as tmp:
        config = Path(tmp) / "service.toml"
        config.write_text(
            '[tick]\nrate = 120.0\n[server]\nlog_level = "info"\n'
            f'[vmc]\ntarget = "127.0.0.1:{rider.port}"\nhorse_target = "127.0.0.1:{horse.port}"\nrate = 120.0\n'
        )
        proc = subprocess.Popen(
            [sys.executable, "-m", "riderlive", "serve", "--port", "0", "--config", str(config)],
            cwd=tmp,
            stderr=subprocess.PIPE,
            text=True,
        )
        time.sleep(seconds + 3.0)  # a soak: the service runs for the whole window
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    time.sleep(0.5)
    rider.stop = horse.stop = True
    match = re.search(r"VMC out: \{.*?'sent': (\d+), 'dropped': (\d+), 'error': (\d+)", err)
    if not match:
        print(err[-2000:])
        raise SystemExit("no VMC summary in the service's log")
    sent, dropped, errors = map(int, match.groups())
    received = rider.count + horse.count
    print(
        f"serve --vmc at 120 Hz for ~{seconds:g} s: sent {sent} bundles (rider + horse), received {received}, "
        f"lost {sent - received}, dropped at the socket {dropped}, send errors {errors}, "
        f"malformed {rider.bad + horse.bad}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    args = parser.parse_args()
    costs()
    loss(args.seconds)


if __name__ == "__main__":
    main()
