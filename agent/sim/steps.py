"""Attitude steps flown in FBWA: the emulated ArduPlane's laws (agent.fbwa) with given
parameters on a JSBSim aircraft, the pilot's stick stepped, the response measured as a
flight-test engineer reads it (rise time 10–90 %, overshoot); and the plants `sysid tune`
designs on for a simulated aircraft (its validated truth, the emulated installation's
linkage). What `sysid tune`'s predictions are checked against (tests/sim/test_tune.py,
benchmarks/tune_check.py)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from agent.config import Excitation
from agent.excitation.follow import linkage
from agent.fbwa import DEFAULTS, TRAVEL_DEG
from agent.sim.ardupilot import (
    FBWA,
    LINKAGE,
    OUTPUTS,
    RC_HALF_RANGE,
    EmulatedArduPlane,
    Params,
    normalised_to_pwm,
    setup,
)
from agent.sim.plant import Plant
from agent.sim.truth import INPUTS, linear_truth
from agent.tune import Actuator, axis_plant, surface_link
from agent.tune import Model as TuneModel
from agent.tune import Options as TuneOptions
from agent.tune import Plant as AxisPlant

TICK_S = 0.01  # the emulated autopilot's tick
# The emulated servo's dead time (agent.sim.ardupilot.Params), which a run's "follows" check
# measures as the lag of the best correlation (agent.excitation.follow): 0.02 s.
SERVO_DELAY_S = Params().servo_delay_s
# Each axis: its surface, rate, angle and states, as `sysid tune` takes them.
AXES = {
    "roll": ("aileron", "p", "phi", ("beta", "p", "r", "phi")),
    "pitch": ("elevator", "q", "theta", ("Vt", "alpha", "q", "theta")),
}
SETTLE_S = 2.0  # flown hands off in FBWA before the step
# The stick's full deflection asks for ROLL_LIMIT_DEG of bank either way, PTCH_LIM_MAX_DEG of
# pitch up and −PTCH_LIM_MIN_DEG down (mode_fbwa.cpp).
STICK_CHANNEL = {
    "roll": (1, ("ROLL_LIMIT_DEG", "ROLL_LIMIT_DEG"), "phi"),
    "pitch": (2, ("PTCH_LIM_MAX_DEG", "PTCH_LIM_MIN_DEG"), "theta"),
}


@dataclass(frozen=True)
class Step:
    """A step's response: the angle's change (deg, from the step's start) every tick."""

    axis: str
    demanded_deg: float
    angle_deg: np.ndarray

    @property
    def final_deg(self) -> float:
        """The mean of the last half second."""
        return float(self.angle_deg[-round(0.5 / TICK_S) :].mean())

    @property
    def rise_s(self) -> float:
        """10–90 % of the final value."""
        a, final = self.angle_deg, self.final_deg
        return float((np.argmax(a >= 0.9 * final) - np.argmax(a >= 0.1 * final)) * TICK_S)

    @property
    def overshoot_pct(self) -> float:
        return float(max(0.0, (self.angle_deg.max() - self.final_deg) / self.final_deg * 100))


def _aircraft(aircraft, airspeed_kts, altitude_ft, params, plant):
    """The trimmed plant, the emulated ArduPlane in FBWA with `params` over the pilot's setup,
    the pilot's trimmed sticks and the offsets a test adds to them."""
    sim = Plant(
        aircraft, airspeed_kts=airspeed_kts, altitude_ft=altitude_ft, linearise=False, **plant
    )
    rc = [1500] * 18
    for ch, name in OUTPUTS.items():
        rc[ch - 1] = normalised_to_pwm(ch, sim.trim[name])
    offset: dict[int, int] = {}

    def pilot(_t: float) -> list[int]:
        return [rc[i] + offset.get(i + 1, 0) for i in range(18)]

    ap = EmulatedArduPlane(
        Params(fbwa=setup(sim.state()) | dict(params)), pilot, dt=TICK_S, trim=sim.trim
    )
    ap.set_mode(FBWA)
    return sim, ap, offset


def held(
    aircraft: str,
    airspeed_kts: float,
    altitude_ft: float,
    params: Mapping[str, float],
    seconds: float = 30.0,
    **plant,
) -> tuple[float, float]:
    """The rms bank and pitch error (deg) while FBWA holds the trimmed attitude hands off for
    `seconds` after SETTLE_S (in turbulence: `plant`'s turbulence and seed)."""
    sim, ap, _ = _aircraft(aircraft, airspeed_kts, altitude_ft, params, plant)
    state = sim.state()
    theta0 = ap.fbwa.params["PTCH_TRIM_DEG"]
    per_tick = round(TICK_S / sim.dt)
    bank, pitch = [], []
    for k in range(round((SETTLE_S + seconds) / TICK_S)):
        sim.set_normalised(ap.tick(k * TICK_S, state), per_tick)
        for _ in range(per_tick):
            sim.step()
        state = sim.state()
        if k >= round(SETTLE_S / TICK_S):
            bank.append(np.degrees(state["phi"]))
            pitch.append(np.degrees(state["theta"]) - theta0)
    return float(np.sqrt(np.mean(np.square(bank)))), float(np.sqrt(np.mean(np.square(pitch))))


def flown_step(
    aircraft: str,
    airspeed_kts: float,
    altitude_ft: float,
    params: Mapping[str, float],
    axis: str,
    step_deg: float,
    seconds: float = 8.0,
    **plant,
) -> Step:
    """Trim `aircraft`, fly it in FBWA with `params` (over the pilot's setup,
    agent.sim.ardupilot.setup) for SETTLE_S, then step the stick to ask for `step_deg` more
    bank or pitch (negative: the other way) and record `seconds`; the response is taken in
    the step's sense."""
    sim, ap, offset = _aircraft(aircraft, airspeed_kts, altitude_ft, params, plant)
    state = sim.state()
    channel, (up, down), angle = STICK_CHANNEL[axis]
    limit = abs(ap.fbwa.params[up if step_deg >= 0 else down])
    per_tick = round(TICK_S / sim.dt)
    trace = []
    start = None
    for k in range(round((SETTLE_S + seconds) / TICK_S)):
        t = k * TICK_S
        if k == round(SETTLE_S / TICK_S):
            offset[channel] = round(RC_HALF_RANGE * step_deg / limit)
            start = np.degrees(state[angle])
        sim.set_normalised(ap.tick(t, state), per_tick)
        for _ in range(per_tick):
            sim.step()
        state = sim.state()
        if start is not None:
            trace.append((np.degrees(state[angle]) - start) * np.sign(step_deg))
    return Step(axis, abs(step_deg), np.asarray(trace))


# The notional outputs (degrees from trim) `links` probes each surface at, either way: up
# to 30 % of the servo's travel, about what a step's or a sized plan's command moves it.
PROBES = (0.0, 2.25, -2.25, 4.5, -4.5, 9.0, -9.0, 13.5, -13.5)


def links(
    aircraft: str, airspeed_kts: float, altitude_ft: float
) -> dict[str, tuple[float, float, float]]:
    """Per surface (link, even, knee) as agent.tune.Actuator takes them: the measured surface's
    degrees per ArduPlane notional degree, fitted to its positions at PROBES as a run's are
    (agent.excitation.follow.linkage: a knee where the travel per degree changes). ±45° is the
    servo's whole travel, JSBSim's ±1 (the emulated installation); JSBSim's surfaces may travel
    further one way (the C310's elevator 14° per unit one way of zero and 4° the other, the
    C172R's ailerons 20° down, 15° up)."""
    channel = {name: ch for ch, name in OUTPUTS.items()}
    names = ("aileron", "elevator", "rudder")
    plant = Plant(aircraft, airspeed_kts=airspeed_kts, altitude_ft=altitude_ft, linearise=False)
    before = plant.state()
    positions = {name: [] for name in names}
    for output in PROBES:  # the surfaces' mapping is static: one plant, each held 40 steps
        nudged = dict(plant.trim)
        for name in names:  # a positive notional output moves JSBSim's command by LINKAGE
            nudged[name] += LINKAGE[channel[name]] * output / TRAVEL_DEG
        plant.set_normalised(nudged, 40)
        for _ in range(40):
            plant.step()
        after = plant.state()
        for name in names:
            positions[name].append(after[name] - before[name])
    return {name: linkage(np.array(PROBES), np.array(positions[name])) for name in names}


def truth_plants(
    aircraft: str, airspeed_kts: float, altitude_ft: float
) -> tuple[dict[str, tuple[AxisPlant, Actuator]], float]:
    """Each axis's plant and actuator as `sysid tune` takes them, from the aircraft's validated
    linear model (agent.sim.truth), the installation's linkage (`links`) and the emulated
    servo's dead time taken whole, as a run measures it (`SERVO_DELAY_S`); and the trim's
    airspeed (m/s)."""
    truth = linear_truth(aircraft, airspeed_kts, altitude_ft=altitude_ft)
    names = list(truth.states)
    model = {"A": truth.A, "B": truth.B, "C": np.eye(len(names))[:8]}
    linked = links(aircraft, airspeed_kts, altitude_ft)
    result = {}
    for axis, (surface, rate, angle, states) in AXES.items():
        mix = None
        if axis == "roll":
            share = linked["rudder"][0] / linked["aileron"][0]
            mix = {"rudder": DEFAULTS["KFF_RDDRMIX"] * share}
        plant = axis_plant(
            model,
            INPUTS,
            names[:8],
            surface=surface,
            rate=rate,
            angle=angle,
            axis_outputs=states,
            slow=("phi", "theta", "Vt"),
            mix=mix,
        )
        link, even, knee = linked[surface]
        servo = {"lag_s": 0.0, "delay_s": SERVO_DELAY_S}
        result[axis] = (plant, Actuator(link=link, even=even, knee=knee, **servo))
    return result, float(truth.trim_state[names.index("Vt")])


def flown_rudder_pulse(
    aircraft: str,
    airspeed_kts: float,
    altitude_ft: float,
    params: Mapping[str, float],
    stick: float = 0.3,
    pulse_s: float = 0.5,
    seconds: float = 10.0,
    **plant,
) -> np.ndarray:
    """Trim `aircraft`, fly it in FBWA with `params` for SETTLE_S, pulse the pilot's rudder
    stick by `stick` of its travel for `pulse_s`, and record the yaw rate (deg/s, every tick)
    for `seconds` after the pulse: the Dutch roll's free response with the laws engaged."""
    sim, ap, offset = _aircraft(aircraft, airspeed_kts, altitude_ft, params, plant)
    state = sim.state()
    per_tick = round(TICK_S / sim.dt)
    start, end = round(SETTLE_S / TICK_S), round((SETTLE_S + pulse_s) / TICK_S)
    trace = []
    for k in range(end + round(seconds / TICK_S)):
        offset[4] = round(RC_HALF_RANGE * stick) if start <= k < end else 0
        sim.set_normalised(ap.tick(k * TICK_S, state), per_tick)
        for _ in range(per_tick):
            sim.step()
        state = sim.state()
        if k >= end:
            trace.append(np.degrees(state["r"]))
    return np.asarray(trace)


def oscillation(trace: np.ndarray, dt: float, near: complex) -> complex:
    """The damped oscillation that fits a free response best, started from `near` (its
    eigenvalue, 1/s): r(t) = a e^{σt} cos(ωt + φ) + b e^{-t/τ} + c, least squares."""
    import scipy.optimize

    t = np.arange(trace.size) * dt

    def model(t, a, sigma, omega, phase, b, tau, c):
        return a * np.exp(sigma * t) * np.cos(omega * t + phase) + b * np.exp(-t / tau) + c

    guess = [np.ptp(trace) / 2, near.real, near.imag, 0.0, 0.0, 2.0, float(trace[-1])]
    bounds = (
        [0, -20, 0.1, -2 * np.pi, -np.inf, 0.05, -np.inf],
        [np.inf, 5, 30, 2 * np.pi, np.inf, 100, np.inf],
    )
    fitted, _ = scipy.optimize.curve_fit(model, t, trace, p0=guess, bounds=bounds, maxfev=20000)
    return complex(fitted[1], fitted[2])


def truth_design_inputs(
    aircraft: str, airspeed_kts: float, altitude_ft: float
) -> tuple[TuneModel, TuneOptions]:
    """The aircraft's validated linear model (agent.sim.truth) as `agent.tune.design` takes an
    identified one, and the installation's linkage (`links`) and the servo's lag as a finished
    run's "follows" check measures them over the default config's surfaces: the design the
    agent would make from a perfect model."""
    truth = linear_truth(aircraft, airspeed_kts, altitude_ft=altitude_ft)
    names = list(truth.states)
    surfaces = Excitation().surfaces
    probed = links(aircraft, airspeed_kts, altitude_ft)
    model = TuneModel(
        id=aircraft,
        inputs=list(INPUTS),
        outputs=names[:8],
        A=truth.A,
        B=truth.B,
        C=np.eye(len(names))[:8],
        trim={n: float(v) for n, v in zip(names, truth.trim_state, strict=True)},
    )
    measured = {}
    for c, (link, even, knee) in probed.items():
        mapping = surface_link(surfaces[c], None)  # plan units per notional degree
        measured[c] = {
            "gain": link / mapping,
            "even": even / abs(mapping),
            "knee": knee * mapping,
            "lag_s": SERVO_DELAY_S,
        }
    return model, TuneOptions(measured=measured)
