"""The whole-aircraft method on JSBSim's aircraft through the full preset (issue 19).

    .venv/bin/python benchmarks/bench_aircraft.py                       # 3 aircraft, calm and
                                                                        # light turbulence, 3 seeds
    .venv/bin/python benchmarks/bench_aircraft.py --aircraft pa28 --turbulence 1 --seeds 10

Each seed is one offline flight (`agent.sim.offline.fly`: the same JSBSim trim, emulated
ArduPlane servos and sensor noise as `sysid sim`, without real time) of the full preset, from
2 s before it to 2 s after, at 100 Hz. The record is identified as the agent does (trim: the
first 0.5 s; sampled inputs), once with the INS's heading and velocities (the measured wind) and
once without (`--no-wind-too` skips that). Truth: `agent.sim.truth.linear_truth`, JSBSim's
validated small-amplitude linear model. Printed per aircraft and condition: each named mode's
error |λ − λ_true| / |λ_true| (median and worst over seeds), the seeds with every named mode
within 10 %, and the median seconds per identification.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse
import time

import numpy as np

from agent.channels import INPUT_ROLES, OUTPUT_ROLES
from agent.excitation.plan import preset
from agent.ident import Experiment, Settings, identify
from agent.sim.offline import fly
from agent.sim.truth import linear_truth

AIRCRAFT = {"J3Cub": 60.0, "c182": 90.0, "pa28": 90.0}
MODES = ("short period", "phugoid", "Dutch roll", "roll")
TRIM_SAMPLES = 50  # 0.5 s at 100 Hz, as the agent's trim


def errors(result, truth: dict[str, list[complex]]) -> list[float]:
    """Each named mode's worst relative error (inf when the mode is not found)."""
    found: dict[str, list[complex]] = {}
    for mode in result.modes:
        if mode.name:
            found.setdefault(mode.name, []).append(complex(mode.eigenvalue))
    out = []
    for name in MODES:
        worst = 0.0
        for true in truth.get(name, []):
            near = min((abs(e - true) for e in found.get(name, [])), default=np.inf)
            worst = max(worst, near / abs(true))
        out.append(worst)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--aircraft", nargs="*", default=list(AIRCRAFT))
    parser.add_argument("--turbulence", type=float, nargs="*", default=[0.0, 1.0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--no-wind-too", action="store_true")
    args = parser.parse_args()
    plan = preset("full")
    settings = Settings(held_inputs=False)
    print(f"{'aircraft':8} {'turb':>4} {'wind':>5}  " + "  ".join(f"{m:>16}" for m in MODES)
          + "   ≤10 %   s/id")  # fmt: skip
    for name in args.aircraft:
        truth = linear_truth(name, AIRCRAFT[name]).modes()
        for turbulence in args.turbulence:
            rows: dict[bool, list[list[float]]] = {True: [], False: []}
            times: dict[bool, list[float]] = {True: [], False: []}
            for seed in range(2, 2 + args.seeds):  # JSBSim's seeds 0 and 1 are one sequence
                rec = fly(plan, aircraft=name, speed_kts=AIRCRAFT[name], turbulence=turbulence,
                          seed=seed)  # fmt: skip
                u0, y0 = rec.u[:TRIM_SAMPLES].mean(0), rec.y[:TRIM_SAMPLES].mean(0)
                for wind in (True, False) if not args.no_wind_too else (True,):
                    exp = Experiment(rec.u - u0, rec.y - y0, operating_point=y0,
                                     navigation=rec.ins if wind else None)  # fmt: skip
                    start = time.perf_counter()
                    result = identify(exp, rec.dt, input_names=rec.inputs,
                                      output_names=rec.outputs, input_roles=INPUT_ROLES,
                                      output_roles=OUTPUT_ROLES, settings=settings)  # fmt: skip
                    times[wind].append(time.perf_counter() - start)
                    rows[wind].append(errors(result, truth))
            for wind in (True, False):
                if not rows[wind]:
                    continue
                e = 100 * np.array(rows[wind])
                cells = "  ".join(f"{np.median(c):6.1f} / {np.max(c):6.1f}" for c in e.T)
                ok = int(np.sum(e.max(axis=1) <= 10))
                print(
                    f"{name:8} {turbulence:4.1f} {'yes' if wind else 'no':>5}  {cells}   "
                    f"{ok:2d}/{len(e):<2d}  {np.median(times[wind]):5.2f}",
                    flush=True,
                )
    print("cells: median / worst error over seeds, %")


if __name__ == "__main__":
    main()
