"""The bare airframe identified from a closed-loop excitation (the plan on the sticks, FBWA's
laws flying the surfaces: agent.excitation.scheduler) against the open-loop one (the same plan
on the surfaces, MANUAL), on each benchmark aircraft.

    .venv/bin/python benchmarks/closed_loop_check.py              # six aircraft, calm and light
    .venv/bin/python benchmarks/closed_loop_check.py --aircraft J3Cub --turbulence 0
    .venv/bin/python benchmarks/closed_loop_check.py --bound  # and what each record allows
    .venv/bin/python benchmarks/closed_loop_check.py --sizing nominal  # at SCALE of the preset

Per aircraft, condition and seed: the full preset flown offline (agent.sim.offline.fly, with
and without the emulated ArduPlane in FBWA at ArduPlane's default gains), sized as the agent
sizes it for that aircraft in that air (`--sizing auto`, the default: bench_jsbsim's
calibration runs; the agent plays the plan it sized on the sticks too) or at SCALE of its
written amplitudes (`--sizing nominal`; on the T-6 at 150 kt that is past its linear range,
where its open-loop phugoid moves by 8 %). Each record is identified as the agent does
(benchmarks/bench_jsbsim.py `ours`: the whole-aircraft method with the INS's wind; the
closed-loop one told so, its lateral axis refined by prediction error,
agent.ident.aircraft.predictor), and per named mode the closed-loop model's difference from
the open-loop one (bench_jsbsim.mode_errors: pole by pole, an overdamped short period by its
ωn and ζ) and each one's error against the validated truth. `--bound`: each record's
Cramér–Rao bound for the validated truth (bench_jsbsim.truth_bound: each mode's median error
an efficient estimator of the method's structure would have on it, the surfaces as measured
taken as known inputs), open and closed loop: where the closed loop's is wide, the loop has
held the mode down and the record cannot give it, whatever the estimator.
"""

from __future__ import annotations

import argparse
import os
from dataclasses import replace

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from bench_jsbsim import (
    AIRCRAFT,
    MODES,
    OURS,
    _amplitudes,
    experiment,
    mode_errors,
    ours,
    setup_for,
    sized_plans,
    truth_bound,
)

from agent.excitation.plan import preset
from agent.ident.errors import DataError, IdentificationFailed
from agent.sizing import scaled

SCALE = 0.5  # of the full preset's written amplitudes, with `--sizing nominal`
WITHIN = 0.10  # the closed-loop model's modes within this of the open-loop one's


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--aircraft", nargs="+", default=list(AIRCRAFT), choices=list(AIRCRAFT))
    parser.add_argument("--turbulence", nargs="+", type=float, default=[0.0, 1.0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--bound", action="store_true", help="each record's Cramér–Rao bound")
    parser.add_argument(
        "--sizing",
        choices=("auto", "nominal"),
        default="auto",
        help=f"the preset as the agent sizes it (auto), or at {SCALE:g} of its amplitudes",
    )
    args = parser.parse_args()
    at = "as the agent sizes it" if args.sizing == "auto" else f"at {SCALE:g} of its amplitudes"
    print(f"closed loop (FBWA) against open loop (MANUAL), full preset {at}; modes {MODES}")
    for name in args.aircraft:
        for turbulence in args.turbulence:
            setup = setup_for(name, turbulence)
            if args.sizing == "auto":
                plans, refused, _ = sized_plans(setup)
                plan = plans["full"]
                if refused["full"]:  # the agent would not arm it, on the sticks or not
                    print(f"{name:8} {turbulence:3g}: refused: {'; '.join(refused['full'])}")
                    continue
            else:
                plan = scaled(
                    preset("full", controls=setup.controls), dict.fromkeys(setup.controls, SCALE)
                )
            print(f"{name:8} {turbulence:3g}: flown at {_amplitudes(plan)}", flush=True)
            reference = setup.truth()
            truth = reference.modes()
            worst, seeds_within = [0.0] * len(MODES), 0
            for seed in range(1, args.seeds + 1):
                found, bounds = {}, {}
                for loop in ("open", "closed"):
                    rec = setup.fly(plan, seed, fbwa=loop == "closed")
                    exp = experiment(rec, setup)
                    try:
                        # The agent tells the identification a run flown on the sticks
                        # was closed loop (agent.ident.aircraft.predictor).
                        settings = replace(OURS, closed_loop=loop == "closed")
                        found[loop], _, _, _ = ours(exp, rec.dt, setup, settings)
                        if args.bound:
                            bounds[loop] = truth_bound(exp, rec.dt, setup, reference)[1]
                    except (IdentificationFailed, DataError) as exc:
                        found[loop] = {}
                        print(f"  {name} {turbulence:g} seed {seed} {loop}: not identified: {exc}")
                apart = mode_errors(found["closed"], found["open"])
                to_truth = {loop: mode_errors(found[loop], truth) for loop in found}
                worst = [max(w, a) for w, a in zip(worst, apart, strict=True)]
                seeds_within += all(a <= WITHIN for a in apart)
                cells = ", ".join(
                    f"{m} {100 * a:.1f} % (truth: open {100 * o:.1f}, closed {100 * c:.1f})"
                    for m, a, o, c in zip(
                        MODES, apart, to_truth["open"], to_truth["closed"], strict=True
                    )
                )
                print(f"{name:8} {turbulence:3g} seed {seed}: closed vs open: {cells}", flush=True)
                for loop, medians in bounds.items():
                    allowed = ", ".join(
                        f"{m} {100 * b:.1f} %" for m, b in zip(MODES, medians, strict=True)
                    )
                    print(f"{'':8} {'':3} {loop:6} loop's bound, median error: {allowed}")
            summary = ", ".join(f"{m} {100 * w:.1f} %" for m, w in zip(MODES, worst, strict=True))
            print(
                f"{name:8} {turbulence:3g}: every mode within {WITHIN:.0%} of the open loop in "
                f"{seeds_within} of {args.seeds} seeds; worst: {summary}",
                flush=True,
            )


if __name__ == "__main__":
    main()
