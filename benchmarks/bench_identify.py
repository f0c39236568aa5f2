"""Identification accuracy and speed against the peers, side by side in one process.

    make bench                                   # 20 seeds, 0 / 5 / 20 % noise (~10 min)
    .venv/bin/python benchmarks/bench_identify.py --seeds 3    # a quick look
    .venv/bin/python benchmarks/bench_identify.py --seeds 1 --noise 0.05 --scaling --no-peers

The thesis's appendix A.2 lateral model (continuous, zero-order hold at
50 Hz) driven by the thesis's flown excitation — Schroeder multisines with four harmonics per
surface (aileron k = 3, 6, 9, 12; rudder k = 5, 10, 15, 20 of a 20 s period), 30 s — with
white output noise of 0, 5 and 20 % of each output's RMS, one seed per record. Validation is
a separate record (aileron doublet, then rudder doublet, 20 s, same noise level).

Methods, all on the same records:
- suas-sysid default: automatic everything, output-error refinement (what `sysid identify`
  does); the same with refinement off (OKID/ERA after preprocessing); and both again with
  frequency-domain OKID (`--method frequency`).
- textbook OKID: OKID/ERA at the record rate, true order 4, no preprocessing, no truncation,
  no refinement, at the p (from 1…20) with the lowest median error — an oracle choice.
- python-control 0.10: `markov` (m = 100, 2 s of FIR) + `eigensys_realization` (n = 4).
- SIPPY (sippy_unipi 1.0): N4SID, MOESP, PARSIM-K at the true order 4 (f = p = 20).
The peers are the `bench` extra (`pip install -e '.[bench]'`, which `make bench` does);
`--no-peers` leaves them out.

Printed per noise level and method: the relative eigenvalue error of each named mode (Dutch
roll, roll, spiral; median and worst over seeds), the median error divided by the Cramér–Rao
bound (1-σ relative error of that eigenvalue for this input and noise, computed here from the
true model with every Ac, Bc entry and the initial state free), the median validation TIC
next to the noise floor (the true model's TIC on the noisy validation record), and the median
wall time per identification. One BLAS thread for everyone (as onboard, where identification
shares two cores with the flight agent).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse
import importlib.util
import json
import statistics
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from agent.excitation.signals import doublet
from agent.ident import Experiment, Settings, identify, reference
from agent.ident.convert import StateSpace, discretize
from agent.ident.errors import DataError, IdentificationFailed
from agent.ident.fit import estimate_initial_state, simulate, theil
from agent.ident.refine import cramer_rao, eigenvalue_std

DT = 0.02
MODEL = reference.LATERAL
# The names `sysid identify --axes lateral` gives the channels: with them `auto` is the
# aircraft method (`identify`), the default row keeps OKID's.
ROLES = {"input_names": MODEL.inputs, "output_names": MODEL.outputs, "output_roles": MODEL.outputs}
TRUE_MODES = {"Dutch roll": 0, "roll": 1, "spiral": 2}  # index into _true_modes()
TEXTBOOK_P = (1, 2, 3, 4, 6, 8, 10, 15, 20)
PEER_MODULES = {"control": "python-control", "sippy_unipi": "SIPPY"}


def _true_modes() -> np.ndarray:
    lam = np.linalg.eigvals(MODEL.A)
    dutch = lam[np.argmax(lam.imag)]
    real = np.sort(lam[np.abs(lam.imag) < 1e-9].real)
    return np.array([dutch, real[0], real[1]])  # Dutch roll, roll (fast), spiral (slow)


TRUTH = _true_modes()


@dataclass
class Outcome:
    """What one method produced on one record."""

    eigenvalues: np.ndarray  # continuous, 1/s
    model: StateSpace | None  # for validation: continuous, or discrete at DT (see `discrete`)
    seconds: float
    discrete: bool = False  # `model` is discrete at DT (a peer with no continuous equivalent)


def mode_errors(eigs: np.ndarray) -> np.ndarray:
    """Relative error of each true mode against the nearest identified eigenvalue (1-to-1)."""
    found = list(eigs) + [e.conjugate() for e in eigs if abs(e.imag) > 1e-9]
    out = np.full(len(TRUTH), np.inf)
    for k in (0, 1, 2):  # Dutch roll first: it takes its pair
        if not found:
            break
        j = int(np.argmin([abs(f - TRUTH[k]) for f in found]))
        out[k] = abs(found.pop(j) - TRUTH[k]) / abs(TRUTH[k])
    return out


def _peer(A, B, C, D, seconds: float) -> Outcome:
    """A peer's discrete model at DT: eigenvalues s = ln z / Δt; validated as is."""
    z = np.linalg.eigvals(A).astype(complex)
    return Outcome(np.log(z) / DT, StateSpace(A, B, C, D), seconds, discrete=True)


def run_ours(settings: Settings, **names) -> Callable[[Experiment], Outcome]:
    """suas-sysid with `settings`; `names`: the channels' names and roles, when given."""

    def method(exp: Experiment) -> Outcome:
        t0 = time.perf_counter()
        result = identify(exp, DT, settings=settings, **names)
        seconds = time.perf_counter() - t0
        eigs = np.array([m.eigenvalue for m in result.modes])
        return Outcome(eigs, result.continuous, seconds)

    return method


def missing_peers() -> list[str]:
    """The peers' libraries that are not installed (the `bench` extra)."""
    return [name for module, name in PEER_MODULES.items() if not importlib.util.find_spec(module)]


def run_python_control(exp: Experiment) -> Outcome:
    import control

    t0 = time.perf_counter()
    H = control.markov(exp.y.T, exp.u.T, m=100, dt=True)
    sys_, _ = control.eigensys_realization(H, 4, dt=True)
    seconds = time.perf_counter() - t0
    return _peer(sys_.A, sys_.B, sys_.C, sys_.D, seconds)


def run_sippy(method_name: str) -> Callable[[Experiment], Outcome]:
    def method(exp: Experiment) -> Outcome:
        import sippy_unipi

        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sys_ = sippy_unipi.system_identification(
                exp.y.T, exp.u.T, method_name, SS_fixed_order=4, SS_f=20, SS_p=20, tsample=DT
            )
        seconds = time.perf_counter() - t0
        return _peer(sys_.A, sys_.B, sys_.C, sys_.D, seconds)

    return method


def validation_tic(outcome: Outcome, val: Experiment) -> float:
    """Average TIC of the model simulated on the validation record (x0 fitted)."""
    model = outcome.model
    if model is None:
        return float("nan")
    if outcome.discrete:
        disc = model
    else:
        A, B = discretize(model.A, model.B, DT)
        disc = StateSpace(A, B, model.C, model.D)
    with np.errstate(all="ignore"):
        x0 = estimate_initial_state(disc, val.u, val.y)
        predicted = simulate(disc, val.u, x0)
        if not np.all(np.isfinite(predicted)):
            return 1.0
        return float(np.mean(theil(predicted, val.y)))


def records(noise: float, seed: int) -> tuple[Experiment, Experiment]:
    u = reference.thesis_multisine(MODEL, DT)
    y = reference.simulate(MODEL, u, DT)
    train = Experiment(u, reference.with_output_noise(y, noise, seed))
    ail = doublet(DT, 1.0, reference.AMPLITUDE["aileron"], lead=1.0, tail=8.0)
    rud = doublet(DT, 1.0, reference.AMPLITUDE["rudder"], lead=0.0, tail=8.0)
    uv = np.zeros((ail.size + rud.size, 2))
    uv[: ail.size, 0] = ail
    uv[ail.size :, 1] = rud
    yv = reference.simulate(MODEL, uv, DT)
    # Validation noise: the same fraction of the training record's output RMS (same sensors).
    scale = noise * np.sqrt(np.mean(y**2, axis=0))
    rng = np.random.default_rng(10_000 + seed)
    return train, Experiment(uv, yv + rng.normal(size=yv.shape) * scale)


def crb_relative(noise: float) -> np.ndarray:
    """1-σ relative Cramér–Rao bound of each true mode's eigenvalue (inf when noise = 0)."""
    if noise == 0:
        return np.zeros(3)
    u = reference.thesis_multisine(MODEL, DT)
    y = reference.simulate(MODEL, u, DT)
    sigma = noise * np.sqrt(np.mean(y**2, axis=0))
    truth = StateSpace(MODEL.A, MODEL.B, np.eye(4), np.zeros((4, 2)))
    cov = cramer_rao(truth, DT, [Experiment(u, y)], sigma)
    n = MODEL.A.shape[0]
    stds = eigenvalue_std(MODEL.A, cov[: n * n, : n * n])
    lam = np.linalg.eigvals(MODEL.A)
    out = []
    for t in TRUTH:
        k = int(np.argmin(np.abs(lam - t)))
        out.append(np.hypot(stds[k].real, stds[k].imag) / abs(t))
    return np.array(out)


def textbook_okid(train: list[Experiment]) -> tuple[int, list[Outcome]]:
    """OKID/ERA at the record rate, order 4, at the p with the lowest median worst error."""
    best = None
    for p in TEXTBOOK_P:
        settings = Settings(markov=p, order=4, decimation=1, refine=False)
        outcomes = []
        for exp in train:
            try:
                outcomes.append(run_ours(settings)(exp))
            except (IdentificationFailed, DataError):  # a p that fails counts as a miss
                outcomes.append(Outcome(np.array([]), None, float("nan")))
        score = statistics.median(mode_errors(o.eigenvalues).max() for o in outcomes)
        if best is None or score < best[0]:
            best = (score, p, outcomes)
    return best[1], best[2]


def fmt_pct(x: float) -> str:
    if not np.isfinite(x):
        return "miss"
    return f"{100 * x:.2f}" if x < 10 else f"{100 * x:.0f}"


def scaling(durations: list[float]) -> list[dict]:
    """Time per identification against record length: A.4 (8 outputs, 4 inputs), 100 Hz."""
    model, dt = reference.FULL, 0.01
    rows = []
    for seconds in durations:
        u = reference.multisine_inputs(model.inputs, dt, seconds, 1, (0.05, 1.5))
        y = reference.with_output_noise(reference.simulate(model, u, dt), 0.05, 1)
        exp = Experiment(u, y)
        row = []
        for settings in (Settings(refine=False), Settings()):
            identify(exp, dt, settings=settings)  # warm
            times = []
            for _ in range(3):
                t0 = time.perf_counter()
                result = identify(exp, dt, settings=settings)
                times.append(time.perf_counter() - t0)
            row.append(1e3 * statistics.median(times))
        rows.append(
            {
                "seconds": seconds,
                "samples": u.shape[0],
                "no_refinement_ms": row[0],
                "default_ms": row[1],
                "decimation": result.preprocessing.factor,
            }
        )
    return rows


def methods(peers: bool) -> list[tuple[str, Callable[[Experiment], Outcome]]]:
    ours = [
        ("suas-sysid default (OKID/ERA + output error)", run_ours(Settings())),
        ("suas-sysid OKID/ERA, no refinement", run_ours(Settings(refine=False))),
        ("suas-sysid frequency OKID + output error", run_ours(Settings(method="frequency"))),
        (
            "suas-sysid frequency OKID, no refinement",
            run_ours(Settings(method="frequency", refine=False)),
        ),
        (
            "suas-sysid aircraft (channels named by role)",
            run_ours(Settings(method="aircraft"), **ROLES),
        ),
    ]
    if not peers:
        return ours
    return [
        *ours,
        ("python-control markov+ERA", run_python_control),
        ("SIPPY N4SID", run_sippy("N4SID")),
        ("SIPPY MOESP", run_sippy("MOESP")),
        ("SIPPY PARSIM-K", run_sippy("PARSIM-K")),
    ]


def noise_level(noise: float, seeds: int, peers: bool) -> dict:
    """Every method on `seeds` records at one noise level: errors, TIC and time per method."""
    bound = crb_relative(noise)
    data = [records(noise, seed) for seed in range(seeds)]
    train, val = [d[0] for d in data], [d[1] for d in data]
    true_model = StateSpace(MODEL.A, MODEL.B, np.eye(4), np.zeros((4, 2)))
    floor = statistics.median(validation_tic(Outcome(TRUTH, true_model, 0.0), v) for v in val)
    rows = [(name, [method(exp) for exp in train]) for name, method in methods(peers)]
    p, textbook = textbook_okid(train)
    rows.append((f"textbook OKID/ERA (oracle p = {p}, n = 4)", textbook))
    out = []
    for name, outcomes in rows:
        errors = np.array([mode_errors(o.eigenvalues) for o in outcomes])
        pairs = zip(outcomes, val, strict=True)
        out.append(
            {
                "method": name,
                "median": np.median(errors, axis=0).tolist(),
                "worst": errors.max(axis=0).tolist(),
                "worst_mode": float(np.median(errors.max(axis=1))),
                "tic": statistics.median(validation_tic(o, v) for o, v in pairs),
                "ms": 1e3 * statistics.median(o.seconds for o in outcomes),
            }
        )
    return {"noise": noise, "crb": bound.tolist(), "tic_floor": floor, "rows": out}


def print_level(level: dict) -> None:
    noise, bound = level["noise"], level["crb"]
    print()
    print(
        f"noise {100 * noise:.0f} %: Cramér–Rao 1-σ Dutch roll {100 * bound[0]:.2f} %, "
        f"roll {100 * bound[1]:.2f} %, spiral {100 * bound[2]:.2f} %; "
        f"validation TIC noise floor {level['tic_floor']:.3f}"
    )
    print(
        f"{'method':<46}{'Dutch roll':>13}{'roll':>13}{'spiral':>13}{'worst':>10}"
        f"{'×CRB DR/roll/spiral':>22}{'val TIC':>9}{'ms':>8}"
    )
    for row in level["rows"]:
        med, worst = row["median"], row["worst"]
        cells = "".join(f"{' ' + fmt_pct(med[k]) + '/' + fmt_pct(worst[k]):>13}" for k in (0, 1, 2))
        ratio = "/".join(f"{med[k] / bound[k]:.1f}" for k in (0, 1, 2)) if noise > 0 else "—"
        print(
            f"{row['method']:<46}{cells}{fmt_pct(row['worst_mode']):>10}{ratio:>22}"
            f"{row['tic']:>9.3f}{row['ms']:>8.1f}"
        )


def print_scaling(rows: list[dict]) -> None:
    print()
    print("record length scaling: A.4 full model (4 inputs, 8 outputs), 100 Hz, 5 % noise")
    print(
        f"{'seconds':>8}{'samples':>9}{'no refinement ms':>18}{'default ms':>12}{'decimation':>12}"
    )
    for r in rows:
        print(
            f"{r['seconds']:>8.0f}{r['samples']:>9}{r['no_refinement_ms']:>18.1f}"
            f"{r['default_ms']:>12.1f}{r['decimation']:>12}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.splitlines()[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--noise", type=float, nargs="+", default=[0.0, 0.05, 0.2])
    parser.add_argument(
        "--scaling",
        type=float,
        nargs="*",
        default=[30.0, 60.0, 150.0, 300.0],
        help="record lengths (s) for the time-versus-length table; none to skip",
    )
    parser.add_argument("--no-peers", action="store_true", help="suas-sysid's methods only")
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout")
    args = parser.parse_args()
    missing = [] if args.no_peers else missing_peers()
    if missing:
        parser.error(
            f"{' and '.join(missing)} not installed: pip install -e '.[bench]' (make bench "
            "does), or --no-peers"
        )
    # Warm up every method once (imports, caches) before timing.
    warm, _ = records(0.05, 999)
    for _, method in methods(not args.no_peers):
        method(warm)
    if not args.json:
        print(
            f"A.2 lateral, thesis multisine (30 s, 50 Hz), {args.seeds} seeds; eigenvalue error "
            "in % (median/worst over seeds; 'worst' = median over seeds of the worst mode), "
            "×CRB = median error / Cramér–Rao 1-σ"
        )
    levels = []
    for noise in args.noise:
        levels.append(noise_level(noise, args.seeds, not args.no_peers))
        if not args.json:
            print_level(levels[-1])
    rows = scaling(args.scaling) if args.scaling else []
    if args.json:
        print(json.dumps({"seeds": args.seeds, "levels": levels, "scaling": rows}))
    elif rows:
        print_scaling(rows)


if __name__ == "__main__":
    main()
