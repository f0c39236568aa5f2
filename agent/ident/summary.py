"""An identification as a text table (`sysid identify` without --json): the settings and what
the method found, the modes with their indicators, the fit, the expected modes not identified
and the poles left out of the modes."""

from __future__ import annotations

import numpy as np

from agent.ident.modal import Mode
from agent.ident.result import Identification


def _fmt_eig(mode: Mode) -> str:
    s = mode.eigenvalue
    return f"{s.real:9.4f} ± {s.imag:.4f}j" if mode.pair else f"{s.real:9.4f}"


def _fmt_std(mode: Mode) -> str:
    u = mode.uncertainty
    return "" if u is None else f"   {u.frequency:9.4f} {u.damping:9.4f}"


def _pct(value: float | None) -> str:
    return "   —" if value is None else f"{value:4.0f}"


# The mode table's indicators: (heading, width, Mode attribute); ERA_ONLY are shown only where
# a mode has them.
INDICATORS = (
    ("MSV", 6, "msv"),
    ("MCI", 5, "mci"),
    ("MOI", 5, "moi"),
    ("EMAC", 6, "emac"),
    ("MPC", 5, "mpc"),
    ("CMI", 5, "cmi"),
)
ERA_ONLY = ("emac", "cmi")


def format_text(result: Identification, records: int, samples: int) -> str:
    """A readable report: data and settings, what the method found, mode table, fit."""
    prep = result.preprocessing
    lines = [
        f"{len(result.input_names)} inputs ({', '.join(result.input_names)}) → "
        f"{len(result.output_names)} outputs ({', '.join(result.output_names)}); "
        f"{records} record(s), {samples} samples at {1 / prep.record_dt:.4g} Hz, analysed at "
        f"{1 / result.dt:.4g} Hz (decimation {prep.factor}, band {prep.band_hz:.3g} Hz)",
        *_method_lines(result),
        "",
    ]
    # ERA's indicators (EMAC, CMI) only where the method has them: the whole-aircraft method
    # has no Hankel realisation to measure them in, and a column of dashes says nothing.
    shown = [
        (label, width, key)
        for label, width, key in INDICATORS
        if key not in ERA_ONLY or any(getattr(m, key) is not None for m in result.modes)
    ]
    lines.append(
        f"{'mode':<13}{'eigenvalue 1/s':<24}{'ωn rad/s':>9}{'ζ':>7}{'τ s':>8}"
        + "".join(f"{label:>{width}}" for label, width, _ in shown)
        + ("   1-σ ωn      1-σ ζ" if result.refinement is not None else "")
    )
    for mode in result.modes:
        tau = "" if mode.time_constant is None else f"{mode.time_constant:8.3f}"
        lines.append(
            f"{mode.name or '—':<13}{_fmt_eig(mode):<24}{mode.frequency:9.3f}{mode.damping:7.3f}"
            f"{tau:>8}"
            + "".join(f"{_pct(getattr(mode, key)):>{width}}" for _, width, key in shown)
            + _fmt_std(mode)
        )
    lines += [
        f"{o.name} as one mode (its two real poles): ωn {o.frequency:.4g} rad/s"
        + ("" if o.frequency_std is None else f" (1-σ {o.frequency_std:.2g})")
        + f", ζ {o.damping:.3f}"
        + ("" if o.damping_std is None else f" (1-σ {o.damping_std:.2g})")
        for o in result.second_order()
    ]
    tic = "  ".join(
        f"{n} {v:.3f}" for n, v in zip(result.output_names, result.fit.tic, strict=True)
    )
    lines += [
        "",
        f"TIC: {tic}  (average {result.fit.tic_avg:.3f}; below 0.3 is a decent fit)",
        f"Stable: {'yes' if result.stable else 'no'}",
    ]
    lines += [f"not identified: {name}: {why}" for name, why in result.missing]
    lines += [f"left out: {why}" for why in result.left_out]
    lines += [f"warning: {w}" for w in result.warnings]
    return "\n".join(lines)


def _method_lines(result: Identification) -> list[str]:
    """What the method has to say: OKID/ERA's p, order and Hankel singular values, or the
    whole-aircraft method's structure, band, engine lags and wind."""
    ref = result.refinement
    refined = (
        f"refined by {'output' if ref.gain is None else 'prediction'} error ({ref.hold} hold"
        if ref is not None
        else "not refined"
    )
    okid, aircraft = result.okid, result.aircraft
    if okid is not None:
        return [
            f"OKID/ERA ({result.method} domain): Markov parameters p = {okid.markov}"
            + (" (automatic)" if okid.markov_choice is not None else "")
            + f"; order n = {result.order}; model in {result.coordinates} coordinates; "
            + (f"{refined}; OKID/ERA TIC {okid.fit.tic_avg:.3f})" if ref is not None else refined),
            "Hankel singular values: "
            + " ".join(f"{v:.3g}" for v in okid.era.singular_values[: result.order + 3]),
        ]
    if aircraft is None:
        return [f"order n = {result.order}; {refined}" + (")" if ref is not None else "")]
    lags = "; ".join(
        f"{axis}: " + ", ".join(f"{name} {tau:.2f} s" for name, tau in by_input.items())
        for axis, by_input in aircraft.engine_lag_s.items()
    )
    engines = "; ".join(_engine(e) for e in aircraft.engine)
    wind = aircraft.wind
    gusts = ", ".join(f"{name} {rms:.3g}" for name, rms in wind.gust_rms.items())
    filtered = [a for a in aircraft.axes if a.estimator == "filter error"]
    predicted = [a for a in aircraft.axes if a.estimator == "prediction error"]
    estimators = "; ".join(
        [
            f"{a.name} by filter error (process noise's share of the residual: "
            + ", ".join(f"{k} {v:.2f}" for k, v in a.process_share.items())
            + ")"
            for a in filtered
        ]
        + [
            f"{a.name} refined by prediction error in the time domain (coloured process noise "
            "on "
            + ", ".join(f"{k}'s equation, pole {v:.2g} 1/s" for k, v in a.process_poles.items())
            + ")"
            for a in predicted
        ]
    )
    return [
        f"whole-aircraft method: {aircraft.model}; order n = {result.order} (the outputs"
        + (" and the engine's lag states" if result.order > len(result.output_names) else "")
        + f"); frequency-domain output error on {aircraft.bins} bins, "
        f"{aircraft.band_hz[0]:.3g}–{aircraft.band_hz[1]:.3g} Hz",
        *([estimators] if estimators else []),
        "axes: "
        + "; ".join(f"{a.name} ← {', '.join(a.inputs)}" for a in aircraft.axes)
        + (f"; engine lags {lags}" if lags and not engines else ""),
        *([f"engine: {engines}"] if engines else []),
        ("kinematics known; " if aircraft.kinematics else "kinematics not known (no trim); ")
        + (f"wind measured (gust rms {gusts})" if wind.measured else "wind not measured")
        + (
            f"; {', '.join(wind.undetected)} gust within the sensors' noise (left out)"
            if wind.undetected
            else ""
        )
        + _air_angles(wind),
    ]


def _air_angles(wind) -> str:
    """How α and β were had: "" for the vanes, else the synthesis's wind per record."""
    if wind.air_angles != "synthesised":
        return ""
    winds = ", ".join(
        f"{np.hypot(*a.wind_mps):.1f} m/s from "
        f"{(np.degrees(np.arctan2(a.wind_mps[1], a.wind_mps[0])) + 180.0) % 360.0:.0f}°"
        for a in wind.synthesised
    )
    return (
        f"; alpha, beta synthesised without vanes (INS less an estimated wind: {winds}), "
        "their gusts not measured"
    )


def _engine(engine) -> str:
    """One engine input in words: "throttle through 1 lag of 0.42 s (lags 0/1/2: AIC +812, 0,
    +1.3)" or "rpm measured, at once"."""
    if engine.measured:
        return f"{engine.input} measured, at once"
    how = (
        f"through {engine.lags} lag{'s' * (engine.lags > 1)} of {engine.time_constant_s:.2f} s"
        if engine.lags and engine.time_constant_s is not None
        else "at once"
    )
    if not engine.criterion:
        return f"{engine.input} {how}"
    tried = sorted(engine.criterion)
    aic = ", ".join(f"{engine.criterion[k]:+.3g}" if engine.criterion[k] else "0" for k in tried)
    return f"{engine.input} {how} (lags {'/'.join(map(str, tried))}: AIC {aic})"
