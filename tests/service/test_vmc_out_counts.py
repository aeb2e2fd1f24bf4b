"""Every bundle the VMC rate asks for is sent or counted: batches after a late web loop and
ticks that never reached the web process, against a real OSC receiver on loopback UDP
(through the live service: ``test_vmc_out.py``, on the server it starts anyway)."""

from __future__ import annotations

import numpy as np
import pytest

from riderlive.horse import DEFAULT_SCALE
from riderlive.service.config import VmcSection
from riderlive.service.poses import RecordPoses
from riderlive.service.vmc_out import OUTCOMES, VmcSender
from tests.service.test_vmc_out import _records

pytest.importorskip("pythonosc")
from tests.vmc.receiver import VmcReceiver


def test_sent_plus_skipped_is_every_chosen_tick(receivers: tuple[VmcReceiver, VmcReceiver]) -> None:
    rider, horse = receivers
    config = VmcSection(target=f"127.0.0.1:{rider.port}", horse_target=f"127.0.0.1:{horse.port}", rate=60.0)
    sender = VmcSender.open(RecordPoses(DEFAULT_SCALE), config, tick_rate=120.0)  # every 2nd tick
    records = _records(400, 120.0)
    # how the web process hands records over: mostly one at a time; 7 at once after a late
    # loop; 13 never read (lapped in the ring); one at a time again
    batches = [[r] for r in records[:100]] + [records[100:107]] + [[r] for r in records[120:400]]
    try:
        for batch in batches:
            sender.publish(batch)
    finally:
        sender.close()
    chosen = list(range(0, 400, 2))  # seq 0..398
    counts = sender.counts
    assert counts["sent"] + counts["dropped"] + counts["error"] + counts["skipped"] == 2 * len(chosen)
    # hand-counted: the batch of 7 (seq 100..106) sends 106 and skips 100, 102, 104; the
    # lapped 107..119 skip 108..118 (6); each skipped tick is two bundles (rider, horse)
    assert counts["skipped"] == 2 * (3 + 6)
    assert rider.wait_for(len(chosen) - 9, timeout=5.0)
    assert rider.wait_for(len(chosen) - 8, timeout=0.3) is False  # nothing more arrives
    assert len(rider.bundles) == counts["sent"] // 2 and counts["dropped"] == counts["error"] == 0
    times = [dict(b)["/VMC/Ext/T"][0] for b in rider.bundles]
    sent_seqs = [s for s in chosen if not (100 <= s < 106 or 107 < s < 120)]
    np.testing.assert_allclose(times, np.array(sent_seqs) / 120.0, atol=1e-5)
    assert set(sender.status()) >= set(OUTCOMES)


def test_a_restarted_tick_is_not_counted_as_skipped(receivers: tuple[VmcReceiver, VmcReceiver]) -> None:
    rider, _ = receivers
    sender = VmcSender.open(RecordPoses(DEFAULT_SCALE), VmcSection(target=f"127.0.0.1:{rider.port}"), 120.0)
    records = _records(40, 120.0)  # decimation 2 (the default 60 Hz)
    try:
        for r in records + records[:10]:  # a new generation's seq starts at 0 again
            sender.publish([r])
    finally:
        sender.close()
    assert sender.counts["skipped"] == 0 and sender.counts["sent"] == 20 + 5
