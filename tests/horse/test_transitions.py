"""Every transition is C1; the output depends only on the script and the seed, never on the rate."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from riderlive.channels import HORSE, HORSE_NAMES
from riderlive.configfile import CONFIG_DIR
from riderlive.horse import GAITS, MOVES, ProceduralHorse, generate, load_script
from riderlive.horse.layers import BlendLayer
from riderlive.horse.model import MAX_BLENDS, Model, advance
from riderlive.horse.script import Segment, ShotScript
from tests.horse.signals import curvature

SHOTS = sorted((CONFIG_DIR / "shots").glob("*.toml"))


def _script(*segments: dict, seed: int | None = None) -> ShotScript:
    return ShotScript(seed=seed, segment=[Segment(**s) for s in segments])


def assert_c1(script: ShotScript) -> None:
    """Halving the step 4x leaves max|x''| bounded for a C1 signal; a kink would grow it 4x, a jump 16x."""
    coarse = curvature(generate(script, 1000.0).values, 1000.0)
    fine = curvature(generate(script, 4000.0).values, 4000.0)
    for name, c, f in zip(HORSE_NAMES, coarse, fine, strict=True):
        assert f <= 1.5 * c + 1e-6, f"{name}: curvature {c:.3g} at 1 kHz grows to {f:.3g} at 4 kHz"
    assert np.all(np.isfinite(fine))


PAIRS = [(a, b) for a, b in itertools.product((*GAITS, "halt"), repeat=2) if a != b]


@pytest.mark.parametrize(("first", "second"), PAIRS)
def test_gait_to_gait_is_c1(first: str, second: str) -> None:
    assert_c1(_script({"gait": first, "seconds": 1.3}, {"gait": second, "seconds": 1.7}))


@pytest.mark.parametrize(("gait", "move"), list(itertools.product(GAITS, MOVES)))
def test_gait_to_move_and_back_is_c1(gait: str, move: str) -> None:
    assert_c1(_script({"gait": gait, "seconds": 1.1}, {"move": move}, {"gait": "walk", "seconds": 1.2}))


def test_commands_mid_blend_mid_ramp_and_mid_move_are_c1() -> None:
    assert_c1(
        _script(
            {"gait": "trot", "seconds": 0.7},
            {"gait": "trot", "seconds": 0.3, "speed": 4.8, "ramp": 2.0},  # a new gait mid-ramp
            {"gait": "canter", "seconds": 0.2},  # interrupted mid-blend
            {"gait": "gallop", "seconds": 0.9},
            {"move": "stop", "seconds": 1.0},  # interrupted mid-move
            {"move": "buck", "seconds": 0.8},
            {"move": "rear"},
            {"gait": "walk", "seconds": 1.0},
        )
    )


def test_stride_variation_is_c1() -> None:
    assert_c1(_script({"gait": "canter", "seconds": 2.0}, {"gait": "gallop", "seconds": 2.0}, seed=3))


def test_live_commands_at_odd_times_keep_c1() -> None:
    rates = (1000.0, 4000.0)
    curves = []
    for rate in rates:
        horse = ProceduralHorse("gallop")
        frames = []
        for i in range(int(4.0 * rate)):
            t = i / rate
            if i == int(0.613 * rate):
                horse.perform("stop")
            if i == int(2.271 * rate):
                horse.set_gait("walk")
            frames.append(horse.sample(t))
        curves.append(curvature(np.array(frames), rate))
    assert np.all(curves[1] <= 1.5 * curves[0] + 1e-6)


@pytest.mark.parametrize("shot", SHOTS, ids=lambda p: p.stem)
@pytest.mark.parametrize("rate", [30.0, 47.0, 60.0, 120.0, 333.0, 1000.0])
def test_no_nan_at_any_rate(shot, rate: float) -> None:
    table = generate(load_script(shot), rate)
    assert table.values.shape[1] == len(HORSE)
    assert np.all(np.isfinite(table.values))


def test_same_frames_at_every_rate() -> None:
    script = load_script(CONFIG_DIR / "shots" / "stop.toml")
    at_30 = generate(script, 30.0)
    at_120 = generate(script, 120.0)
    np.testing.assert_allclose(at_120.values[::4][: len(at_30)], at_30.values, rtol=0, atol=1e-9)


def test_determinism_by_seed() -> None:
    first = generate(_script({"gait": "trot", "seconds": 5.0}, seed=11), 120.0).values
    again = generate(_script({"gait": "trot", "seconds": 5.0}, seed=11), 120.0).values
    other = generate(_script({"gait": "trot", "seconds": 5.0}, seed=12), 120.0).values
    plain = generate(_script({"gait": "trot", "seconds": 5.0}), 120.0).values
    assert np.array_equal(first, again)
    assert not np.allclose(first, other)
    assert not np.allclose(first, plain)
    # without a seed there is no variation: every stride's hoof lift and trunk heave are the same
    for column, seeded_spread in ((1, 5e-3), (13, 1e-3)):
        y = [plain[:, column], first[:, column]]
        peaks = [[v[i] for i in range(1, len(v) - 1) if v[i - 1] < v[i] >= v[i + 1]] for v in y]
        assert np.ptp(peaks[0]) < 1e-3
        assert np.ptp(peaks[1]) > seeded_spread


def test_live_path_equals_batch_path() -> None:
    script = load_script(CONFIG_DIR / "shots" / "jump.toml")
    batch = generate(script, 120.0)
    horse = ProceduralHorse("canter", speed=5.5)
    horse.sample(0.0)
    horse._state = script.start(horse.model)  # the same queued script, live
    live = np.array([horse.sample(float(t)) for t in batch.t])
    np.testing.assert_allclose(live, batch.values, rtol=0, atol=1e-9)


def test_play_follows_a_script_live() -> None:
    script = load_script(CONFIG_DIR / "shots" / "stop.toml")
    horse = ProceduralHorse("walk")
    horse.sample(10.0)
    horse.play(script)
    seen = set()
    for i in range(int(script.duration * 60)):
        horse.sample(10.0 + i / 60)
        seen.add((horse.gait, horse.move))
    assert ("gallop", "stop") in seen
    assert ("walk", None) in seen
    assert horse.gait == "walk"


def test_time_must_not_go_backwards_or_be_nan() -> None:
    horse = ProceduralHorse()
    horse.sample(1.0)
    with pytest.raises(ValueError, match="backwards"):
        horse.sample(0.5)
    with pytest.raises(ValueError, match="finite"):
        horse.sample(float("nan"))


def test_bad_names_and_speeds_are_rejected() -> None:
    horse = ProceduralHorse()
    with pytest.raises(ValueError, match="unknown gait"):
        horse.set_gait("amble")
    with pytest.raises(ValueError, match="unknown move"):
        horse.perform("moonwalk")
    with pytest.raises(ValueError, match=r"3\.2-4\.9"):
        horse.set_gait("trot", 9.0)
    with pytest.raises(ValueError, match="speed"):
        ProceduralHorse("walk", speed=5.0)


def _blends(layer) -> int:
    return 1 + max(_blends(layer.before), _blends(layer.after)) if isinstance(layer, BlendLayer) else 0


def test_a_speed_slider_during_a_blend_stays_c1_and_shallow() -> None:
    speeds = [3.3 + 1.5 * abs(np.sin(i / 7.0)) for i in range(60)]
    segments = [{"gait": "walk", "seconds": 1.0}] + [{"gait": "trot", "seconds": 0.02, "speed": v} for v in speeds]
    script = _script(*segments, {"gait": "trot", "seconds": 1.0})
    assert_c1(script)
    state = script.start(Model())
    for t in np.arange(0.0, 1.5, 0.005):
        state = advance(Model(), state, float(t))
        assert _blends(state.layer) <= 1


def test_a_burst_of_commands_keeps_the_layer_chain_bounded() -> None:
    horse = ProceduralHorse("trot")
    for i in range(400):
        if i % 2 == 0:
            horse.set_gait(("walk", "trot", "canter", "gallop")[i // 2 % 4])
        if i % 50 == 25:
            horse.perform("buck")
        frame = horse.sample(i / 100.0)
        assert np.all(np.isfinite(frame))
        assert horse.state is not None and _blends(horse.state.layer) <= MAX_BLENDS
    for i in range(400, 700):
        horse.sample(i / 100.0)
    assert horse.state is not None and _blends(horse.state.layer) == 0  # everything settled


def test_speed_follows_commands() -> None:
    horse = ProceduralHorse("gallop")
    assert horse.speed == 12.0
    horse.sample(0.0)
    horse.perform("stop")
    horse.sample(5.0)
    assert horse.speed < 0.05 and horse.gait == "halt" and horse.move is None


def test_a_live_command_ends_a_playing_script() -> None:
    script = load_script(CONFIG_DIR / "shots" / "ramp.toml")
    horse = ProceduralHorse("walk")
    horse.sample(0.0)
    horse.play(script)
    horse.sample(4.0)
    assert horse.gait == "trot"
    horse.set_gait("walk")
    for i in range(1, 25):
        horse.sample(4.0 + i)
    assert horse.gait == "walk"  # the script's later segments were dropped
    horse.play(load_script(CONFIG_DIR / "shots" / "stop.toml"))
    horse.play(load_script(CONFIG_DIR / "shots" / "rear.toml"))  # replaces the stop script
    seen = set()
    for i in range(1, 800):
        horse.sample(28.0 + i / 100)
        seen.add(horse.move)
    assert "rear" in seen and "stop" not in seen
