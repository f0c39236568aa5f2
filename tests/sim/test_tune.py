"""`sysid tune`'s gains flown: designed on JSBSim's validated linear J-3 Cub (agent.sim.truth)
with the installation's linkage, flown in FBWA by the emulated ArduPlane on the nonlinear
JSBSim aircraft (agent.sim.steps), the ±20° bank and ±5° pitch steps against the prediction:
rise time within 20 %, overshoot within 5 points and at most 10 %."""

from __future__ import annotations

import pytest

from agent.sim.aircraft import FLOWN
from agent.sim.steps import flown_step, truth_plants
from agent.tune import design_axis, scaling_for

AIRCRAFT = "J3Cub"


@pytest.mark.parametrize("axis", ["roll", "pitch"])
def test_the_designed_gains_fly_as_predicted(axis):
    speed, altitude = FLOWN[AIRCRAFT][:2]
    axes, eas = truth_plants(AIRCRAFT, speed, altitude)
    plant, actuator = axes[axis]
    scaling = max(eas, *(scaling_for(p, a, eas) for p, a in axes.values()))
    tune = design_axis(axis, plant, actuator, eas=eas, scaling_speed=scaling)
    flown = flown_step(
        AIRCRAFT, speed, altitude, {**tune.params, "SCALING_SPEED": scaling}, axis, tune.step_deg
    )
    assert flown.final_deg == pytest.approx(tune.step_deg, rel=0.1)
    assert flown.rise_s == pytest.approx(tune.rise_s, rel=0.2), (flown.rise_s, tune.rise_s)
    assert abs(flown.overshoot_pct - tune.overshoot_pct) <= 5.0
    assert flown.overshoot_pct <= 10.0
