"""`sysid tune`'s gains against the flight, on each benchmark aircraft: designed on JSBSim's
validated linear model (agent.sim.truth) with the installation's linkage, flown in FBWA by the
emulated ArduPlane on the nonlinear aircraft (agent.sim.steps), beside ArduPlane's defaults.

    .venv/bin/python benchmarks/tune_check.py                   # six aircraft, a few minutes
    .venv/bin/python benchmarks/tune_check.py --aircraft J3Cub  # one

Per aircraft and axis: the designed gains, the whole loop's margins, the ±20° bank and ±5°
pitch steps' rise time and overshoot predicted and flown (calm, and in light turbulence, W20 =
5 ft/s), and the rms bank and pitch error FBWA holds hands off for 30 s in light turbulence
with the tuned gains and with ArduPlane's defaults (`SCALING_SPEED` and the airspeed limits
set for the aircraft in both, as its pilot would); and the yaw damper (YAW2SRV_DAMP) as the
agent designs it, a rudder pulse's Dutch roll in FBWA with and without it, predicted and flown.
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from agent.config import Channels, Excitation
from agent.sim.aircraft import FLOWN
from agent.sim.steps import (
    TICK_S,
    flown_rudder_pulse,
    flown_step,
    held,
    oscillation,
    truth_design_inputs,
    truth_plants,
)
from agent.tune import TuneError, design, design_axis, scaling_for

LIGHT = 1.0  # turbulence: W20 = 5 ft/s


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--aircraft", nargs="+", default=list(FLOWN), choices=list(FLOWN))
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    for aircraft in args.aircraft:
        speed, altitude = FLOWN[aircraft][:2]
        tuned: dict[str, float] = {}
        axes, eas = truth_plants(aircraft, speed, altitude)
        # As `sysid tune`: SCALING_SPEED the trim's, raised where an FF would not fit.
        scaling = max([eas, *(scaling_for(p, a, eas) for p, a in axes.values())])
        print(f"{aircraft}: trim {eas:.1f} m/s, SCALING_SPEED {scaling:.1f}")
        for axis, (plant, actuator) in axes.items():
            try:
                tune = design_axis(axis, plant, actuator, eas=eas, scaling_speed=scaling)
            except TuneError as exc:
                print(f"{aircraft} {axis}: not tuned: {exc}")
                continue
            tuned.update(tune.params)
            gains = ", ".join(f"{k} {v:g}" for k, v in tune.params.items())
            m = tune.attitude_loop
            print(
                f"{aircraft} {axis}: {gains}; whole loop {m.gain_db:.1f} dB, "
                f"{m.phase_deg:.0f}° at {m.crossover_rad_s:.2f} rad/s; predicted rise "
                f"{tune.rise_s:.2f} s, overshoot {tune.overshoot_pct:.1f} %"
            )
            for turbulence in (0.0, LIGHT):
                for sign in (1, -1):
                    step = flown_step(
                        aircraft,
                        speed,
                        altitude,
                        {**tune.params, "SCALING_SPEED": scaling},
                        axis,
                        sign * tune.step_deg,
                        turbulence=turbulence,
                        seed=args.seed,
                    )
                    rise_error = step.rise_s / tune.rise_s - 1
                    print(
                        f"    {'calm ' if not turbulence else 'light'} {sign * tune.step_deg:+g}°:"
                        f" flown rise {step.rise_s:.2f} s ({rise_error:+.0%}), overshoot "
                        f"{step.overshoot_pct:.1f} %, final {step.final_deg:.2f}°"
                    )
        for label, params in (
            ("tuned", {**tuned, "SCALING_SPEED": scaling}),
            ("ArduPlane defaults", {"SCALING_SPEED": eas}),
        ):
            bank, pitch = held(aircraft, speed, altitude, params, turbulence=LIGHT, seed=args.seed)
            print(
                f"  light turbulence, held hands off, {label}: bank rms {bank:.2f}°, "
                f"pitch rms {pitch:.2f}°"
            )
        yaw_damper(aircraft, speed, altitude)


def yaw_damper(aircraft: str, speed: float, altitude: float) -> None:
    """The yaw damper as the agent designs it (agent.tune.design on the truth, with the
    installation's linkage), then a rudder pulse flown in FBWA calm with and without it: the
    Dutch roll fitted to the yaw rate's free response beside the prediction."""
    model, options = truth_design_inputs(aircraft, speed, altitude)
    try:
        designed = design(model, Channels(), Excitation().surfaces, options)
    except TuneError as exc:
        print(f"{aircraft} yaw: not designed: {exc}")
        return
    yaw = designed.yaw
    if yaw is None:
        print(f"{aircraft} yaw: no rudder in the model")
        return
    damp = yaw.params["YAW2SRV_DAMP"]
    notes = "; ".join(yaw.notes)
    print(f"{aircraft} yaw: YAW2SRV_DAMP {damp:g}{'; ' + notes if notes else ''}")
    params = designed.params()
    for value, predicted in ((damp, yaw.after), (0.0, yaw.before)):
        if value == 0.0 and damp == 0.0 and predicted is yaw.after:
            continue
        rate = flown_rudder_pulse(aircraft, speed, altitude, {**params, "YAW2SRV_DAMP": value})
        flown = oscillation(rate, TICK_S, predicted)
        print(
            f"    YAW2SRV_DAMP {value:g}: Dutch roll predicted ζ {yaw.zeta(predicted):.3f} at "
            f"{abs(predicted):.2f} rad/s, flown ζ {-flown.real / abs(flown):.3f} at "
            f"{abs(flown):.2f} rad/s"
        )


if __name__ == "__main__":
    main()
