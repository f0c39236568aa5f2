"""`sysid tune`'s gains flown: designed on JSBSim's validated linear J-3 Cub (agent.sim.truth)
with the installation's linkage, flown in FBWA by the emulated ArduPlane on the nonlinear
JSBSim aircraft (agent.sim.steps), the ±20° bank and ±5° pitch steps against the prediction:
rise time within 20 %, overshoot within 5 points and at most 10 %."""

from __future__ import annotations

import numpy as np
import pytest

from agent.fbwa import DEFAULTS, TRAVEL_DEG
from agent.sim.aircraft import FLOWN
from agent.sim.ardupilot import LINKAGE, OUTPUTS
from agent.sim.plant import Plant
from agent.sim.steps import flown_step
from agent.sim.truth import INPUTS, linear_truth
from agent.tune import Actuator, axis_plant, design_axis

AIRCRAFT = "J3Cub"
CHANNEL = {name: ch for ch, name in OUTPUTS.items()}
AXES = {
    "roll": ("aileron", "p", "phi", ("beta", "p", "r", "phi")),
    "pitch": ("elevator", "q", "theta", ("Vt", "alpha", "q", "theta")),
}


def _links(speed: float, altitude: float) -> dict[str, float]:
    """Measured surface degrees per ArduPlane notional degree: ±45° is the servo's whole
    travel, JSBSim's ±1 (the emulated installation), probed on the aircraft."""
    plant = Plant(AIRCRAFT, airspeed_kts=speed, altitude_ft=altitude, linearise=False)
    before = plant.state()
    nudged = dict(plant.trim)
    for name in ("aileron", "elevator", "rudder"):
        nudged[name] += 0.1
    plant.set_normalised(nudged, 40)
    for _ in range(40):
        plant.step()
    after = plant.state()
    return {
        name: LINKAGE[CHANNEL[name]] * (after[name] - before[name]) / 0.1 / TRAVEL_DEG
        for name in ("aileron", "elevator", "rudder")
    }


@pytest.mark.parametrize("axis", ["roll", "pitch"])
def test_the_designed_gains_fly_as_predicted(axis):
    speed, altitude = FLOWN[AIRCRAFT][:2]
    truth = linear_truth(AIRCRAFT, speed, altitude_ft=altitude)
    names = list(truth.states)
    outputs = names[:8]
    model = {"A": truth.A, "B": truth.B, "C": np.eye(len(names))[:8]}
    links = _links(speed, altitude)
    surface, rate, angle, states = AXES[axis]
    mix = (
        {"rudder": DEFAULTS["KFF_RDDRMIX"] * links["rudder"] / links["aileron"]}
        if axis == "roll"
        else None
    )
    plant = axis_plant(
        model,
        INPUTS,
        outputs,
        surface=surface,
        rate=rate,
        angle=angle,
        axis_outputs=states,
        slow=("phi", "theta", "Vt"),
        mix=mix,
    )
    eas = float(truth.trim_state[names.index("Vt")])
    tune = design_axis(
        axis,
        plant,
        Actuator(link=links[surface], lag_s=0.05, delay_s=0.02),
        eas=eas,
        scaling_speed=eas,
    )
    flown = flown_step(
        AIRCRAFT, speed, altitude, {**tune.params, "SCALING_SPEED": eas}, axis, tune.step_deg
    )
    assert flown.final_deg == pytest.approx(tune.step_deg, rel=0.1)
    assert flown.rise_s == pytest.approx(tune.rise_s, rel=0.2), (flown.rise_s, tune.rise_s)
    assert abs(flown.overshoot_pct - tune.overshoot_pct) <= 5.0
    assert flown.overshoot_pct <= 10.0
