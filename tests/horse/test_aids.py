"""The rider leading the horse (thesis section 10): aids answered after the delay, within a stride,
within the acceleration bound; unknown aids refused naming file, key and the allowed set."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.configfile import ConfigError
from riderlive.horse import generate
from riderlive.horse.aids import ACCELERATION, AIDS, REACTION_DELAY, AidScript, load_take
from riderlive.horse.curves import SCALAR
from riderlive.horse.gaits import GAIT_TABLE, Gait
from riderlive.horse.layers import BlendLayer, GaitLayer
from riderlive.horse.model import Model, State, advance
from riderlive.horse.script import ShotScript

AIDS_DIR = Path(__file__).resolve().parents[2] / "config" / "aids"


def aids(*timed: tuple[float, str], seconds: float = 12.0, start: str = "halt") -> ShotScript:
    script = AidScript.model_validate(
        {"seconds": seconds, "start": start, "aid": [{"at": at, "aid": aid} for at, aid in timed]}
    )
    return script.shot()


def states(script: ShotScript, times: np.ndarray) -> list[State]:
    model: Model = script.model()
    state = script.start(model)
    out = []
    for t in times:
        state = advance(model, state, float(t))
        out.append(state)
    return out


@pytest.mark.parametrize(
    ("before", "aid", "after"),
    [
        ("walk on", "trot", Gait.TROT),
        ("trot", "canter", Gait.CANTER),
        ("canter", "walk on", Gait.WALK),
        ("trot", "halt", Gait.HALT),
    ],
)
def test_an_aid_is_answered_after_the_delay_and_within_a_stride(before: str, aid: str, after: Gait) -> None:
    t = 4.0
    with_aid = aids((0.5, before), (t, aid))
    without = aids((0.5, before))
    rate = 1000.0
    a, b = generate(with_aid, rate).values, generate(without, rate).values
    answer = t + REACTION_DELAY
    k = int(answer * rate) - 1
    np.testing.assert_array_equal(a[: k + 1], b[: k + 1])  # nothing changes before the answer
    assert not np.array_equal(a[k + 2 : k + 50], b[k + 2 : k + 50])
    times = np.array([answer - 1e-6, answer + 1e-6])
    old, new = states(with_aid, times)
    assert old.gait is not after and new.gait is after and isinstance(new.layer, BlendLayer)
    if after is not Gait.HALT:  # the new gait has taken over within one of its strides
        stride = 1.0 / GAIT_TABLE[after].frequency_at(GAIT_TABLE[after].default_speed)
        (done,) = states(with_aid, np.array([answer + min(max(stride, 0.4), 1.2) + 1e-6]))
        assert isinstance(done.layer, GaitLayer) and done.layer.spec.gait is after


aid_names = st.sampled_from(["walk on", "trot", "canter", "gallop", "halt", "faster", "slower"])


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(0.0, 20.0), aid_names), min_size=1, max_size=8))
def test_the_ground_speed_never_changes_faster_than_the_bound(timed: list[tuple[float, str]]) -> None:
    timed = sorted(timed)
    gait = "halt"  # faster / slower only once the horse moves (else the script is refused)
    kept = []
    for at, aid in timed:
        if gait == "halt" and aid in ("faster", "slower"):
            continue
        kept.append((at, aid))
        gait = {"walk on": "walk", "faster": gait, "slower": gait}.get(aid, aid)
    if not kept:
        return
    script = aids(*kept, seconds=25.0)
    times = np.arange(0.0, 25.0, 0.005)
    accel = [abs(float(s.ramp.at(float(t), SCALAR)[1])) for s, t in zip(states(script, times), times, strict=True)]
    assert max(accel) <= ACCELERATION * (1.0 + 1e-9)


def test_faster_and_slower_step_a_quarter_of_the_range_within_it() -> None:
    script = aids((0.0, "trot"), (1.0, "faster"), (2.0, "faster"), (3.0, "faster"), (4.0, "slower"), start="walk")
    lo, hi = GAIT_TABLE[Gait.TROT].speed
    speeds = [seg.speed for seg in script.segment[2:]]
    default = GAIT_TABLE[Gait.TROT].default_speed
    step = 0.25 * (hi - lo)
    assert speeds == pytest.approx([default + step, min(default + 2 * step, hi), hi, hi - step])


@pytest.mark.parametrize(
    ("text", "key", "message"),
    [
        ('[[aid]]\nat = 1\naid = "trott"', "aid.0.aid", "unknown aid 'trott': the horse answers 'walk on', 'trot'"),
        ('[[aid]]\nat = 1\naid = "turn left"', "aid.0.aid", "'jump'"),
        ('[[aid]]\nat = -1\naid = "trot"', "aid.0.at", "greater than or equal to 0"),
        ('[[aid]]\nat = 1\naid = "faster"', "", "aid 0: 'faster' while the horse stands"),
        ('[[aid]]\nat = 2\naid = "trot"\n[[aid]]\nat = 1\naid = "walk on"', "", "aid 1: at = 1.0 s comes before"),
        ('[response]\ndelay = 5\n[[aid]]\nat = 1\naid = "trot"', "response.delay", "less than or equal to 2"),
        ('[response]\nacceleration = 0\n[[aid]]\nat = 1\naid = "trot"', "response.acceleration", "greater than"),
    ],
)
def test_bad_aids_name_file_key_and_allowed_set(tmp_path: Path, text: str, key: str, message: str) -> None:
    path = tmp_path / "ride.toml"
    path.write_text(f"seconds = 10\n{text}\n")
    with pytest.raises(ConfigError, match=message) as err:
        load_take(path)
    assert str(err.value).startswith(f"{path}: {key}:" if key else f"{path}: ")
    if "unknown aid" in message:
        assert all(repr(a) in str(err.value) for a in AIDS)


def test_shipped_aid_script_loads_and_the_cli_writes_it(tmp_path: Path) -> None:
    from riderlive.cli import main

    script = load_take(AIDS_DIR / "hack.toml")
    assert script.model().terrain is not None and script.duration == pytest.approx(40.0)
    out = tmp_path / "hack.csv"
    assert main(["horse", "--script", str(AIDS_DIR / "hack.toml"), "--rate", "60", "-o", str(out)]) == 0
    assert len(out.read_text().splitlines()) == 40 * 60 + 1
