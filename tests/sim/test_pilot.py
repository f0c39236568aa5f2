"""The scripted safety pilot: sticks, switch, schedule.

Bad input tried: moving the excitation switch as if it were a stick."""

from __future__ import annotations

import math

import pytest

from agent.sim.pilot import HIGH_US, LOW_US, ScriptedPilot, departed, recovered


def test_sticks_move_and_the_switch_is_not_a_stick():
    pilot = ScriptedPilot({1: 1505, 4: 1490}, switch_channel=7)
    assert pilot(0.0)[:7] == [1505, 1500, 1500, 1490, 1500, 1500, LOW_US]
    pilot.set_stick(1, 1400)
    assert pilot.stick(1) == 1400
    assert pilot(0.0)[0] == 1400
    with pytest.raises(ValueError, match="channel 7 is the excitation switch"):
        pilot.set_stick(7, HIGH_US)
    assert not pilot.switch_high
    pilot.schedule(1.0, high=True)
    assert pilot(0.5)[6] == LOW_US
    assert pilot(1.0)[6] == HIGH_US
    pilot.take_control()
    assert pilot(2.0)[6] == LOW_US


def test_a_departure_is_named_by_what_left_the_trimmed_flight():
    # Past the agent's envelope's bank (45°), where its monitor hands back trimmed sticks that
    # do not stop a spiral: the safety pilot's cue; back near the trim: recovered.
    trim = {"phi": 0.0, "theta": math.radians(2.0), "Vt": 60.0}
    assert departed(trim, trim) is None
    assert departed(trim | {"phi": math.radians(-40.0)}, trim) is None
    assert departed(trim | {"phi": math.radians(-62.0)}, trim) == "bank 62°"
    assert departed(trim | {"theta": math.radians(-20.0)}, trim) == "pitch -22° from the trim's"
    assert departed(trim | {"Vt": 76.0}, trim) == "airspeed 1.27 × the trim's"
    assert departed(trim | {"Vt": 40.0}, trim) == "airspeed 0.67 × the trim's"
    high = trim | {"agl": 305.0}
    assert departed(high | {"agl": 160.0}, high) is None
    assert departed(high | {"agl": 140.0}, high) == "140 m above the ground, of 305"
    assert recovered(trim | {"phi": math.radians(10.0)}, trim)
    assert not recovered(trim | {"phi": math.radians(20.0)}, trim)
    assert not recovered(trim | {"theta": math.radians(14.0)}, trim)
    assert not recovered(trim | {"Vt": 70.0}, trim)
