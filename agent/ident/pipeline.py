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

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from agent.ident import aircraft, frequency, okid
from agent.ident.candidates import Candidate, MarkovChoice, choose_markov, run_candidate
from agent.ident.convert import (
    StateSpace,
    discretize,
    discretize_hold,
    output_coordinates_transform,
    to_continuous,
)
from agent.ident.era import EraResult
from agent.ident.errors import (
    ConstantChannelError,
    ContinuousConversionError,
    DataError,
    IdentificationFailed,
)
from agent.ident.fit import Fit, fit, theil
from agent.ident.modal import HankelFactors, Mode, modal_analysis
from agent.ident.naming import name_modes
from agent.ident.preprocess import Preprocessing, preprocess
from agent.ident.refine import (
    MAX_PASSES,
    Refinement,
    eigenvalue_std,
    refine,
    simulate_refined,
)
from agent.ident.settings import Settings

# A decent fit has TIC below this (thesis §5.3, ref. [67]).
TIC_DECENT = 0.3
# The kinematic forcing is the kinematics less their expansion about the trim, taken as the
# record's first TRIM_S (the job removes the same stretch's mean as the operating point).
TRIM_S = 0.5
# The aircraft method's simulation starts each record at the mean of its first INITIAL_S of
# outputs.
INITIAL_S = 0.05


@dataclass(frozen=True)
class Identification:
    """Everything one identification produced."""

    dt: float  # analysis sample time (after decimation)
    preprocessing: Preprocessing
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    markov: int
    markov_choice: MarkovChoice | None  # None when p was given
    era: EraResult  # the realisation in ERA's balanced coordinates
    discrete: StateSpace  # reported coordinates (outputs when possible)
    continuous: StateSpace | None  # None when no real continuous model exists
    coordinates: str  # "outputs" or "era"
    observer_gain: np.ndarray  # G in reported coordinates: A + G C is the OKID observer
    modes: tuple[Mode, ...]
    fit: Fit
    refinement: Refinement | None  # None when turned off or impossible (see warnings)
    okid_fit: Fit  # the OKID/ERA model's own fit, before refinement
    warnings: tuple[str, ...]
    method: str = "time"
    frequency_data: frequency.FrequencyData | None = None  # spectra and FRF for "frequency"
    aircraft: dict | None = None  # for "aircraft": band, axes, engine lag, coupling found

    @property
    def order(self) -> int:
        return self.era.order

    @property
    def stable(self) -> bool:
        return all(mode.stable for mode in self.modes)

    @property
    def singular_values(self) -> np.ndarray:
        return self.era.singular_values


# No measurement is this large in any unit; beyond it the regression's products overflow.
MAX_MAGNITUDE = 1e100


def check_channels(
    batch: Sequence[okid.Experiment], input_names: Sequence[str], output_names: Sequence[str]
) -> None:
    """Reject channels that never move over the whole batch (they cannot be identified), and
    values so large that their products overflow float64."""
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
        if np.ptp(u[:, j]) == 0:
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
    digits (an unconverged 8-state refinement put a lateral record's roll mode anywhere from
    −9.9 ± 1.1j to −12.9 under 1e-14 perturbations; the aircraft method gave −12.2 on each,
    the truth −12.1)."""
    settings = settings or Settings()
    raw = okid.as_experiments(experiments)
    if dt <= 0:
        raise DataError(f"sample time must be positive, got {dt}")
    inputs, outputs = _names(raw, input_names, output_names)
    check_channels(raw, inputs, outputs)
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
    if settings.method == "aircraft":
        if not present:
            raise DataError(
                "method 'aircraft' needs the four outputs of an axis (airspeed, alpha, q, "
                "theta or beta, p, r, phi) and its inputs, named by their roles"
            )
        if decimated:
            raise DataError(
                f"method 'aircraft' fits the record's spectra at its own rate and takes no "
                f"decimation (given {settings.decimation}): leave --decimation (and "
                "[identification] decimation) out, or give --method time or frequency"
            )
        return _identify_aircraft(raw, dt, inputs, outputs, in_roles, out_roles, present, settings)
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
    if output_roles is not None:
        modes = name_modes(modes, output_roles)
    if any(not mode.stable for mode in modes):
        warnings.append("the identified model has unstable modes")
    if fitted.tic_avg >= TIC_DECENT:
        warnings.append(f"average TIC {fitted.tic_avg:.3f} is not below {TIC_DECENT}")
    return Identification(
        dt=dt,
        preprocessing=prep,
        input_names=inputs,
        output_names=outputs,
        markov=candidate.markov,
        markov_choice=choice,
        era=candidate.era,
        discrete=model,
        continuous=continuous,
        coordinates=coordinates,
        observer_gain=G,
        modes=tuple(modes),
        fit=fitted,
        refinement=refinement,
        okid_fit=candidate.fit,
        warnings=tuple(warnings),
        method=settings.method,
        frequency_data=freq,
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
    return _with_uncertainty(_with_consistency(modes, okid_modes), refinement)


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


def _with_uncertainty(modes: Sequence[Mode], refinement: Refinement) -> list[Mode]:
    """Attach the Cramér–Rao 1-σ of each mode's eigenvalue (nearest eigenvalue of Ac)."""
    lam = np.linalg.eigvals(refinement.continuous.A)
    stds = eigenvalue_std(refinement.continuous.A, refinement.covariance_of_a())
    out = []
    for mode in modes:
        k = int(np.argmin(np.abs(lam - mode.eigenvalue)))
        out.append(replace(mode, uncertainty=stds[k]))
    return out


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


def _identify_aircraft(
    raw: Sequence[okid.Experiment],
    dt: float,
    inputs: tuple[str, ...],
    outputs: tuple[str, ...],
    input_roles: Sequence[str | None],
    output_roles: Sequence[str | None],
    present: dict[str, tuple[list[int], list[int]]],
    settings: Settings,
) -> Identification:
    """Decoupled longitudinal and lateral models in the frequency domain (agent.ident.aircraft),
    assembled into one model whose first states are the outputs and whose last ones are the
    engine's lag states; where the data show coupling, the other axis's states join an
    axis's inputs and their gains fill A's coupling blocks."""
    # The transforms leave out DC, so trim errors do not matter to the fit; the time-domain
    # simulation (TIC) starts from the records' own trim, as the other methods'.
    batch = list(raw)
    r = len(inputs)
    ready = aircraft.prepare(batch, output_roles, max(1, round(TRIM_S / dt)), dt)
    band = settings.band_hz or aircraft.input_band(batch, dt)
    sp = aircraft.spectra(
        ready.batch,
        dt,
        band,
        settings.held_inputs,
        ready.known,
        ready.kinematics,
        ready.attitude,
        ready.rows,
    )
    E = len(batch)
    throttle = [j for j, role in enumerate(input_roles) if role == "throttle"]
    known = {axis: [j for j, a in ready.extra_axes.items() if a == axis] for axis in aircraft.AXES}
    if "longitudinal" not in present:  # α barely moves: its products only add unknowns
        known["lateral"] = [j for j in known["lateral"] if j not in ready.bilinear]
    names = [*inputs, *ready.extra_names]
    wind = {"measured": bool(ready.gusts), "gust_rms": ready.gust_rms}
    fits, report = (
        [],
        {
            "band_hz": list(sp.band_hz),
            "bins": int(sp.s.size),
            "coupling": {},
            "kinematics": ready.known is not None,
            "wind": wind,
        },
    )
    for axis, (states, ins) in present.items():
        rated = [j for j in known[axis] if j in ready.rates]  # gust rates: one lag each
        fits.append(
            aircraft.fit_axis(
                sp,
                axis,
                states,
                [*ins, *known[axis]],
                [j for j in ins if j in throttle] + rated,
                E,
                ins,
                dict.fromkeys(rated, aircraft.GUST_RATE_LAGS),
            )
        )
    width = sp.U.shape[1]
    if len(fits) == 2:
        # The other axis's measured states as known inputs: their gains are the coupling
        # blocks of A (Klein & Morelli, ch. 9). The propeller's gyroscopic moments couple
        # pitch and yaw rates (q̇ = … − 0.52 r on JSBSim's Cub) however symmetric the airframe.
        augmented = replace(sp, U=np.hstack([sp.U, sp.Y]))
        own = [[j for j in f.inputs if j < r] for f in fits]  # each axis's own controls
        for k, fitted in enumerate(fits):
            other = own[1 - k]
            cross = [width + c for c in fits[1 - k].states if c not in ready.attitude]
            by_inputs, moved_inputs = aircraft.coupling(sp, fitted, other, E)
            by_states, moved_states = aircraft.coupling(augmented, fitted, cross, E)
            report["coupling"][fitted.name] = {
                "by_inputs": by_inputs,
                "by_states": by_states,
                "response_by_inputs": moved_inputs,
                "response_by_states": moved_states,
            }
            ins, controls = list(fitted.inputs), list(fitted.controls)
            # The longitudinal forces and moments are even in the lateral variables (the
            # airframe's symmetry), so lateral controls never join the longitudinal axis: what
            # they explain there is even-order (sideslip drag), which a linear term only mimics.
            # Where the longitudinal controls reach the lateral axis, the throttle joins it
            # (the propeller's torque and slipstream act linearly and at once), the elevator
            # does not: it has no path to the lateral forces but through the longitudinal
            # states. Controls and states join each on its own test, not one of them by the
            # larger share of the cost: where the shares nearly tie (JSBSim's Cub in calm
            # air), that choice flips from seed to seed and the spiral with it.
            join_controls = moved_inputs > aircraft.COUPLED and fitted.name == "lateral"
            join_states = moved_states > aircraft.COUPLED
            lags = list(fitted.lags)
            if join_controls:
                thrust = [j for j in other if j in throttle]
                ins += thrust
                controls += thrust
                # The throttle reaches the lateral axis as it reaches the longitudinal one:
                # through the engine's lags (its torque and slipstream follow the thrust).
                lags += thrust
            if join_states:
                ins += cross
            if ins != list(fitted.inputs):
                fits[k] = aircraft.fit_axis(
                    augmented,
                    fitted.name,
                    fitted.states,
                    ins,
                    tuple(lags),
                    E,
                    controls,
                    fitted.lag_powers,
                )
        coupled = []
        for k, f in enumerate(fits):
            by = ["the throttle"] if any(j < r and j not in own[k] for j in f.inputs) else []
            by += ["the other axis's states"] if any(j >= width for j in f.inputs) else []
            if by:
                coupled.append(f"{f.name} coupled by {' and '.join(by)}")
        report["model"] = "decoupled" + (f", {' and '.join(coupled)}" if coupled else "")
    else:
        report["model"] = fits[0].name
    model, covariance, _lag_times = _assemble(
        fits, len(inputs), len(outputs), {width + c: c for c in range(len(outputs))}
    )
    for column, row in ready.rows.items():  # sideslip drag: V̇ = … + X_β² β²
        for f in fits:
            gain = aircraft.known_gain(f, column, row)
            if gain is not None:
                report["sideslip_drag"] = {"gain": gain[0], "std": gain[1]}
    # The lateral derivatives' change with α: each product's gain in β̇, ṗ and ṙ.
    products = {}
    for column in ready.bilinear:
        for f in fits:
            for row in f.states:
                gain = aircraft.known_gain(f, column, row)
                if gain is not None and row not in ready.attitude:
                    products.setdefault(names[column], {})[outputs[row]] = {
                        "gain": gain[0],
                        "std": gain[1],
                    }
    if products:
        report["alpha_products"] = products
    report["engine_lag_s"] = {
        f.name: {inputs[j]: tau for j, tau in f.lags.items() if j < r} for f in fits if f.lags
    }
    report["axes"] = [
        {
            "name": f.name,
            "outputs": [outputs[i] for i in f.states],
            "inputs": [names[j] if j < width else outputs[j - width] for j in f.inputs],
            "iterations": f.iterations,
            "converged": f.converged,
        }
        for f in fits
    ]
    hold = "zoh" if settings.held_inputs else "foh"
    discrete = _sampled(model, dt, hold, outputs)
    n_model = model.A.shape[0]
    # Each record starts where its outputs are (the model's first states are the outputs) with
    # the engine's lag states at rest. Estimated by least squares instead, those nearly
    # unobservable states took values of ±1000 that traded the bank angle's fit for the
    # airspeed's (the Cub's φ TIC 0.64 against 0.06).
    start = max(1, round(INITIAL_S / dt))
    initial = [
        np.concatenate([e.y[:start].mean(axis=0), np.zeros(n_model - len(outputs))]) for e in batch
    ]
    fitted = fit(discrete, batch, initial)
    warnings: list[str] = []
    if not all(f.converged for f in fits):
        warnings.append("the output-error fit stopped at its iteration limit")
    residuals = np.vstack([e.y - p for e, p in zip(batch, fitted.predictions, strict=True)])
    refinement = Refinement(
        gain=None,
        continuous=model,
        discrete=discrete,
        dt=dt,
        hold=hold,
        initial_states=fitted.initial_states,
        noise_std=residuals.std(axis=0),
        covariance=covariance,
        cost_initial=sum(f.cost_start for f in fits),
        cost=sum(f.cost for f in fits),
        iterations=sum(f.iterations for f in fits),
        passes=1,
        converged=all(f.converged for f in fits),
    )
    n = model.A.shape[0]
    era = EraResult(
        discrete.A,
        discrete.B,
        discrete.C,
        discrete.D,
        np.zeros(0),
        n,
        0,
        0,
        np.zeros((0, n)),
        np.zeros((n, 0)),
    )
    # Modes of the aircraft states alone (the lag states are the engine's, two equal poles
    # with no modal decomposition), with each lagged input at its steady gain.
    m = len(outputs)
    Bm = model.B[:m].copy()
    for f in fits:
        for c, j in enumerate(f.inputs):
            if j < r:  # a control (the gusts are not the model's inputs)
                Bm[list(f.states), j] = f.B[:, c]
    states_only = StateSpace(model.A[:m, :m], Bm, np.eye(m), np.zeros((m, len(inputs))))
    index = np.arange(n * n).reshape(n, n)[:m, :m].ravel()
    for_modes = replace(
        refinement, continuous=states_only, covariance=covariance[np.ix_(index, index)]
    )
    Am, Bmd = _zoh(states_only, dt)
    input_rms, output_rms = okid.channel_rms(batch)
    modes = modal_analysis(
        Am, Bmd, states_only.C, dt, input_scale=input_rms, output_scale=output_rms
    )
    modes = _with_uncertainty(modes, for_modes)
    if any(role is not None for role in output_roles):
        modes = name_modes(modes, output_roles, min_msv=0.0)
    if any(not mode.stable for mode in modes):
        warnings.append("the identified model has unstable modes")
    if fitted.tic_avg >= TIC_DECENT:
        warnings.append(f"average TIC {fitted.tic_avg:.3f} is not below {TIC_DECENT}")
    prep = Preprocessing(
        record_dt=dt,
        dt=dt,
        factor=1,
        band_hz=sp.band_hz[1],
        held_inputs=settings.held_inputs,
        smoothing_s=None,
        dropped_samples=0,
    )
    return Identification(
        dt=dt,
        preprocessing=prep,
        input_names=inputs,
        output_names=outputs,
        markov=0,
        markov_choice=None,
        era=era,
        discrete=discrete,
        continuous=model,
        coordinates="outputs",
        observer_gain=np.zeros((n, len(outputs))),
        modes=tuple(modes),
        fit=fitted,
        refinement=refinement,
        okid_fit=fitted,
        warnings=tuple(warnings),
        method="aircraft",
        aircraft=report,
    )


def _sampled(model: StateSpace, dt: float, hold: str, outputs: Sequence[str]) -> StateSpace:
    """The whole-aircraft model sampled at dt. An output with no response above its noise (a
    dead sensor's noise alone) gets gains of 10¹⁰ in the other equations and the model a pole
    millions of 1/s fast, which no sampling survives: a clear failure naming that output, not
    an overflow deep in the modal analysis."""
    with np.errstate(all="ignore"):
        discrete = discretize_hold(model.A, model.B, model.C, model.D, dt, hold)
    if all(np.all(np.isfinite(x)) for x in (discrete.A, discrete.B)):
        return discrete
    pole = np.max(np.abs(np.linalg.eigvals(model.A)))
    m = len(outputs)
    gains = np.max(np.abs(model.A[:m, :m]), axis=0)  # what each output's changes are worth
    where = outputs[int(np.argmax(gains))]
    raise IdentificationFailed(
        f"the identified model has a pole of {pole:.3g} 1/s, far beyond what sampling at "
        f"{dt:g} s can show, and gains up to {gains.max():.3g} on {where}: an output with no "
        f"response above its noise (a dead sensor) does that; check {where}'s signal or "
        "leave it out of the outputs"
    )


def _assemble(fits: Sequence[aircraft.AxisFit], r: int, m: int, states_of: dict | None = None):
    """One continuous model (states: the m outputs, then two lag states per lagged input of
    each axis) and the covariance of [vec Ac, vec Bc, vec C, vec D] (zero where fixed)."""
    lagged = [(f, j) for f in fits for j in f.lags if j < r]  # the gust rates' are no state
    n = m + aircraft.THROTTLE_LAGS * len(lagged)
    A, B = np.zeros((n, n)), np.zeros((n, r))
    index_a = np.arange(n * n).reshape(n, n)
    index_b = n * n + np.arange(n * r).reshape(n, r)
    size = n * n + n * r + m * n + m * r
    cov = np.zeros((size, size))
    lag_times = {}
    extra = m
    for f in fits:
        st = list(f.states)
        A[np.ix_(st, st)] = f.A
        where_b = np.full((len(st), len(f.inputs)), -1)  # where each B entry went
        for c, j in enumerate(f.inputs):
            if j >= r and j in (states_of or {}):  # another axis's state: a coupling of A
                A[st, states_of[j]] = f.B[:, c]
                where_b[:, c] = index_a[st, states_of[j]]
                continue
            if j >= r:  # a measured gust: it drove the fit, it is not an input of the model
                continue
            if j in f.lags:  # u → lag → lag → the axis: B's column acts on the last lag state
                tau = f.lags[j]
                chain = list(range(extra, extra + aircraft.THROTTLE_LAGS))
                B[chain[0], j] = 1.0 / tau
                for a, b in itertools.pairwise(chain):
                    A[b, a] = 1.0 / tau
                for k in chain:
                    A[k, k] = -1.0 / tau
                A[st, chain[-1]] = f.B[:, c]
                where_b[:, c] = index_a[st, chain[-1]]
                lag_times[j] = tau
                extra += aircraft.THROTTLE_LAGS
            else:
                B[st, j] = f.B[:, c]
                where_b[:, c] = index_b[st, j]
        pos = np.concatenate([index_a[np.ix_(st, st)].ravel(), where_b.ravel()])
        kept = pos >= 0
        cov[np.ix_(pos[kept], pos[kept])] = f.covariance[np.ix_(kept, kept)]
    C = np.hstack([np.eye(m), np.zeros((m, n - m))])
    return StateSpace(A, B, C, np.zeros((m, r))), cov, lag_times
