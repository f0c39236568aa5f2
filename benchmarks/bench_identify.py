"""Our OKID/ERA against python-control's `markov` + `eigensys_realization`, in one process.

    make bench            # or: .venv/bin/python benchmarks/bench_identify.py [--repeat N]

Both identify the thesis's A.2 lateral model (50 Hz, 1 s trim, 30 s of orthogonal multisines)
from the same records: noise-free, and with the thesis's sensor noise levels (VN-200 attitude
0.05°, rates 0.02 °/s, µADC β 0.2°). python-control estimates Markov parameters as a finite
impulse response (it assumes C A^k B = 0 beyond m), so it is given m = 100 (2 s) and the true
order 4; ours runs with its automatic choices, and again with p = 2, n = 4. Printed: the worst
relative eigenvalue error over the four true eigenvalues, the median wall time, and our time
relative to python-control's.
"""

from __future__ import annotations

import argparse
import statistics
import time

import control
import numpy as np

from agent.ident import Experiment, Settings, identify, reference

DT = 0.02
DEG = np.pi / 180
NOISE = {"beta": 0.2 * DEG, "p": 0.02 * DEG, "r": 0.02 * DEG, "phi": 0.05 * DEG}
MODEL = reference.LATERAL


def worst_error(continuous_eigs: np.ndarray) -> float:
    truth = np.linalg.eigvals(MODEL.A)
    found = list(continuous_eigs)
    worst = 0.0
    for t in sorted(truth, key=abs):
        k = int(np.argmin([abs(f - t) for f in found]))
        worst = max(worst, abs(found.pop(k) - t) / abs(t))
    return worst


def ours(exp: Experiment, settings: Settings) -> np.ndarray:
    result = identify(exp, DT, settings=settings)
    z = np.linalg.eigvals(result.discrete.A).astype(complex)
    return np.log(z) / DT


def python_control(exp: Experiment) -> np.ndarray:
    H = control.markov(exp.y.T, exp.u.T, m=100, dt=True)
    sys_, _ = control.eigensys_realization(H, 4, dt=True)
    z = np.linalg.eigvals(sys_.A).astype(complex)
    return np.log(z) / DT


def timed(fn, repeat: int):
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return out, statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    print(f"{'record':<14}{'method':<34}{'worst eig err':>14}{'time ms':>10}{'ratio':>8}")
    for label, noise in (("noise-free", None), ("sensor noise", NOISE)):
        record = reference.make_record(MODEL, noise=noise)
        n0 = round(0.5 / DT)
        exp = Experiment(
            u=record.inputs - record.inputs[:n0].mean(axis=0),
            y=record.outputs - record.outputs[:n0].mean(axis=0),
        )
        peer_eigs, peer_t = timed(lambda e=exp: python_control(e), args.repeat)
        rows = [
            ("python-control markov(m=100)+ERA(n=4)", peer_eigs, peer_t),
            ("suas-sysid automatic p, n", *timed(lambda e=exp: ours(e, Settings()), args.repeat)),
            (
                "suas-sysid p=2, n=4",
                *timed(lambda e=exp: ours(e, Settings(markov=2, order=4)), args.repeat),
            ),
        ]
        for method, eigs, seconds in rows:
            print(
                f"{label:<14}{method:<34}{worst_error(eigs):>14.3e}"
                f"{1e3 * seconds:>10.1f}{seconds / peer_t:>8.2f}"
            )


if __name__ == "__main__":
    main()
