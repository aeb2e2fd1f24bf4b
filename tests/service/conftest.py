from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.service.live_server import LiveServer

BASE_CONFIG = """
[tick]
rate = 200.0
realtime_priority = false
preset_dirs = ["presets"]
hang_floor = 1.0  # the shared test server is not about supervision: no false restarts under load

[input]
delay = 0.03
hold = 0.5
ease_time = 0.4
blend_time = 0.0
producer_timeout = 0.3

[source]
resume_after = 0.5

[publish]
send_timeout = 0.5
"""


@pytest.fixture(scope="session")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    live = LiveServer(BASE_CONFIG, tmp_path_factory.mktemp("serve"))
    yield live
    live.stop()
