"""One identification: experiments in, model, modes, quality indicators and fit out.

Preprocessing (band of interest, anti-alias decimation, optional smoothing) → OKID (observer
Markov parameters, p chosen by simulation fit unless given) → system Markov parameters → ERA
(order from the Hankel singular values unless given) → observer gain → output coordinates
when every state is measured → continuous time → output-error refinement with Cramér–Rao
standard errors (unless turned off) → modes with indicators, uncertainties and aircraft
names → simulation fit (TIC) and stability. Every caller (command line, onboard job, offline
analysis) goes through `identify`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from agent.channels import INPUT_ROLES, POWER_ROLES
from agent.ident import aircraft, frequency, okid
from agent.ident.candidates import Candidate, choose_markov, run_candidate
from agent.ident.convert import (
    StateSpace,
    discretize,
    output_coordinates_transform,
    to_continuous,
)
from agent.ident.errors import (
    ConstantChannelError,
    ContinuousConversionError,
    DataError,
    IdentificationFailed,
)
from agent.ident.fit import Fit, fit, theil
from agent.ident.modal import HankelFactors, Mode, left_out, modal_analysis
from agent.ident.naming import missing_modes, name_modes
from agent.ident.preprocess import Preprocessing, preprocess
from agent.ident.refine import (
    MAX_PASSES,
    Refinement,
    refine,
    simulate_refined,
    with_uncertainty,
)
from agent.ident.result import Identification, OkidDetails, judged
from agent.ident.settings import Settings

# No measurement is this large in any unit; beyond it the regression's products overflow.
MAX_MAGNITUDE = 1e100


def check_channels(
    batch: Sequence[okid.Experiment],
    input_names: Sequence[str],
    output_names: Sequence[str],
    resting: Sequence[int] = (),
) -> None:
    """Reject channels that never move over the whole batch (they cannot be identified), and
    values so large that their products overflow float64. `resting`: inputs that may be
    constant (the aircraft method leaves a control the record did not move out, and says so)."""
    u = np.vstack([e.u for e in batch])
    y = np.vstack([e.y for e in batch])
    for values, names, kind in ((u, input_names, "input"), (y, output_names, "output")):
        peaks = np.max(np.abs(values), axis=0) if values.size else np.zeros(len(names))
        for j, name in enumerate(names):
            if peaks[j] > MAX_MAGNITUDE:
                raise DataError(
                    f"{kind} '{name}' reaches {peaks[j]:.3g}: beyond {MAX_MAGNITUDE:g}, its "
                    "squares and products overflow float64 (overflow); rescale the record "
                    "(check its units)"
                )
    for j, name in enumerate(input_names):
        if np.ptp(u[:, j]) == 0 and j not in resting:
            raise ConstantChannelError(
                f"input '{name}' is constant in every record, so its effect cannot be "
                "identified; excite it or leave it out of the inputs"
            )
    for j, name in enumerate(output_names):
        if np.ptp(y[:, j]) == 0:
            raise ConstantChannelError(
                f"output '{name}' is constant in every record: there is no response to fit; "
                "check the sensor or leave it out of the outputs"
            )


# A sampled position carries its sensor's white noise, and a record's third differences are
# then the noise's: white noise's third differences have a lag-one correlation of −3/4, and
# successive ones share their sign about a quarter of the time; a computed command's, smooth
# between samples, nearly always (a few jumps aside, which the share does not feel). A moved
# input whose successive third differences share their sign in under NOISY of its samples
# carries a sensor's noise: it is a measured position.
NOISY = 0.5
# A moved input that repeats its last value exactly in at least this share of its samples
# away from rest is a staircase: a command held between updates slower than the record's rate.
STAIRCASE = 0.5


def held_by_data(raw: Sequence[okid.Experiment], inputs: Sequence[str]) -> tuple[bool, str]:
    """Whether a record's inputs are held between samples, by the data, with the note that
    says why: held when every moved input is a staircase (STAIRCASE) or carries no sensor
    noise (NOISY) — commands; else sampled, interpolated between samples — a measured position
    carries its sensor's noise, and held it would put every response half a sample late."""
    measured = []
    for j, name in enumerate(inputs):
        columns = [np.asarray(e.u)[:, j] for e in raw if np.ptp(np.asarray(e.u)[:, j]) > 0]
        if not columns:  # never moved: nothing to hold or interpolate
            continue
        if _staircase(columns) or not _noisy(columns):
            continue
        measured.append(name)
    if measured:
        return False, (
            f"inputs taken as sampled positions, interpolated between samples: "
            f"{', '.join(measured)} carry a sensor's noise (held_inputs = false in "
            "[identification] says otherwise)"
        )
    return True, (
        "inputs taken as commands held between samples: none carries a sensor's noise "
        "(held_inputs = false in [identification] says otherwise)"
    )


def _staircase(columns: Sequence[np.ndarray]) -> bool:
    """Whether the columns repeat their last value in STAIRCASE of the samples where they are
    away from rest (a tenth of their range from their median): a command held between
    updates. A measured position repeats at rest (its quantisation) but not while moving."""
    repeats, moving = 0, 0
    for c in columns:
        away = np.abs(c[1:] - np.median(c)) > 0.1 * np.ptp(c)
        repeats += int(np.sum(np.diff(c)[away] == 0))
        moving += int(away.sum())
    return moving > 0 and repeats >= STAIRCASE * moving


def _noisy(columns: Sequence[np.ndarray]) -> bool:
    """Whether the columns' successive third differences share their sign in under NOISY of
    the samples (zeros left out): a sensor's white noise, not a smooth command."""
    same, pairs = 0, 0
    for c in columns:
        d = np.sign(np.diff(c, 3))
        d = d[d != 0]
        same += int(np.sum(d[1:] == d[:-1]))
        pairs += max(d.size - 1, 0)
    return pairs >= 10 and same < NOISY * pairs


def _every_input_used(
    inputs: Sequence[str],
    roles: Sequence[str | None],
    output_roles: Sequence[str | None],
    present: dict[str, tuple[list[int], list[int]]],
) -> None:
    """A DataError naming each input the whole-aircraft method would not use: one without a
    role it knows, or one whose axis's outputs the record lacks. An input asked for is used
    or refused with the reason, never dropped in silence (a record's measured thrust,
    named `thrust` but not so in the config, was)."""
    used = {j for _, ins in present.values() for j in ins}
    known = (*INPUT_ROLES, *POWER_ROLES)
    reasons = []
    for j, name in enumerate(inputs):
        if j in used:
            continue
        role = roles[j]
        if role not in known:
            reasons.append(
                f"input {name!r} has no role the aircraft method knows: name its column in "
                f"[identification.channels] as one of {', '.join(known)} (e.g. thrust = "
                f"{name!r} for a measured thrust)"
            )
            continue
        axis = next(a for a, (_, ins) in aircraft.AXES.items() if role in ins)
        outs, _ = aircraft.AXES[axis]
        lacking = [o for o in outs if o not in output_roles]
        reasons.append(
            f"input {name!r} ({role}) moves the {axis} axis, whose outputs the record does "
            f"not give ({', '.join(lacking)} missing)"
        )
    if reasons:
        raise DataError(
            "; ".join(reasons) + ": leave it out of --inputs, or give --method time (OKID/ERA "
            "takes any input)"
        )


def identify(
    experiments: Sequence[okid.Experiment] | okid.Experiment,
    dt: float,
    *,
    input_names: Sequence[str] | None = None,
    output_names: Sequence[str] | None = None,
    output_roles: Sequence[str | None] | None = None,
    settings: Settings | None = None,
    input_roles: Sequence[str | None] | None = None,
) -> Identification:
    """Identify one model from a batch of experiments sampled every `dt` seconds.

    `method` "auto" (the default) is "aircraft" when the roles name an axis's four outputs
    with one of its inputs (any `--axes`) and none of p, the order, a decimation other than 1
    or refine=False is given (they are OKID's: asking for them asks for OKID), and "time"
    otherwise. The structured model with its kinematics known holds an aircraft's modes where
    a black-box model of the same record can leave a poorly determined one to the data's last
    digits (benchmarks/README.md, *The whole-aircraft method's terms*)."""
    settings = settings or Settings()
    raw = okid.as_experiments(experiments)
    if dt <= 0:
        raise DataError(f"sample time must be positive, got {dt}")
    inputs, outputs = _names(raw, input_names, output_names)
    if settings.held_inputs is None:
        held, hold_note = held_by_data(raw, inputs)
        settings = replace(settings, held_inputs=held)
        result = identify(
            raw,
            dt,
            input_names=inputs,
            output_names=outputs,
            output_roles=output_roles,
            settings=settings,
            input_roles=input_roles,
        )
        return replace(result, warnings=(hold_note, *result.warnings))
    in_roles = tuple(input_roles) if input_roles is not None else inputs
    out_roles = tuple(output_roles) if output_roles is not None else ()
    present = aircraft.axes_present(in_roles, out_roles)
    # A decimation factor is OKID's preprocessing: the aircraft method fits the record's own
    # spectra at its own rate, so a factor other than 1 asks for OKID, as p and the order do.
    decimated = settings.decimation not in (None, 1)
    if settings.method == "auto":
        okid_asked = (
            settings.markov is not None
            or settings.order is not None
            or decimated
            or not settings.refine
        )
        settings = replace(settings, method="aircraft" if present and not okid_asked else "time")
    controls = [j for j, role in enumerate(in_roles) if role in INPUT_ROLES]
    check_channels(raw, inputs, outputs, resting=controls if settings.method == "aircraft" else ())
    if settings.method == "aircraft":
        if not present:
            raise DataError(
                "method 'aircraft' needs the four outputs of an axis (airspeed, alpha, q, "
                "theta or beta, p, r, phi) and its inputs, named by their roles"
            )
        _every_input_used(inputs, in_roles, out_roles, present)
        if decimated:
            raise DataError(
                f"method 'aircraft' fits the record's spectra at its own rate and takes no "
                f"decimation (given {settings.decimation}): leave --decimation (and "
                "[identification] decimation) out, or give --method time or frequency"
            )
        fitted = aircraft.fitted_axes(
            raw,
            dt,
            inputs=inputs,
            outputs=outputs,
            input_roles=in_roles,
            output_roles=out_roles,
            present=present,
            settings=settings,
        )
        return replace(aircraft.identify(fitted, settings), fitted=fitted)
    batch, prep = preprocess(
        raw,
        dt,
        decimation=settings.decimation,
        band_hz=settings.band_hz,
        held_inputs=settings.held_inputs,
        smoothing_s=settings.smoothing_s,
    )
    dt = prep.dt
    warnings: list[str] = []
    freq = None
    if settings.method == "frequency":
        period = None if settings.period_s is None else round(settings.period_s / dt)
        freq = frequency.analyse(batch, period)
        warnings.extend(freq.warnings)
    elif settings.method != "time":
        raise DataError(
            f"method must be 'auto', 'time', 'frequency' or 'aircraft', not {settings.method!r}"
        )
    if settings.markov is None:
        candidate, choice = choose_markov(batch, settings, dt, prep.band_hz, freq)
    else:
        candidate = run_candidate(batch, settings.markov, settings, dt, prep.band_hz, freq)
        choice = None
    model, factors, G, coordinates = _reported_model(candidate)
    okid_model = model
    continuous = _continuous(model, dt, warnings)
    refinement, fitted = None, candidate.fit
    if settings.refine and continuous is None:
        warnings.append("no refinement: no continuous-time model to start from")
    elif settings.refine:
        refined = _refine(continuous, dt, batch, prep, coordinates, settings, G)
        if refined is None:
            warnings.append("refinement could not start or did not improve the OKID/ERA fit")
        else:
            refinement, fitted = refined
            continuous = refinement.continuous
            if not refinement.converged:
                warnings.append(
                    f"refinement stopped at its iteration limit ({refinement.iterations}) before "
                    "the cost settled: poorly determined modes can move with the data's last "
                    "digits; a lower order or a richer excitation helps"
                )
            A, B = _zoh(continuous, dt)
            model = StateSpace(A, B, continuous.C, continuous.D)
    modes = _modes(model, okid_model, factors, candidate, batch, dt, refinement)
    missing: list[tuple[str, str]] = []
    if output_roles is not None:
        modes = name_modes(modes, output_roles)
        span = max(e.length for e in batch) * dt
        missing = missing_modes(modes, output_roles, span_s=span)
    return Identification(
        dt=dt,
        preprocessing=prep,
        input_names=inputs,
        output_names=outputs,
        discrete=model,
        continuous=continuous,
        coordinates=coordinates,
        modes=tuple(modes),
        fit=fitted,
        refinement=refinement,
        warnings=(*warnings, *judged(modes, fitted)),
        method=settings.method,
        okid=OkidDetails(
            markov=candidate.markov,
            markov_choice=choice,
            era=candidate.era,
            observer_gain=G,
            fit=candidate.fit,
            frequency_data=freq,
        ),
        missing=tuple(missing),
        left_out=tuple(left_out(model.A, dt, None if continuous is None else continuous.A)),
    )


def _continuous(model: StateSpace, dt: float, warnings: list[str]) -> StateSpace | None:
    """The continuous-time model, or None (and the reason in `warnings`) when none exists."""
    try:
        Ac, Bc = to_continuous(model.A, model.B, dt)
    except ContinuousConversionError as exc:
        warnings.append(str(exc))
        return None
    return StateSpace(Ac, Bc, model.C, model.D)


def _modes(
    model: StateSpace,
    okid_model: StateSpace,
    factors: HankelFactors,
    candidate: Candidate,
    batch: Sequence[okid.Experiment],
    dt: float,
    refinement: Refinement | None,
) -> list[Mode]:
    """Modes with indicators; after refinement with EMAC inherited and Cramér–Rao 1-σ."""
    input_rms, output_rms = okid.channel_rms(batch)
    okid_modes = modal_analysis(
        okid_model.A,
        okid_model.B,
        okid_model.C,
        dt,
        factors=factors,
        input_scale=input_rms,
        output_scale=output_rms,
    )
    if refinement is None:
        return okid_modes
    modes = modal_analysis(
        model.A,
        model.B,
        model.C,
        dt,
        input_scale=input_rms,
        output_scale=output_rms,
        horizon=(candidate.era.rows, candidate.era.cols),
    )
    return with_uncertainty(_with_consistency(modes, okid_modes), refinement)


def _zoh(model: StateSpace, dt: float) -> tuple[np.ndarray, np.ndarray]:
    return discretize(model.A, model.B, dt)


def _refine(
    continuous: StateSpace,
    dt: float,
    batch: Sequence[okid.Experiment],
    prep: Preprocessing,
    coordinates: str,
    settings: Settings,
    observer_gain: np.ndarray,
) -> tuple[Refinement, Fit] | None:
    """Maximum-likelihood refinement and its fit; None if it cannot start or does not help.

    Held inputs at the record rate are exactly a zero-order hold; decimated (filtered, hence
    smooth) or sampled-continuous inputs are modelled with a first-order hold. Output error
    first; when its fit is poor and its residuals coloured (COLOURED, PROCESS_NOISE_TIC: the
    response carries process noise such as turbulence, which output error does not model),
    the prediction-error fit of the innovation form instead, started
    from the OKID/ERA model and its observer (K = −G). `noise_model` forces either.
    """
    hold = "zoh" if prep.factor == 1 and settings.held_inputs else "foh"

    def run(start: StateSpace, gain: np.ndarray | None, passes: int = MAX_PASSES) -> Refinement:
        return refine(
            start,
            dt,
            batch,
            output_coordinates=coordinates == "outputs",
            estimate_d=settings.estimate_d,
            hold=hold,
            gain=gain,
            max_passes=passes,
        )

    refinement = None
    try:
        if settings.noise_model == "output":
            refinement = run(continuous, None)
        elif settings.noise_model == "auto":
            # One output-error pass tells whether the residuals are coloured; if not, the
            # remaining passes continue from where it stopped.
            first = run(continuous, None, passes=1)
            predictions = simulate_refined(first, batch)
            measured = np.vstack([e.y for e in batch])
            poor = float(np.mean(theil(np.vstack(predictions), measured))) > PROCESS_NOISE_TIC
            if not (poor and residual_colour(predictions, batch) > COLOURED):
                refinement = run(first.continuous, None)
        if refinement is None:
            refinement = run(continuous, -observer_gain)
    except IdentificationFailed:
        return None
    result = fit(refinement.discrete, batch)
    if refinement.cost > refinement.cost_initial or not np.all(np.isfinite(result.tic)):
        return None
    return refinement, result


# Output-error residuals whose lag-1 autocorrelation (averaged over outputs) exceeds COLOURED
# are coloured: white sensor noise after the decimation filter stays near 0.2 (a low-pass at
# 0.8 of Nyquist), turbulence gives 0.9 and more. A tiny deterministic misfit (a noise-free
# record, the hold approximation) is coloured too but harmless, so the innovation form is
# used only when the output-error fit is also poorer than TIC PROCESS_NOISE_TIC.
COLOURED = 0.5
PROCESS_NOISE_TIC = 0.05


def residual_colour(predictions: Sequence[np.ndarray], batch: Sequence[okid.Experiment]) -> float:
    """Lag-1 autocorrelation of the simulation residuals, averaged over outputs."""
    num, den = 0.0, 0.0
    for predicted, exp in zip(predictions, batch, strict=True):
        e = exp.y - predicted
        e = e - e.mean(axis=0)
        num = num + np.sum(e[1:] * e[:-1], axis=0)
        den = den + np.sum(e**2, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = np.where(den > 0, num / den, 0.0)
    return float(np.mean(rho))


# A refined mode inherits the temporal consistency (EMAC) of the OKID/ERA mode it came from
# when their eigenvalues lie within this relative distance; otherwise its EMAC is unknown.
CONSISTENCY_MATCH = 0.2


def _with_consistency(modes: Sequence[Mode], okid_modes: Sequence[Mode]) -> list[Mode]:
    """EMAC (and CMI) of refined modes from the OKID/ERA modes they started as.

    EMAC compares a mode with the Hankel matrix of the data's Markov parameters through the
    ERA realisation's factors; a refined model has different eigenvectors, so the factors do
    not apply to it. Each refined mode takes the EMAC of the nearest OKID/ERA mode (one to
    one) when that lies within CONSISTENCY_MATCH of it.
    """
    remaining = list(okid_modes)
    out = []
    for mode in sorted(modes, key=lambda m: -m.msv):
        emac = None
        if remaining:
            k = int(np.argmin([abs(o.eigenvalue - mode.eigenvalue) for o in remaining]))
            if abs(remaining[k].eigenvalue - mode.eigenvalue) <= CONSISTENCY_MATCH * max(
                abs(mode.eigenvalue), 1e-12
            ):
                emac = remaining.pop(k).emac
        cmi = None if emac is None else emac * mode.mpc / 100.0
        out.append(replace(mode, emac=emac, cmi=cmi))
    return sorted(out, key=lambda mode: (mode.frequency, mode.eigenvalue.imag))


def _names(
    batch: Sequence[okid.Experiment],
    input_names: Sequence[str] | None,
    output_names: Sequence[str] | None,
) -> tuple[tuple[str, ...], tuple[str, ...]]:
    r, m = batch[0].u.shape[1], batch[0].y.shape[1]
    inputs = tuple(input_names or (f"u{j}" for j in range(r)))
    outputs = tuple(output_names or (f"y{j}" for j in range(m)))
    if len(inputs) != r or len(outputs) != m:
        raise DataError(f"{len(inputs)} input and {len(outputs)} output names for {r} × {m} data")
    return inputs, outputs


def _reported_model(
    candidate: Candidate,
) -> tuple[StateSpace, HankelFactors, np.ndarray, str]:
    """Model, Hankel factors and observer gain in output coordinates when possible, else ERA's."""
    realised, m = candidate.era, candidate.era.C.shape[0]
    gain_steps = max(candidate.markov, -(-realised.order // m) + 1)
    G = okid.observer_gain(
        realised.A, realised.C, okid.observer_gain_markov(candidate.omp, gain_steps)
    )
    model = StateSpace(realised.A, realised.B, realised.C, realised.D)
    factors = HankelFactors(realised.observability, realised.controllability)
    T = output_coordinates_transform(realised.C)
    if T is None:
        return model, factors, G, "era"
    return model.transformed(T), factors.transformed(T), T @ G, "outputs"
