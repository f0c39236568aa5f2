"""Where a phugoid's error comes from, on one benchmark aircraft in calm air, without sensor
noise: the truth, the phugoid's own nonlinearity, or the identification.

    .venv/bin/python benchmarks/phugoid_check.py --aircraft c182        # about two minutes

1. JSBSim's own free decay: an elevator doublet at several multiples of the presets'
   amplitude, then 120 s of free flight; a damped sinusoid fitted to the airspeed and the
   pitch attitude after the short period has died out (from 12 s) gives the phugoid's ωn and
   ζ at that amplitude, against the validated truth's (agent.sim.truth). A phugoid whose ζ
   does not move with the amplitude is linear there, and one near the truth's says the truth
   holds it.
2. The identification (as `make bench-jsbsim` runs it, with the INS's navigation) of one
   noise-free record of the full preset as the agent sizes it, of its longitudinal controls
   alone (elevator and throttle), of its elevator alone, and of the whole preset at half its
   amplitudes: the phugoid's ωn and ζ against the truth's. With no noise a difference is the
   method's structure on this aircraft, and the manoeuvres tell which part of the record
   carries it.
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
from bench_jsbsim import AIRCRAFT, Setup, _second_order, calibrate, experiment, ours, setup_for
from scipy.optimize import curve_fit

from agent.excitation.plan import PRESET_AMPLITUDE, Doublet, Plan, Segment, only, preset
from agent.sizing import scaled

FREE_FROM_S = 12.0  # the short period has died out
FREE_S = 120.0
DOUBLET_SCALES = (0.25, 1.0, 3.0)
TRIM = 50  # samples: the trim, as the benchmark's


def _decay(t, a, b, s, w, c, d):
    return np.exp(-s * t) * (a * np.cos(w * t) + b * np.sin(w * t)) + c + d * t


def free_decay(
    setup: Setup, scale: float, wn: float, zeta: float
) -> list[tuple[str, float, float]]:
    """The phugoid's (output, ωn, ζ) from a free decay after an elevator doublet."""
    signal = Doublet(pulse_s=1.0, amplitude=scale * PRESET_AMPLITUDE["elevator"])
    plan = Plan(
        id="decay",
        axes="longitudinal",
        segments=(Segment(signals={"elevator": signal}, free_s=FREE_S),),
    )
    rec = setup.fly(plan, 2, noise=False)
    t = np.arange(len(rec.y)) * rec.dt
    keep = t > FREE_FROM_S
    out = []
    for column, name in ((0, "airspeed"), (3, "theta")):
        y = rec.y[keep, column] - rec.y[:TRIM, column].mean()
        start = [y[0], 0.0, zeta * wn, wn * np.sqrt(1 - zeta**2), 0.0, 0.0]
        p, _ = curve_fit(_decay, t[keep] - t[keep][0], y, p0=start, maxfev=20000)
        found = float(np.hypot(p[2], p[3]))
        out.append((name, found, float(p[2]) / found))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--aircraft", choices=list(AIRCRAFT), default="c182")
    args = parser.parse_args()
    setup = setup_for(args.aircraft, 0.0)
    controls = setup.controls
    phugoid = setup.truth().modes().get("phugoid")
    if not phugoid or _second_order(phugoid) is None:
        parser.error(f"{args.aircraft}: the truth has no phugoid pair")
    wn, zeta = _second_order(phugoid)
    print(f"{args.aircraft}: the validated truth's phugoid ωn {wn:.4f} rad/s, ζ {zeta:.4f}")
    for scale in DOUBLET_SCALES:
        for name, found, damping in free_decay(setup, scale, wn, zeta):
            print(
                f"  free decay, elevator doublet {scale:g}× the preset's, {name:8}: "
                f"ωn {100 * (found / wn - 1):+5.1f} %, ζ {100 * (damping / zeta - 1):+5.1f} %"
            )
    full = calibrate(setup, preset("full", controls=controls))[0].plan
    manoeuvres = {
        "full preset, as sized": full,
        "its elevator and throttle alone": only(
            full, [c for c in ("elevator", "throttle") if c in controls]
        ),
        "its elevator alone": only(full, ["elevator"]),
        "full preset at half its amplitudes": scaled(full, dict.fromkeys(controls, 0.5)),
    }
    for label, plan in manoeuvres.items():
        rec = setup.fly(plan, 2, noise=False)
        _, result, _, _ = ours(experiment(rec, setup), rec.dt, setup)
        found = [m for m in result.modes if m.name == "phugoid"]
        if not found:
            print(f"  identified, {label}: no phugoid")
            continue
        m = found[0]
        print(
            f"  identified, {label}: ωn {100 * (m.frequency / wn - 1):+5.1f} %, "
            f"ζ {100 * (m.damping / zeta - 1):+5.1f} %"
        )


if __name__ == "__main__":
    main()
