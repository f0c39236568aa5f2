"""Which instrument's noise moves a mode, on one benchmark aircraft and manoeuvre: the same
noise-free records identified with no sensor noise, with each group's alone, and with all.

    .venv/bin/python benchmarks/noise_check.py --aircraft t6texan2 --excitation card   # ~2 min

Each seed's record is flown once without noise (as `make bench-jsbsim` sizes the manoeuvre,
in `--turbulence`), then each group's white noise is added at the simulator's levels
(agent.sim.aircraft.NOISE), from its own random stream: the surface potentiometers (the
inputs), the air data and the INS's attitude and rates (the outputs), the INS's navigation
(heading and velocities, the measured wind). The identification is the benchmark's, with the
INS's navigation. Printed per group and named mode: its natural frequency's error against the
validated truth (signed: a mode found slow is negative), mean and range over the seeds.

A group whose noise moves a mode well beyond the noise-free error, on every seed the same way,
biases it; one that only widens the range adds scatter. The noise-free row is the method's
structure on that record.
"""

from __future__ import annotations

import argparse
import dataclasses
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
from bench_jsbsim import (
    AIRCRAFT,
    EXCITATIONS,
    FIRST_SEED,
    MODES,
    Record,
    _second_order,
    experiment,
    ours,
    setup_for,
    sized_plans,
)

from agent.sim.aircraft import NOISE
from agent.sim.offline import INPUT_CHANNELS, INS_CHANNELS, OUTPUT_NOISE

SURFACES = ("elevator", "aileron", "rudder")
# The record's surface columns' noise: the aileron is ½(δA_R − δA_L), two potentiometers.
SURFACE_NOISE = {
    "elevator": NOISE["elevator"],
    "aileron": np.sqrt(0.5) * NOISE["aileron_left"],
    "rudder": NOISE["rudder"],
}
GROUPS = {
    "none": (),
    "surfaces": ("surfaces",),
    "air data, attitude, rates": ("outputs",),
    "navigation": ("navigation",),
    "all": ("surfaces", "outputs", "navigation"),
}


def noisy(rec: Record, parts: tuple[str, ...], rng: np.random.Generator) -> Record:
    """`rec` with white noise at the simulator's levels on the groups in `parts`."""
    u, y, ins = rec.u.copy(), rec.y.copy(), rec.ins.copy()
    if "surfaces" in parts:
        for name in SURFACES:
            u[:, INPUT_CHANNELS.index(name)] += SURFACE_NOISE[name] * rng.standard_normal(len(u))
    if "outputs" in parts:
        for k, name in enumerate(Record.outputs):
            y[:, k] += NOISE[OUTPUT_NOISE[name]] * rng.standard_normal(len(y))
    if "navigation" in parts:
        for k, name in enumerate(INS_CHANNELS):
            ins[:, k] += NOISE[name] * rng.standard_normal(len(ins))
    return dataclasses.replace(rec, u=u, y=y, ins=ins)


def frequency_errors(found: dict[str, list[complex]], truth: dict) -> dict[str, float]:
    """Each named mode's natural-frequency error against the truth (signed, relative): a
    pair's or two real poles' by their second-order polynomial, a single pole's by its
    magnitude."""
    out = {}
    for name in MODES:
        true, mine = truth.get(name, []), found.get(name, [])
        if not true or not mine:
            continue
        polynomial = _second_order(true), _second_order(mine)
        if None not in polynomial:
            out[name] = polynomial[1][0] / polynomial[0][0] - 1
        elif len(true) == 1:
            nearest = min(mine, key=lambda pole: abs(pole - true[0]))
            out[name] = abs(nearest) / abs(true[0]) - 1
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--aircraft", choices=list(AIRCRAFT), default="t6texan2")
    parser.add_argument("--excitation", choices=EXCITATIONS, default="card")
    parser.add_argument("--turbulence", type=float, default=0.0)
    parser.add_argument("--seeds", type=int, default=4, help=f"seeds from {FIRST_SEED}")
    args = parser.parse_args()
    if args.seeds < 1:
        parser.error("--seeds must be at least 1")
    setup = setup_for(args.aircraft, args.turbulence)
    truth = setup.truth().modes()
    plans, refused, _ = sized_plans(setup)
    if refused[args.excitation]:
        parser.error(f"the agent would not arm it: {'; '.join(refused[args.excitation])}")
    seeds = range(FIRST_SEED, FIRST_SEED + args.seeds)
    records = [setup.fly(plans[args.excitation], seed, noise=False) for seed in seeds]
    print(
        f"{args.aircraft}, {args.excitation}, turbulence {args.turbulence:g}, "
        f"{args.seeds} seeds: each named mode's ωn error, mean [range] %"
    )
    for label, parts in GROUPS.items():
        errors: dict[str, list[float]] = {}
        for seed, rec in zip(seeds, records, strict=True):
            rng = np.random.default_rng(seed)
            found, _, _, _ = ours(experiment(noisy(rec, parts, rng), setup), rec.dt, setup)
            for name, error in frequency_errors(found, truth).items():
                errors.setdefault(name, []).append(100 * error)
        cells = "  ".join(
            f"{name} {np.mean(v):+.1f} [{min(v):+.1f}, {max(v):+.1f}]"
            + ("" if len(v) == args.seeds else f" ({args.seeds - len(v)} not found)")
            for name, v in errors.items()
        )
        print(f"  {label:26} {cells}", flush=True)


if __name__ == "__main__":
    main()
