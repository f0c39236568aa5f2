"""A simulated flight without real time or protocols: the record `sysid sim` would give the
identification, made in seconds, for benchmarks and studies over many aircraft and seeds.

The same parts as the real-time simulation, minus the bytes: JSBSim trimmed as `Plant` does,
the plan rendered at the excitation rate and turned into RC PWM by the default surface
calibration ([excitation.surfaces]: 20 µs per degree, 10 µs per percent of throttle), the
emulated ArduPlane's servo model (delay, rate and travel limits) at its 100 Hz tick, and the
sensors' white noise at the instruments' levels (agent.sim.aircraft.NOISE). The record holds
what the agent records for a full-axis identification: the throttle servo output (µs), the
potentiometers' surface positions (deg) and the eight aircraft outputs, at 100 Hz, from
`margin_s` before the plan to `margin_s` after it, trim as recorded (not removed).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agent.config import Excitation
from agent.excitation.plan import Plan, Timeline, render
from agent.sim.aircraft import NOISE, TICK_HZ
from agent.sim.ardupilot import (
    FBWA,
    EmulatedArduPlane,
    Params,
    ServoModel,
    normalised_to_pwm,
    pwm_to_normalised,
    setup,
)
from agent.sim.ardupilot import OUTPUTS as AP_OUTPUTS
from agent.sim.plant import OUTPUTS, Plant

INPUT_CHANNELS = ("throttle", "elevator", "aileron", "rudder")
CHANNEL = {"aileron": 1, "elevator": 2, "throttle": 3, "rudder": 4}
OUTPUT_NOISE = {
    "Vt": "Vt",
    "alpha": "alpha",
    "q": "q",
    "theta": "theta",
    "beta": "beta",
    "p": "p",
    "r": "r",
    "phi": "phi",
}
# The INS's heading and velocity (north, east, down): with the attitude they give the inertial
# velocity the wind is measured from (agent.ident.aircraft.prepare).
INS_CHANNELS = ("psi", "vn", "ve", "vd")


@dataclass(frozen=True)
class Record:
    """One flight's record at `dt`: inputs (INPUT_CHANNELS) and outputs (plant OUTPUTS)."""

    u: np.ndarray
    y: np.ndarray
    dt: float
    ins: np.ndarray  # INS_CHANNELS
    inputs: tuple[str, ...] = INPUT_CHANNELS
    outputs: tuple[str, ...] = OUTPUTS
    height: np.ndarray | None = None  # above the ground (m), the truth's


def fly(
    plan: Plan | Timeline,
    *,
    aircraft: str = "J3Cub",
    speed_kts: float = 60.0,
    turbulence: float = 0.0,
    seed: int = 0,
    altitude_ft: float = 1000.0,
    noise: bool = True,
    margin_s: float = 2.0,
    settle_s: float = 1.0,
    rate_hz: float = 50.0,
    plant: Plant | None = None,
    fbwa: bool = False,
) -> Record:
    """Fly `plan` (or a timeline already rendered) once from trim at `altitude_ft` above the
    ground; `settle_s` of trimmed flight precede the recorded margin. `fbwa`: the plan plays
    on the pilot's sticks about their trim, the emulated ArduPlane in FBWA flying the
    surfaces with its laws at ArduPlane's defaults (the agent's closed-loop excitation,
    agent.excitation.scheduler)."""
    plant = plant or Plant(
        aircraft,
        airspeed_kts=speed_kts,
        altitude_ft=altitude_ft,
        turbulence=turbulence,
        seed=seed,
        linearise=False,
    )
    surfaces = Excitation().surfaces
    params = Params()
    timeline = plan if isinstance(plan, Timeline) else render(plan, rate_hz)
    tick = 1.0 / TICK_HZ
    steps = round(tick / plant.dt)
    trim_pwm = {c: normalised_to_pwm(CHANNEL[c], plant.trim[c]) for c in INPUT_CHANNELS}
    servos = {
        c: ServoModel(
            params.servo_delay_s, params.servo_rate, params.servo_travel, tick, plant.trim[c]
        )
        for c in INPUT_CHANNELS
    }
    autopilot, sticks = None, {}
    if fbwa:
        rc = [1500] * 18
        for ch, name in AP_OUTPUTS.items():
            rc[ch - 1] = normalised_to_pwm(ch, plant.trim[name])
        autopilot = EmulatedArduPlane(
            Params(fbwa=setup(plant.state())),
            lambda _t: [rc[i] + sticks.get(i + 1, 0) for i in range(18)],
            dt=tick,
            trim=plant.trim,
        )
        autopilot.set_mode(FBWA)
    state = plant.state()
    lead = round((settle_s + margin_s) / tick)
    played = round(timeline.duration / tick)
    total = lead + played + round(margin_s / tick)
    rng = np.random.default_rng(seed + 1000)
    u = np.empty((total, len(INPUT_CHANNELS)))
    y = np.empty((total, len(OUTPUTS)))
    ins = np.empty((total, len(INS_CHANNELS)))
    height = np.empty(total)
    per_command = round(timeline.dt / tick)
    for k in range(total):
        j = (k - lead) // per_command
        pwm = {}
        for c in INPUT_CHANNELS:
            delta = timeline.values[c][j] if 0 <= j < timeline.count and c in timeline.values else 0
            value = trim_pwm[c] + surfaces[c].direction * surfaces[c].us_per_unit * delta
            pwm[c] = round(float(np.clip(value, surfaces[c].min_us, surfaces[c].max_us)))
        if autopilot is None:
            commands = {
                c: servos[c].step(pwm_to_normalised(CHANNEL[c], pwm[c])) for c in INPUT_CHANNELS
            }
        else:  # the overrides are the sticks: offsets about the pilot's trimmed ones
            sticks.update({CHANNEL[c]: pwm[c] - trim_pwm[c] for c in INPUT_CHANNELS})
            commands = autopilot.tick(k * tick, state)
            pwm["throttle"] = autopilot.outputs.get(CHANNEL["throttle"], pwm["throttle"])
        plant.set_normalised(commands, steps)
        for _ in range(steps):
            plant.step()
        s = state = plant.state()
        u[k] = [pwm["throttle"], s["elevator"], s["aileron"], s["rudder"]]
        y[k] = [s[name] for name in OUTPUTS]
        ins[k] = [s[name] for name in INS_CHANNELS]
        height[k] = s["agl"]
        if noise:
            u[k, 1:] += rng.normal(size=3) * [
                NOISE["elevator"],
                np.sqrt(0.5) * NOISE["aileron_left"],
                NOISE["rudder"],
            ]
            y[k] += rng.normal(size=len(OUTPUTS)) * [NOISE[OUTPUT_NOISE[n]] for n in OUTPUTS]
            ins[k] += rng.normal(size=len(INS_CHANNELS)) * [NOISE[n] for n in INS_CHANNELS]
    keep = round(settle_s / tick)
    return Record(u[keep:], y[keep:], tick, ins[keep:], height=height[keep:])
