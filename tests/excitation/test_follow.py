"""Did each surface follow its command (agent.excitation.follow)?

A doublet's command against measured positions made from it: delayed and scaled (a servo),
negated (a direction or calibration set up the wrong way), stuck, missing, gappy.

Bad input tried: a stuck surface (constant), a surface with gaps (NaN) and one that is NaN
throughout, a window too short to judge, a command that never moves, times that do not
advance.
"""

from __future__ import annotations

import numpy as np
import pytest

from agent.excitation.follow import FOLLOWS, MAX_LAG_S, Following, following, linkage
from agent.excitation.plan import Doublet, Plan, Segment, render

RATE = 50.0
START = 10.0
DT = 0.01  # the recorder's rows


@pytest.fixture(scope="module")
def doublet():
    plan = Plan(
        id="d",
        axes="lateral",
        segments=(Segment(signals={"aileron": Doublet(pulse_s=1.0, amplitude=4.0)}, free_s=1.0),),
    )
    timeline = render(plan, RATE)
    times = START - 1.0 + DT * np.arange(round((timeline.duration + 2.0) / DT))
    index = np.floor((times - START) / timeline.dt).astype(int)
    inside = (index >= 0) & (index < timeline.count)
    command = np.where(inside, timeline.values["aileron"][np.clip(index, 0, timeline.count - 1)], 0)
    return timeline, times, command


def _servo(command: np.ndarray, delay_s: float, gain: float, seed: int = 0) -> np.ndarray:
    shift = round(delay_s / DT)
    moved = np.concatenate([np.zeros(shift), command[: command.size - shift]])
    return 1.5 + gain * moved + np.random.default_rng(seed).normal(0, 0.1, command.size)


def test_a_servo_behind_its_command_follows_at_its_lag_and_gain(doublet):
    timeline, times, command = doublet
    (f,) = following(timeline, START, times, {"aileron": _servo(command, 0.05, 0.7)})
    assert f.verdict == "follows"
    assert f.correlation > 0.95
    assert f.lag_s == pytest.approx(0.05, abs=DT)
    assert f.gain == pytest.approx(0.7, rel=0.05)
    assert f.text() == ""


def test_a_surface_moving_against_its_command_is_named_with_what_to_check(doublet):
    timeline, times, command = doublet
    (f,) = following(timeline, START, times, {"aileron": _servo(command, 0.05, -0.7)})
    assert f.verdict == "reversed"
    assert f.correlation < -0.95
    assert f.gain < 0
    assert "aileron moved against its command" in f.text()
    assert "direction in [excitation.surfaces]" in f.text()


def test_a_stuck_or_unrelated_surface_does_not_follow(doublet):
    timeline, times, _ = doublet
    stuck = np.full(times.size, 2.0)
    noise = np.random.default_rng(1).normal(0, 1.0, times.size)
    for measured in (stuck, noise):
        (f,) = following(timeline, START, times, {"aileron": measured})
        assert f.verdict == "not following"
        assert abs(f.correlation) < FOLLOWS
        assert "did not follow its command" in f.text()


def test_gaps_are_left_out_and_a_surface_never_measured_is_not_judged(doublet):
    timeline, times, command = doublet
    gappy = _servo(command, 0.05, 0.7)
    gappy[100:160] = np.nan  # a pot frame lost: the recorder's NaN
    (f,) = following(timeline, START, times, {"aileron": gappy})
    assert f.verdict == "follows"
    assert following(timeline, START, times, {"aileron": np.full(times.size, np.nan)}) == []
    assert following(timeline, START, times, {"rudder": gappy}) == []  # not commanded


def test_too_little_data_or_nothing_commanded_is_not_judged(doublet):
    timeline, times, command = doublet
    measured = {"aileron": _servo(command, 0.05, 0.7)}
    assert following(timeline, START, times[:2], measured) == []
    assert following(timeline, START, np.full(times.size, START), measured) == []
    before = times < START  # the margin before the plan: the command holds trim
    assert following(timeline, START, times[before], {"aileron": measured["aileron"][before]}) == []
    assert MAX_LAG_S >= 0.1  # a servo's delay and slew lie inside the lags searched


def test_a_linkage_with_more_travel_one_way_is_measured_with_its_knee():
    """Travel per degree that changes at a knee: differential ailerons (at trim) and an
    elevator whose travel changes 1.5° of command from trim (JSBSim's Cessna 310: 14° per unit
    one way of its zero, 4° the other). A sine of commands through the pot's 0.1° noise: the
    gain, even part and knee recovered, and the position each way (`moved`) within 5 %; a
    straight linkage keeps its knee at trim. Bad input tried: gaps (NaN) in the record."""
    u = 4.0 * np.sin(np.linspace(0.0, 12 * np.pi, 3000))
    noise = np.random.default_rng(2).normal(0, 0.1, u.size)
    for gain, even, knee in ((0.7, 0.2, 0.0), (0.37, -0.19, 1.5), (0.7, 0.0, 0.0)):
        y = 2.0 + gain * u + even * (np.abs(u - knee) - abs(knee)) + noise
        y[500:520] = np.nan
        g, e, k = linkage(u, y)
        assert g == pytest.approx(gain, abs=0.02)
        assert e == pytest.approx(even, abs=0.02)
        assert k == pytest.approx(knee, abs=0.5)
        f = Following("elevator", 0.99, 0.02, g, e, k)
        for command in (-4.0, -1.0, 1.0, 3.0, 4.0):
            truth = gain * command + even * (abs(command - knee) - abs(knee))
            assert f.moved(command) == pytest.approx(truth, rel=0.05, abs=0.05)
