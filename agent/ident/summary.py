"""An identification as plain data (the `sysid identify --json` contract) and as a text table."""

from __future__ import annotations

from typing import Any

import numpy as np

from agent.ident.modal import Mode
from agent.ident.pipeline import Identification


def _rows(matrix: np.ndarray) -> list[list[float]]:
    return [[float(v) for v in row] for row in np.asarray(matrix)]


def _num(value: float | None) -> float | None:
    return None if value is None else float(value)


def mode_to_dict(mode: Mode) -> dict[str, Any]:
    """One mode with the keys of the JSON contract."""
    return {
        "name": mode.name,
        "eigenvalue": [float(mode.eigenvalue.real), float(mode.eigenvalue.imag)],
        "frequency_rad_s": float(mode.frequency),
        "damping": float(mode.damping),
        "time_constant_s": _num(mode.time_constant),
        "msv": float(mode.msv),
        "mci": float(mode.mci),
        "moi": float(mode.moi),
        "emac": _num(mode.emac),
        "mpc": float(mode.mpc),
        "cmi": _num(mode.cmi),
        # Cramér–Rao 1-σ after output-error refinement (None without refinement).
        "eigenvalue_std": None
        if mode.uncertainty is None
        else [mode.uncertainty.real, mode.uncertainty.imag],
        "frequency_std_rad_s": None if mode.uncertainty is None else mode.uncertainty.frequency,
        "damping_std": None if mode.uncertainty is None else mode.uncertainty.damping,
    }


def to_dict(result: Identification, trim: list[dict[str, float]] | None = None) -> dict[str, Any]:
    """The `sysid identify --json` object: contract keys first, then extras."""
    model = result.discrete
    cont = result.continuous
    out_coords = result.coordinates == "outputs"
    return {
        "dt": float(result.dt),
        "order": int(result.order),
        "markov": int(result.markov),
        "inputs": list(result.input_names),
        "outputs": list(result.output_names),
        "A": _rows(model.A),
        "B": _rows(model.B),
        "C": _rows(model.C),
        "D": _rows(model.D),
        "Ac": _rows(cont.A) if cont is not None and out_coords else None,
        "Bc": _rows(cont.B) if cont is not None and out_coords else None,
        "singular_values": [float(v) for v in result.singular_values],
        "stable": bool(result.stable),
        "tic": {n: float(v) for n, v in zip(result.output_names, result.fit.tic, strict=True)},
        "tic_avg": float(result.fit.tic_avg),
        "modes": [mode_to_dict(m) for m in result.modes],
        # Extras beyond the contract.
        "coordinates": result.coordinates,
        "continuous": None
        if cont is None
        else {"A": _rows(cont.A), "B": _rows(cont.B), "C": _rows(cont.C), "D": _rows(cont.D)},
        "markov_auto": None
        if result.markov_choice is None
        else [{"markov": p, "order": n, "tic_avg": t} for p, n, t in result.markov_choice.tried],
        "trim": trim or [],
        "preprocessing": _preprocessing(result),
        "method": result.method,
        "aircraft": result.aircraft,
        "frequency": _frequency(result),
        "refinement": _refinement(result),
        "warnings": list(result.warnings),
    }


def _preprocessing(result: Identification) -> dict[str, Any]:
    prep = result.preprocessing
    return {
        "record_dt": prep.record_dt,
        "decimation": prep.factor,
        "band_hz": prep.band_hz,
        "held_inputs_shifted": prep.held_inputs,
        "smoothing_s": prep.smoothing_s,
        "dropped_samples_per_end": prep.dropped_samples,
    }


def _frequency(result: Identification) -> dict[str, Any] | None:
    data = result.frequency_data
    if data is None:
        return None
    spectra = data.spectra
    return {
        "periodic": spectra.periodic,
        "segment_s": spectra.segment_length * result.dt,
        "segments": spectra.segments,
        "leakage": spectra.leakage,
        "markov_from": "inverse FFT" if data.frf.broadband else "observer fit to the FRF",
    }


def _refinement(result: Identification) -> dict[str, Any] | None:
    ref = result.refinement
    if ref is None:
        return None
    std = ref.matrix_std()
    out_coords = result.coordinates == "outputs"
    return {
        "criterion": "output error" if ref.gain is None else "prediction error (innovation form)",
        "hold": ref.hold,
        "iterations": ref.iterations,
        "converged": ref.converged,
        "noise_std": {n: float(v) for n, v in zip(result.output_names, ref.noise_std, strict=True)},
        "okid_tic_avg": float(result.okid_fit.tic_avg),
        "Ac_std": _rows(std.A) if out_coords else None,
        "Bc_std": _rows(std.B) if out_coords else None,
    }


def _fmt_eig(mode: Mode) -> str:
    s = mode.eigenvalue
    return f"{s.real:9.4f} ± {s.imag:.4f}j" if mode.pair else f"{s.real:9.4f}"


def _fmt_std(mode: Mode) -> str:
    u = mode.uncertainty
    return "" if u is None else f"   {u.frequency:9.4f} {u.damping:9.4f}"


def _pct(value: float | None) -> str:
    return "   —" if value is None else f"{value:4.0f}"


def format_text(result: Identification, records: int, samples: int) -> str:
    """A readable report: settings, Hankel singular values, mode table, fit."""
    lines = [
        f"{len(result.input_names)} inputs ({', '.join(result.input_names)}) → "
        f"{len(result.output_names)} outputs ({', '.join(result.output_names)}); "
        f"{records} record(s), {samples} samples at "
        f"{1 / result.preprocessing.record_dt:.4g} Hz, analysed at {1 / result.dt:.4g} Hz"
        f" (decimation {result.preprocessing.factor}, band {result.preprocessing.band_hz:.3g} Hz)",
        f"Markov parameters p = {result.markov}"
        + (" (automatic)" if result.markov_choice is not None else "")
        + f"; order n = {result.order}; model in {result.coordinates} coordinates; "
        + (
            f"refined by {'output' if result.refinement.gain is None else 'prediction'} error "
            f"({result.refinement.hold} hold; "
            f"OKID/ERA TIC {result.okid_fit.tic_avg:.3f})"
            if result.refinement is not None
            else "not refined"
        ),
        "Hankel singular values: "
        + " ".join(f"{v:.3g}" for v in result.singular_values[: result.order + 3]),
        "",
        f"{'mode':<13}{'eigenvalue 1/s':<24}{'ωn rad/s':>9}{'ζ':>7}{'τ s':>8}"
        f"{'MSV':>6}{'MCI':>5}{'MOI':>5}{'EMAC':>6}{'MPC':>5}{'CMI':>5}"
        + ("   1-σ ωn      1-σ ζ" if result.refinement is not None else ""),
    ]
    for mode in result.modes:
        tau = "" if mode.time_constant is None else f"{mode.time_constant:8.3f}"
        lines.append(
            f"{mode.name or '—':<13}{_fmt_eig(mode):<24}{mode.frequency:9.3f}{mode.damping:7.3f}"
            f"{tau:>8}{_pct(mode.msv):>6}{_pct(mode.mci):>5}{_pct(mode.moi):>5}"
            f"{_pct(mode.emac):>6}{_pct(mode.mpc):>5}{_pct(mode.cmi):>5}" + _fmt_std(mode)
        )
    tic = "  ".join(
        f"{n} {v:.3f}" for n, v in zip(result.output_names, result.fit.tic, strict=True)
    )
    lines += [
        "",
        f"TIC: {tic}  (average {result.fit.tic_avg:.3f}; below 0.3 is a decent fit)",
        f"Stable: {'yes' if result.stable else 'no'}",
    ]
    lines += [f"warning: {w}" for w in result.warnings]
    return "\n".join(lines)
