"""The scripted safety pilot: sticks, switch, schedule.

Bad input tried: moving the excitation switch as if it were a stick."""

from __future__ import annotations

import pytest

from agent.sim.pilot import HIGH_US, LOW_US, ScriptedPilot


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
