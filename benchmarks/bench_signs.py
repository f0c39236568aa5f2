"""Does the full preset's result hinge on the relative sign of its lateral multisines?

    .venv/bin/python benchmarks/bench_signs.py                       # the Cub, calm, seeds 2–3
    .venv/bin/python benchmarks/bench_signs.py --aircraft c182 --turbulence 1 --seeds 4
    .venv/bin/python benchmarks/bench_signs.py --scale-lateral 0.5 --scale-longitudinal 0.5
    .venv/bin/python benchmarks/bench_signs.py --seeds 1 --signs ++    # one flight

Flies the full preset four times per seed, with the aileron's and the rudder's amplitudes each
as is or negated (the same waveforms, mirrored), through `agent.sim.offline.fly` as
`make bench-jsbsim` does, and identifies each record as the agent does. Prints every named
mode's error against the validated truth (%), the spiral's z (identified less true, in its
standard errors), and the bank angle's mean and largest excursion. An excitation design
should not matter by a sign that carries no information: the rows of one seed should agree
to within its noise. `--scale-lateral` and `--scale-longitudinal` scale the preset's
amplitudes of aileron and rudder, and of elevator and throttle: what moves with amplitude is
nonlinearity. The truth's spiral is printed beside FGLinearization's, an independent check,
and, per seed, the spiral identified from the truth's own linear response to the first
flight's recorded inputs (held over each step, as `Truth.simulate` holds them): what the
method gives where nothing is nonlinear. `--signs` flies some of the four (aileron's sign, then
the rudder's: ++, -+, +-, --).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse
import dataclasses

import numpy as np
from bench_jsbsim import (
    AIRCRAFT,
    FIRST_SEED,
    MODES,
    TRIM_SAMPLES,
    Setup,
    experiment,
    mode_errors,
    ours,
)

from agent.channels import INPUT_ROLES, OUTPUT_ROLES
from agent.excitation.plan import FULL_AMPLITUDE, preset
from agent.ident import Settings, identify
from agent.sim.offline import OUTPUTS, Record, fly
from agent.sim.plant import INPUTS, Plant
from agent.sim.truth import Truth, linear_truth

SIGN_NAMES = {"++": (1, 1), "-+": (-1, 1), "+-": (1, -1), "--": (-1, -1)}


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.splitlines()[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--aircraft", default="J3Cub", choices=list(AIRCRAFT))
    parser.add_argument("--turbulence", type=float, default=0.0, help="1: light (W20 = 5 ft/s)")
    parser.add_argument("--seeds", type=int, default=2, help=f"seeds from {FIRST_SEED}")
    parser.add_argument(
        "--signs",
        nargs="+",
        choices=list(SIGN_NAMES),
        default=list(SIGN_NAMES),
        help="the aileron's and the rudder's signs to fly",
    )
    parser.add_argument("--scale-lateral", type=float, default=1.0)
    parser.add_argument("--scale-longitudinal", type=float, default=1.0)
    args = parser.parse_args()
    signs = [SIGN_NAMES[name] for name in args.signs]
    speed = AIRCRAFT[args.aircraft].speed_kts
    plant = Plant(args.aircraft, airspeed_kts=speed)
    setup = Setup(
        args.aircraft, AIRCRAFT[args.aircraft], args.turbulence, INPUTS, plant.true_airspeed
    )
    reference = linear_truth(args.aircraft, speed)
    truth = reference.modes()
    spiral_true = truth["spiral"][0].real if truth.get("spiral") else None
    fg = np.linalg.eigvals(plant.linearisation.A)
    if spiral_true is not None:
        real = fg[np.abs(fg.imag) < 1e-12].real
        nearest = real[np.argmin(np.abs(real - spiral_true))]
        print(
            f"spiral: truth {spiral_true:+.5f}, FGLinearization's nearest real pole {nearest:+.5f}"
        )
    head = "  ".join(f"{m:>13}" for m in MODES)
    print(f"{args.aircraft} at {speed:g} kt, turbulence {args.turbulence:g}; errors in %")
    print(f"{'seed':>4} {'aileron':>7} {'rudder':>6} {head}  spiral z  bank mean / max (deg)")
    phi = OUTPUTS.index("phi")
    for seed in range(FIRST_SEED, FIRST_SEED + args.seeds):
        first = None
        for aileron, rudder in signs:
            lateral, longitudinal = args.scale_lateral, args.scale_longitudinal
            amplitude = {
                "aileron": aileron * lateral * FULL_AMPLITUDE["aileron"],
                "rudder": rudder * lateral * FULL_AMPLITUDE["rudder"],
                "elevator": longitudinal * FULL_AMPLITUDE["elevator"],
                "throttle": longitudinal * FULL_AMPLITUDE["throttle"],
            }
            plan = preset("full", amplitude=amplitude)
            rec = fly(
                plan, aircraft=args.aircraft, speed_kts=speed, turbulence=args.turbulence, seed=seed
            )
            found, _, _, spiral = ours(experiment(rec, setup), rec.dt, setup)
            errors = "  ".join(f"{100 * e:>13.1f}" for e in mode_errors(found, truth))
            z = (
                (spiral.eigenvalue.real - spiral_true) / spiral.uncertainty.real
                if spiral is not None and spiral.uncertainty is not None and spiral_true
                else float("nan")
            )
            bank = np.degrees(rec.y[:, phi])
            print(
                f"{seed:>4} {aileron:>+7d} {rudder:>+6d} {errors}  {z:>8.1f}  "
                f"{bank.mean():+.1f} / {np.abs(bank).max():.1f}",
                flush=True,
            )
            if first is None:  # the truth's linear response is to this flight's inputs
                first = rec
        spiral = linear_spiral(reference, first, setup)
        print(f"{seed:>4} the truth's linear response: spiral {spiral:+.5f}")


def linear_spiral(truth: Truth, rec: Record, setup: Setup) -> float:
    """The spiral identified from the truth's linear response to `rec`'s inputs."""
    u = rec.u - rec.u[:TRIM_SAMPLES].mean(axis=0)
    u = u[:, [rec.inputs.index(name) for name in INPUTS]]
    u[:, INPUTS.index("throttle")] /= 1000.0  # µs → the truth's 0–1
    x = truth.simulate(u, rec.dt)
    y = rec.y[:TRIM_SAMPLES].mean(axis=0) + x[:, [OUTPUTS.index(o) for o in rec.outputs]]
    linear = dataclasses.replace(rec, y=y)
    result = identify(
        experiment(linear, setup, wind=False),
        rec.dt,
        input_names=rec.inputs,
        output_names=rec.outputs,
        input_roles=INPUT_ROLES,
        output_roles=OUTPUT_ROLES,
        settings=Settings(held_inputs=True),
    )
    return next(m.eigenvalue.real for m in result.modes if m.name == "spiral")


if __name__ == "__main__":
    main()
