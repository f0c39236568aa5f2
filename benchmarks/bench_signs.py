"""Does the full preset's result hinge on the relative sign of its lateral multisines?

    .venv/bin/python benchmarks/bench_signs.py                       # the Cub, calm, seeds 2–3
    .venv/bin/python benchmarks/bench_signs.py --aircraft c182 --turbulence 1 --seeds 4

Flies the full preset four times per seed, with the aileron's and the rudder's amplitudes each
as is or negated (the same waveforms, mirrored), through `agent.sim.offline.fly` as
`make bench-jsbsim` does, and identifies each record as the agent does. Prints every named
mode's error against the validated truth (%), the spiral's z (identified less true, in its
standard errors), and the bank angle's mean and largest excursion. An excitation design
should not matter by a sign that carries no information: the rows of one seed should agree
to within its noise.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse

import numpy as np
from bench_jsbsim import AIRCRAFT, FIRST_SEED, MODES, experiment, mode_errors, ours

from agent.excitation.plan import FULL_AMPLITUDE, preset
from agent.sim.offline import OUTPUTS, fly
from agent.sim.truth import linear_truth

SIGNS = ((1, 1), (-1, 1), (1, -1), (-1, -1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--aircraft", default="J3Cub", choices=list(AIRCRAFT))
    parser.add_argument("--turbulence", type=float, default=0.0)
    parser.add_argument("--seeds", type=int, default=2)
    args = parser.parse_args()
    speed = AIRCRAFT[args.aircraft]
    truth = linear_truth(args.aircraft, speed).modes()
    spiral_true = truth["spiral"][0].real if truth.get("spiral") else None
    head = "  ".join(f"{m:>13}" for m in MODES)
    print(f"{args.aircraft} at {speed:g} kt, turbulence {args.turbulence:g}; errors in %")
    print(f"{'seed':>4} {'aileron':>7} {'rudder':>6} {head}  spiral z  bank mean / max (deg)")
    phi = OUTPUTS.index("phi")
    for seed in range(FIRST_SEED, FIRST_SEED + args.seeds):
        for aileron, rudder in SIGNS:
            amplitude = {
                "aileron": aileron * FULL_AMPLITUDE["aileron"],
                "rudder": rudder * FULL_AMPLITUDE["rudder"],
            }
            plan = preset("full", amplitude=amplitude)
            rec = fly(
                plan, aircraft=args.aircraft, speed_kts=speed, turbulence=args.turbulence, seed=seed
            )
            found, _, _, spiral = ours(experiment(rec), rec.dt, rec)
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


if __name__ == "__main__":
    main()
