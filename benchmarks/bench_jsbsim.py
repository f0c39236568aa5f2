"""The whole-aircraft benchmark: JSBSim's three aircraft, calm and in light turbulence, identified
through the full preset by suas-sysid and by the peers, in one process.

    make bench-jsbsim                                            # 3 × 2 × 10 seeds (~5 min)
    .venv/bin/python benchmarks/bench_jsbsim.py --seeds 2 --no-peers          # a quick look
    .venv/bin/python benchmarks/bench_jsbsim.py --aircraft pa28 --turbulence 1
    .venv/bin/python benchmarks/bench_jsbsim.py --no-peers --without alpha-products
    .venv/bin/python benchmarks/bench_jsbsim.py --aircraft J3Cub --turbulence 0 --seeds 1 \
        --no-peers                                               # the smoke test: one flight

Each seed is one offline flight (`agent.sim.offline.fly`: JSBSim trimmed as `sysid sim` trims
it, the emulated ArduPlane's servos, the sensors' noise, 100 Hz). It holds the full preset
from 2 s before to 2 s after. The record is identified as the agent does: the trim from the
first 0.5 s, the INS's heading and velocities for the wind. The aircraft and speeds are the
J-3 Cub at 60 kt and the Cessna 182 and PA-28 at 90 kt. Light turbulence:
Dryden (MIL-F-8785C), W20 = 5 ft/s (`--turbulence 1`). Seeds start at 2, because JSBSim's
seeds 0 and 1 give one turbulence sequence.

Truth: `agent.sim.truth.linear_truth`, JSBSim's validated small-amplitude linear model. Printed
per aircraft, condition and method:
- each named mode's error |λ − λ_true| / |λ_true| (median / worst over seeds);
- the seeds with every named mode within 10 %;
- for suas-sysid, the seeds whose spiral holds the truth within 3 standard errors, and below
  the row the spiral's z-scores (identified − truth over its standard error): their mean, sd,
  rms and worst, which would be 0, 1, 1 and about 2 for an unbiased, calibrated estimate;
- the validation TIC: the model simulated on separate records, its own seed each: an elevator
  doublet judged on V, α, q, θ, and an aileron then a rudder doublet judged on β, p, r, φ
  (the mean of the two means; median / worst over seeds). The doublets are sized to the
  atmosphere as a flight-test engineer sizes a validation manoeuvre (`validation_scale`);

- the median seconds per identification.

The peers get the same records (inputs and outputs less the trim) and the truth's order
without engine, altitude and heading (8 aircraft states + 1); python-control and SIPPY are the
`bench` extra (`pip install -e '.[bench]'`, which `make bench-jsbsim` does). The "validated
truth" row gives the truth's own validation TIC: the best a linear model can score on those
records.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse
import dataclasses
import importlib.util
import time
import warnings

import numpy as np

from agent.channels import INPUT_ROLES, OUTPUT_ROLES
from agent.excitation.plan import (
    DOUBLET_PULSE_S,
    PRESET_AMPLITUDE,
    Doublet,
    Plan,
    Segment,
    Timeline,
    preset,
    render,
)
from agent.ident import Experiment, Settings, identify
from agent.ident.convert import StateSpace
from agent.ident.errors import DataError, IdentificationFailed
from agent.ident.fit import simulate
from agent.sim.offline import Record, fly
from agent.sim.truth import Truth, linear_truth, theil

AIRCRAFT = {"J3Cub": 60.0, "c182": 90.0, "pa28": 90.0}
MODES = ("short period", "phugoid", "Dutch roll", "roll")
TRIM_SAMPLES = 50  # 0.5 s at 100 Hz, as the agent's trim
PEER_ORDER = 9
TEXTBOOK_P = 4
FIRST_SEED = 2  # JSBSim's seeds 0 and 1 give one turbulence sequence
VALIDATION_SEED = 1000
QUIET_SEED = 1500
SNR_REQUIRED = 3.0
MAX_VALIDATION_SCALE = 2.0
COMMAND_HZ = 50.0  # `fly`'s command rate
# suas-sysid as the agent runs it on these records: the surfaces' positions are sampled by
# their potentiometers while they move, so the inputs are not held between samples.
OURS = Settings(held_inputs=False)


def experiment(rec: Record, wind: bool = True) -> Experiment:
    u0, y0 = rec.u[:TRIM_SAMPLES].mean(0), rec.y[:TRIM_SAMPLES].mean(0)
    return Experiment(
        rec.u - u0, rec.y - y0, operating_point=y0, navigation=rec.ins if wind else None
    )


# The validation records: each axis's doublets, judged on that axis's outputs. One record
# with every doublet would judge a linear model on what no linear model holds: the lateral
# doublets' sideslip drag and bank move V, α and θ by more than the elevator's doublet does
# (the validated truth itself scores TIC 0.25 there on the PA-28, 0.76 on V).
VALIDATION = {"longitudinal": (("elevator", 8.0),), "lateral": (("aileron", 6.0), ("rudder", 8.0))}
AXIS_OUTPUTS = {"longitudinal": (0, 1, 2, 3), "lateral": (4, 5, 6, 7)}


def doublets(axis: str, scale: float) -> Plan:
    """An axis's validation manoeuvre: its surfaces' doublets in turn (the presets' pulse
    widths, `scale` times their amplitudes), each followed by free flight."""
    segments = tuple(
        Segment(
            signals={c: Doublet(pulse_s=DOUBLET_PULSE_S[c], amplitude=scale * PRESET_AMPLITUDE[c])},
            free_s=free,
        )
        for c, free in VALIDATION[axis]
    )
    return Plan(id=f"{axis[:3]}-doublets", axes=axis, segments=segments)


def validation(
    name: str, turbulence: float, seed: int, model: StateSpace
) -> tuple[list[tuple[Experiment, tuple]], list[float]]:
    """Each axis's doublet record, flown from trim with its own seed (its own turbulence),
    and the outputs it is judged on, with the scale its doublets were flown at
    (`validation_scale`). Without sensor noise: a doublet at the presets' amplitude moves the
    airspeed and α of these aircraft by about their sensors' noise (0.1 m/s, 0.2°), so a noisy
    record would score the pitot and the vane, not the model (the validated truth scored TIC
    0.7 on the airspeed there)."""
    out, scales = [], []
    for k, axis in enumerate(VALIDATION):
        flight = dict(aircraft=name, speed_kts=AIRCRAFT[name], turbulence=turbulence, noise=False)
        seeded = VALIDATION_SEED + 2 * seed + k
        exp = experiment(fly(doublets(axis, 1.0), seed=seeded, **flight), wind=False)
        quiet = fly(_still(doublets(axis, 1.0)), seed=QUIET_SEED + 2 * seed + k, **flight)
        scale = validation_scale(model, exp, experiment(quiet, wind=False), AXIS_OUTPUTS[axis])
        if scale > 1.0:
            exp = experiment(fly(doublets(axis, scale), seed=seeded, **flight), wind=False)
        scales.append(scale)
        out.append((Experiment(exp.u, exp.y), AXIS_OUTPUTS[axis]))
    return out, scales


def validation_scale(
    model: StateSpace, doublet: Experiment, quiet: Experiment, outputs: tuple[int, ...]
) -> float:
    """The doublets' scale on the presets' amplitudes: the smallest whose predicted response
    stands SNR_REQUIRED times above what the aircraft does with no input, capped at
    MAX_VALIDATION_SCALE (twice the presets' amplitude; beyond it these aircraft are no longer
    linear on a doublet).

    Chosen before it was run, from what is known in flight: the quiet record (as long as the
    validation record, trimmed flight with no input, its own turbulence seed) gives each
    output's RMS σ_w about its trim; the identified model driven by the 1× record's inputs
    gives each output's response RMS r. The ratio is the median over the axis's outputs of
    r / σ_w. A perfect linear model whose record carries an unmodelled response w uncorrelated
    with the doublet's s scores TIC = ‖w‖ / (‖s + w‖ + ‖s‖) ≈ σ_w / (2 σ_s), so a ratio of 3
    leaves the truth about 0.17, room under the 0.3 turbulence target for the model's own
    error. In calm air σ_w is the trim's own drift and the scale stays 1."""
    with np.errstate(all="ignore"):
        predicted = simulate(model, doublet.u, np.zeros(model.A.shape[0]))
    if not np.all(np.isfinite(predicted)):
        return 1.0
    cols = list(outputs)
    response = np.sqrt(np.mean(predicted[:, cols] ** 2, axis=0))
    still = np.sqrt(np.mean(quiet.y[:, cols] ** 2, axis=0))
    ratio = float(np.median(response / np.maximum(still, 1e-12)))
    return float(np.clip(SNR_REQUIRED / ratio, 1.0, MAX_VALIDATION_SCALE))


def _still(plan: Plan) -> Timeline:
    """`plan` rendered and then held at trim throughout: the quiet record's timeline."""
    timeline = render(plan, COMMAND_HZ)
    values = {c: np.zeros_like(v) for c, v in timeline.values.items()}
    return dataclasses.replace(timeline, values=values)


def mode_errors(found: dict[str, list[complex]], truth: dict[str, list[complex]]) -> list[float]:
    """Each named mode's worst relative error (inf when it is not found)."""
    out = []
    for name in MODES:
        worst = 0.0
        for true in truth.get(name, []):
            near = min((abs(e - true) for e in found.get(name, [])), default=np.inf)
            worst = max(worst, near / abs(true))
        out.append(worst)
    return out


def named_by_truth(eigenvalues: np.ndarray, truth: dict[str, list[complex]]) -> dict:
    """A peer's modes named as the truth's nearest ones (peers name nothing themselves)."""
    pool = [complex(e) for e in eigenvalues if e.imag >= -1e-9]
    found: dict[str, list[complex]] = {}
    for name in MODES:
        for true in truth.get(name, []):
            if not pool:
                break
            j = int(np.argmin([abs(e - true) for e in pool]))
            found.setdefault(name, []).append(pool.pop(j))
    return found


def ours(exp: Experiment, dt: float, rec: Record, settings: Settings = OURS):
    start = time.perf_counter()
    result = identify(
        exp,
        dt,
        input_names=rec.inputs,
        output_names=rec.outputs,
        input_roles=INPUT_ROLES,
        output_roles=OUTPUT_ROLES,
        settings=settings,
    )
    seconds = time.perf_counter() - start
    found: dict[str, list[complex]] = {}
    spiral = None
    for mode in result.modes:
        if mode.name:
            found.setdefault(mode.name, []).append(complex(mode.eigenvalue))
        if mode.name == "spiral":
            spiral = mode
    return found, result.discrete, seconds, spiral


def textbook(exp: Experiment, dt: float, rec: Record):
    start = time.perf_counter()
    result = identify(
        Experiment(exp.u, exp.y),
        dt,
        settings=Settings(
            method="time", markov=TEXTBOOK_P, order=PEER_ORDER, decimation=1, refine=False
        ),
    )
    return result.discrete, time.perf_counter() - start


def python_control(exp: Experiment, dt: float, rec: Record):
    import control

    start = time.perf_counter()
    H = control.markov(exp.y.T, exp.u.T, m=200, dt=True)
    sys_, _ = control.eigensys_realization(H, PEER_ORDER, dt=True)
    return StateSpace(sys_.A, sys_.B, sys_.C, sys_.D), time.perf_counter() - start


def sippy_n4sid(exp: Experiment, dt: float, rec: Record):
    import sippy_unipi

    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s = sippy_unipi.system_identification(
            exp.y.T, exp.u.T, "N4SID", SS_fixed_order=PEER_ORDER, SS_f=20, SS_p=20, tsample=dt
        )
    return StateSpace(s.A, s.B, s.C, s.D), time.perf_counter() - start


PEERS = {
    "textbook OKID/ERA": textbook,
    "python-control ERA": python_control,
    "SIPPY N4SID": sippy_n4sid,
}


def truth_tic(truth: Truth, records: list[tuple[Experiment, tuple]], dt: float) -> float:
    """The validated truth's own validation TIC: the best a linear model can do there. Its
    inputs are the throttle's position (0–1; the record's µs / 1000) and the surfaces'; each
    sample acts over the interval it ends."""
    tics = []
    for exp, outputs in records:
        u = exp.u.copy()
        u[:, 0] /= 1000.0
        x = truth.simulate(np.vstack([u[1:], u[-1:]]), dt)[:, : exp.y.shape[1]]
        tics.append(np.mean(theil(exp.y, x)[list(outputs)]))
    return float(np.mean(tics))


def validation_tic(model: StateSpace, records: list[tuple[Experiment, tuple]]) -> float:
    """The mean over the validation records of the mean TIC over each one's axis outputs, the
    model simulated from the trim the records start in (x0 = 0, as the truth is). Estimating
    x0 instead lets a model's unobservable engine states take absurd values (−517 on the Cub)
    that bias its bank angle by 5°."""
    tics = []
    for exp, outputs in records:
        with np.errstate(all="ignore"):
            predicted = simulate(model, exp.u, np.zeros(model.A.shape[0]))
        if not np.all(np.isfinite(predicted)):
            tics.append(1.0)
            continue
        tics.append(np.mean(theil(exp.y, predicted)[list(outputs)]))
    return float(np.mean(tics))


# Terms of the whole-aircraft method that `--without` leaves out (docs/identification.md):
# the Settings field that holds each.
ABLATIONS = {"alpha-products": "alpha_products", "sideslip-drag": "sideslip_drag"}


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.splitlines()[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--aircraft", nargs="*", choices=list(AIRCRAFT), default=list(AIRCRAFT))
    parser.add_argument(
        "--turbulence", type=float, nargs="*", default=[0.0, 1.0], help="1: W20 = 5 ft/s"
    )
    parser.add_argument("--seeds", type=int, default=10, help=f"seeds from {FIRST_SEED}")
    parser.add_argument("--no-peers", action="store_true", help="suas-sysid alone")
    parser.add_argument(
        "--without",
        nargs="*",
        default=[],
        choices=sorted(ABLATIONS),
        help="leave out a term of the whole-aircraft method, to see what it does",
    )
    args = parser.parse_args()
    missing = [
        name
        for module, name in (("control", "python-control"), ("sippy_unipi", "SIPPY"))
        if not args.no_peers and not importlib.util.find_spec(module)
    ]
    if missing:
        parser.error(
            f"{' and '.join(missing)} not installed: pip install -e '.[bench]' (make "
            "bench-jsbsim does), or --no-peers"
        )
    settings = dataclasses.replace(OURS, **{ABLATIONS[term]: False for term in args.without})
    plan = preset("full")
    print(
        "cells: median / worst over seeds; errors in %; ≤10 %: seeds with every named mode "
        "within 10 %; spiral: seeds with the truth within 3σ; TIC: validation record"
    )
    head = "  ".join(f"{m:>13}" for m in MODES)
    print(f"{'aircraft':8} {'turb':>4} {'method':20} {head}  ≤10 %  spiral  {'TIC':>11}   s/id")
    for name in args.aircraft:
        reference = linear_truth(name, AIRCRAFT[name])
        truth = reference.modes()
        for turbulence in args.turbulence:
            rows: dict[str, list] = {}
            sizes: list[float] = []
            for seed in range(FIRST_SEED, FIRST_SEED + args.seeds):
                rec = fly(
                    plan, aircraft=name, speed_kts=AIRCRAFT[name], turbulence=turbulence, seed=seed
                )
                exp = experiment(rec)
                found, model, seconds, spiral = ours(exp, rec.dt, rec, settings)
                check, scales = validation(name, turbulence, seed, model)
                sizes.extend(scales)
                rows.setdefault("validated truth", []).append(
                    ([0.0] * len(MODES), truth_tic(reference, check, rec.dt), np.nan, None)
                )
                z = _spiral_z(spiral, truth)
                rows.setdefault("suas-sysid", []).append(
                    (mode_errors(found, truth), validation_tic(model, check), seconds, z)
                )
                if args.no_peers:
                    continue
                for peer, method in PEERS.items():
                    try:
                        model, seconds = method(exp, rec.dt, rec)
                        eig = np.log(np.linalg.eigvals(model.A).astype(complex)) / rec.dt
                        errs = mode_errors(named_by_truth(eig, truth), truth)
                        tic = validation_tic(model, check)
                    except (IdentificationFailed, DataError, np.linalg.LinAlgError, ValueError):
                        errs, tic, seconds = [np.inf] * len(MODES), 1.0, np.nan
                    rows.setdefault(peer, []).append((errs, tic, seconds, None))
            for method, results in rows.items():
                _print(name, turbulence, method, results)
            print(
                f"{'':8} {'':4} validation doublets: {np.median(sizes):.2f}× the presets' "
                f"amplitudes (median), {np.max(sizes):.2f}× at most",
                flush=True,
            )


def _spiral_z(spiral, truth) -> float | None:
    """The identified spiral's offset from the truth's in its standard errors (inf when none
    was identified or it has no standard error; None when the truth has no spiral)."""
    if not truth.get("spiral"):
        return None
    if spiral is None or spiral.uncertainty is None or spiral.uncertainty.real <= 0:
        return np.inf
    true = truth["spiral"][0].real
    return float((spiral.eigenvalue.real - true) / spiral.uncertainty.real)


def _print(name: str, turbulence: float, method: str, results: list) -> None:
    e = 100 * np.array([r[0] for r in results], dtype=float)
    cells = "  ".join(_pair(np.median(c), np.max(c)) for c in e.T)
    ok = int(np.sum(np.all(e <= 10, axis=1)))
    tics = np.array([r[1] for r in results])
    z = np.array([r[3] for r in results if r[3] is not None])
    spiral_cell = f"{int(np.sum(np.abs(z) <= 3)):2d}/{len(z):<2d}" if z.size else "  –  "
    times = [r[2] for r in results if np.isfinite(r[2])]
    seconds = f"{np.median(times):5.2f}" if times else "    –"
    print(
        f"{name:8} {turbulence:4.1f} {method:20} {cells}  {ok:2d}/{len(e):<2d}  {spiral_cell}  "
        f"{np.median(tics):5.3f}/{np.max(tics):5.3f}  {seconds}",
        flush=True,
    )
    if z.size and np.all(np.isfinite(z)):  # calibrated and unbiased: mean 0, sd and rms 1
        print(
            f"{'':8} {'':4} spiral z (identified − truth, in its σ): mean {np.mean(z):+.2f}, "
            f"sd {np.std(z):.2f}, rms {np.sqrt(np.mean(z * z)):.2f}, worst {np.max(np.abs(z)):.2f}",
            flush=True,
        )


def _pair(median: float, worst: float) -> str:
    def cell(x: float) -> str:
        return "miss" if not np.isfinite(x) else f"{x:.1f}" if x < 100 else f"{x:.0f}"

    return f"{cell(median):>6}/{cell(worst):<6}"


if __name__ == "__main__":
    main()
