"""`sysid tune`'s gains against the flight, on each benchmark aircraft: designed on JSBSim's
validated linear model (agent.sim.truth) with the installation's linkage (probed each way) and
the emulated servo's dead time, flown in FBWA by the emulated ArduPlane on the nonlinear
aircraft (agent.sim.steps), beside ArduPlane's defaults.

    .venv/bin/python benchmarks/tune_check.py                   # six aircraft, a few minutes
    .venv/bin/python benchmarks/tune_check.py --aircraft J3Cub  # one
    .venv/bin/python benchmarks/tune_check.py --model identified  # as `sysid tune MODEL`

`--model identified` designs instead on the model the agent identifies from a flight: the
full preset sized as the agent sizes it (benchmarks/bench_jsbsim.py's calibration runs),
flown once in calm air and once in light turbulence, each record identified as the agent
does with the INS (the whole-aircraft method, the surfaces as measured) and its surfaces'
linkage and lag measured on it as the agent measures them (agent.excitation.follow); the calm
model's gains flown calm, the light model's in light turbulence and held beside the defaults.
Each step is judged against its own way's prediction (the linkage may move a surface more one
way than the other).

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

import bench_jsbsim as bench

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
from agent.tune import Model, TuneError, design, design_axis, scaling_for
from agent.tune import Options as TuneOptions

LIGHT = 1.0  # turbulence: W20 = 5 ft/s
CONDITIONS = {"calm": 0.0, "light": LIGHT}
# The steps and holds `sysid tune`'s issue asks the gains to meet (issue 37): rise time within
# 20 % of the prediction, overshoot within 5 points of it and at most 10 %.
RISE_WITHIN, OVERSHOOT_POINTS, OVERSHOOT_MAX = 0.20, 5.0, 10.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--aircraft", nargs="+", default=list(FLOWN), choices=list(FLOWN))
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument(
        "--model",
        choices=("truth", "identified"),
        default="truth",
        help="design on the validated truth, or on the model identified from a flight",
    )
    args = parser.parse_args()
    if args.model == "identified":
        for aircraft in args.aircraft:
            identified(aircraft, args.seed)
        return
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
            print(designed_line(f"{aircraft} {axis}", tune))
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
                    rise_error = step.rise_s / predicted(tune, sign)[0] - 1
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


def predicted(tune, sign: int) -> tuple[float, float]:
    """The predicted step's (rise s, overshoot %) the way of `sign` (the linkage's travel may
    differ each way: agent.tune.AxisTune.each_way)."""
    return tune.each_way()["+" if sign > 0 else "−"]


def designed_line(label: str, tune) -> str:
    """One axis's designed gains, whole-loop margins and predicted step (each way where the
    linkage's travel differs)."""
    gains = ", ".join(f"{k} {v:g}" for k, v in tune.params.items())
    m = tune.attitude_loop
    steps = (
        f"rise {tune.rise_s:.2f} s, overshoot {tune.overshoot_pct:.1f} %"
        if tune.down is None
        else "; ".join(
            f"{w}: rise {r:.2f} s, overshoot {o:.1f} %" for w, (r, o) in tune.each_way().items()
        )
    )
    return (
        f"{label}: {gains}; whole loop {m.gain_db:.1f} dB, {m.phase_deg:.0f}° at "
        f"{m.crossover_rad_s:.2f} rad/s; predicted {steps}"
    )


def identified(aircraft: str, seed: int) -> None:
    """The gains designed on the models identified from the sized full preset flown calm and
    in light turbulence, each flown in its condition beside its prediction (steps), the light
    one held hands off beside ArduPlane's defaults."""
    speed, altitude = FLOWN[aircraft][:2]
    for condition, turbulence in CONDITIONS.items():
        setup = bench.setup_for(aircraft, turbulence)
        plans, refused, _ = bench.sized_plans(setup)
        if refused["full"]:
            print(f"{aircraft} {condition}: the agent refused the full preset: {refused['full']}")
            continue
        rec = setup.fly(plans["full"], bench.FIRST_SEED)
        # The linkage and lag as the agent measures them on the finished run (what its gains
        # design and `sysid tune --exec-log` take).
        options = TuneOptions(
            measured={
                f.control: {"gain": f.gain, "lag_s": f.lag_s, "even": f.even, "knee": f.knee}
                for f in bench.followed(setup, rec, plans["full"])
                if f.verdict == "follows"
            }
        )
        print(
            f"{aircraft} {condition}: linkage measured "
            + ", ".join(
                f"{c} {m['gain']:.3f} (even {m['even']:.3f} from {m['knee']:.2f}, "
                f"lag {m['lag_s']:.2f} s)"
                for c, m in options.measured.items()
            )
        )
        exp = bench.experiment(rec, setup)
        _, result, _, _ = bench.ours(exp, rec.dt, setup)
        if result.continuous is None or result.coordinates != "outputs":
            print(f"{aircraft} {condition}: no continuous model in output coordinates")
            continue
        trim = dict(zip(rec.outputs, exp.operating_point, strict=True))
        model = Model(
            id=f"{aircraft}-{condition}",
            inputs=list(result.input_names),
            outputs=list(result.output_names),
            A=result.continuous.A,
            B=result.continuous.B,
            C=result.continuous.C,
            trim=trim,
        )
        named = ", ".join(
            f"{m.name} {abs(complex(m.eigenvalue)):.2f} rad/s" for m in result.modes if m.name
        )
        print(f"{aircraft} {condition}: identified ({named})")
        try:
            designed = design(model, Channels(), Excitation().surfaces, options)
        except TuneError as exc:
            print(f"{aircraft} {condition}: not tuned: {exc}")
            continue
        params = designed.params()
        for note in (*designed.notes, *designed.refused):
            print(f"    {note}")
        for tune in designed.tunes:
            print(designed_line(f"{aircraft} {condition} {tune.axis}", tune))
            misses = []
            for sign in (1, -1):
                step = flown_step(
                    aircraft,
                    speed,
                    altitude,
                    params,
                    tune.axis,
                    sign * tune.step_deg,
                    turbulence=turbulence,
                    seed=seed,
                )
                rise, overshoot = predicted(tune, sign)
                rise_error = step.rise_s / rise - 1
                if abs(rise_error) > RISE_WITHIN:
                    misses.append(f"rise {rise_error:+.0%}")
                if abs(step.overshoot_pct - overshoot) > OVERSHOOT_POINTS:
                    misses.append(f"overshoot {step.overshoot_pct:.1f} % against predicted")
                if step.overshoot_pct > OVERSHOOT_MAX:
                    misses.append(f"overshoot {step.overshoot_pct:.1f} %")
                print(
                    f"    {sign * tune.step_deg:+g}°: flown rise {step.rise_s:.2f} s "
                    f"({rise_error:+.0%}), overshoot {step.overshoot_pct:.1f} %, final "
                    f"{step.final_deg:.2f}°"
                )
            print(f"    {'meets' if not misses else 'misses: ' + '; '.join(misses)}")
        if turbulence:
            for label, flown in (("tuned", params), ("ArduPlane defaults", {})):
                bank, pitch = held(
                    aircraft,
                    speed,
                    altitude,
                    {"SCALING_SPEED": designed.eas} | flown,
                    turbulence=turbulence,
                    seed=seed,
                )
                print(
                    f"  {condition}, held hands off, {label}: bank rms {bank:.2f}°, "
                    f"pitch rms {pitch:.2f}°"
                )


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
