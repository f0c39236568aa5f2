"""The truth check for each benchmark aircraft, JSBSim's `FGLinearization` beside ours.

    .venv/bin/python benchmarks/truth_check.py                  # about two minutes
    .venv/bin/python benchmarks/truth_check.py --aircraft J3Cub   # one aircraft
    .venv/bin/python benchmarks/truth_check.py --amplitudes 2 4    # the truth at 2× and 4×

For a doublet on each surface and a throttle step, each flown as a ± pair (the odd part of
JSBSim's response), it prints the worst TIC over the outputs the test moves (agent.sim.truth
says which count). FGLinearization's model is driven by the commands, which its B is for;
ours by the surface and throttle positions. Both are held to TIC ≤ 0.05; a test on which ours
is over that bound is marked, and the command then exits with code 1. The aircraft are
`make bench-jsbsim`'s (bench_jsbsim.AIRCRAFT); FGLinearization has nothing for a glider
(JSBSim's crashes on an aircraft without engines: "–").

With `--amplitudes`, it prints instead how each named mode of the truth moves when its
multisine is flown at those multiples of its amplitude: the best linear approximation of a
nonlinear aircraft is one per amplitude, so an identification at the flown amplitude can be
right and still differ from the truth by that much. Where that exceeds a standard error the
method reports, the benchmark's z-scores against the truth measure the aircraft's
nonlinearity, not the standard error.
"""

from __future__ import annotations

import argparse
import os
import sys

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
import scipy.linalg
from bench_jsbsim import AIRCRAFT

from agent.sim import truth as T  # noqa: N812 — T for truth, as in the docs
from agent.sim.plant import FT, INPUTS, LINEAR_INPUTS, LINEAR_STATES, Plant

BENCHMARK = [(name, f.speed_kts, f.altitude_ft) for name, f in AIRCRAFT.items()]


def fg_worst(aircraft: str, speed: float, altitude: float, ours: list[T.Check]) -> dict:
    """FGLinearization's worst TIC per test, over the outputs our check counted (NaN: it has
    no linearisation of this aircraft)."""
    lin = Plant(aircraft, airspeed_kts=speed, altitude_ft=altitude).linearisation
    if lin is None:
        return {name: float("nan") for name in INPUTS}
    names = list(lin.state_names)
    B = lin.B[:, [lin.input_names.index(LINEAR_INPUTS[i]) for i in INPUTS]]
    rate = 200.0
    block = np.zeros((len(names) + len(INPUTS),) * 2)
    block[: len(names), : len(names)], block[: len(names), len(names) :] = lin.A, B
    phi = scipy.linalg.expm(block / rate)
    Ad, Bd = phi[: len(names), : len(names)], phi[: len(names), len(names) :]
    worst = {}
    for name, check in zip(INPUTS, ours, strict=True):
        commands = T.check_commands(name, rate)
        x, _, _ = T.odd_response(aircraft, speed, commands, altitude_ft=altitude)
        state = np.zeros(len(names))
        predicted = np.empty((len(commands), len(T.OUTPUTS)))
        for k, row in enumerate(commands):
            state = Ad @ state + Bd @ row
            predicted[k] = [state[names.index(LINEAR_STATES[o])] for o in T.OUTPUTS]
        predicted[:, 0] *= FT  # Vt: ft/s → m/s, as the truth's states
        tic = T.theil(x[:, :8], predicted)
        worst[name] = max(tic[T.OUTPUTS.index(o)] for o in check.counted)
    return worst


def amplitude_sensitivity(
    aircraft: str, speed: float, altitude: float, factors: list[float]
) -> None:
    """Each named mode's ωn and ζ at each factor × the truth's amplitude, as changes in % of
    the truth's own."""
    base = T.linear_truth(aircraft, speed, altitude_ft=altitude).modes()
    for factor in factors:
        try:
            truth = T.linear_truth(
                aircraft, speed, amplitude=factor * T.AMPLITUDE, altitude_ft=altitude
            )
        except np.linalg.LinAlgError as error:  # the aircraft left its trim in the run
            print(f"{aircraft:<8} ×{factor:g}: no truth ({error})", flush=True)
            continue
        cells = []
        for name, poles in truth.modes().items():
            if not poles or not base.get(name):
                continue
            (wn, zeta), (wn0, zeta0) = (_wn_zeta(poles), _wn_zeta(base[name]))
            cells.append(
                f"{name} ωn {100 * (wn / wn0 - 1):+.2f} %, ζ {100 * (zeta / zeta0 - 1):+.2f} %"
            )
        print(f"{aircraft:<8} ×{factor:g}: " + "; ".join(cells), flush=True)


def _wn_zeta(poles: list[complex]) -> tuple[float, float]:
    """ωn and ζ of a mode: of its pair, of its two real poles' polynomial, or of one real pole
    (ζ 1)."""
    if len(poles) == 2:
        wn = float(np.sqrt(abs(poles[0] * poles[1])))
        return wn, float(-(poles[0] + poles[1]).real / (2 * wn))
    pole = complex(poles[0])
    return abs(pole), (-pole.real / abs(pole) if pole.imag else 1.0)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    names = [name for name, _, _ in BENCHMARK]
    parser.add_argument(
        "--aircraft", nargs="+", choices=names, default=names, help="which aircraft to check"
    )
    parser.add_argument(
        "--amplitudes",
        nargs="+",
        type=float,
        metavar="K",
        help="the truth's modes at K times its multisine's amplitude, against its own",
    )
    args = parser.parse_args()
    if args.amplitudes:
        for aircraft, speed, altitude in BENCHMARK:
            if aircraft in args.aircraft:
                amplitude_sensitivity(aircraft, speed, altitude, args.amplitudes)
        return
    print(f"worst TIC over the outputs each test moves (bound {T.CHECK_TIC})")
    print(f"{'aircraft':<8}{'test':<10}{'FGLinearization':>17}{'agent.sim.truth':>17}")
    over = []
    for aircraft, speed, altitude in BENCHMARK:
        if aircraft not in args.aircraft:
            continue
        truth = T.linear_truth(aircraft, speed, altitude_ft=altitude)
        ours = T.check(truth)
        theirs = fg_worst(aircraft, speed, altitude, ours)
        for check in ours:
            mark = " over the bound" if check.worst > T.CHECK_TIC else ""
            print(
                f"{aircraft:<8}{check.test:<10}{theirs[check.test]:>17.3f}{check.worst:>17.3f}"
                f"{mark}",
                flush=True,
            )
            if mark:
                over.append(f"{aircraft} {check.test}")
        modes = ", ".join(f"{k} {v[0]:.3f}" for k, v in truth.modes().items() if v)
        print(f"  truth modes: {modes}")
    if over:
        sys.exit(f"truth_check: agent.sim.truth over TIC {T.CHECK_TIC} on {', '.join(over)}")


if __name__ == "__main__":
    main()
