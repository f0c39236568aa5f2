"""The whole-aircraft model: each axis fitted, coupled where the data show coupling, assembled
into one model whose first states are the outputs and whose last ones are the engine's lag
states, with its modes, fit and report.

Coupling (Klein & Morelli, *Aircraft System Identification*, 2006, ch. 9): each axis model is
fitted again with the other axis's controls added, and again with the other axis's measured
states, and each joins on its own test, when it changes the outputs by more than COUPLED:
- where the longitudinal controls reach the lateral axis, the throttle joins it, through the
  engine's lags (the propeller's torque and slipstream act linearly and at once). The
  elevator does not: it has no path to the lateral forces but through the longitudinal
  states. Lateral controls never join the longitudinal axis: its forces and moments are even
  in the lateral variables (the airframe's symmetry), so what they explain there is
  even-order (sideslip drag), which a linear term only mimics;
- the other axis's states (θ and φ aside, which the kinematics carry) join either axis. Their
  gains are the coupling blocks of the assembled A, so the modes are the coupled aircraft's;
  the propeller's gyroscopic moments couple pitch and yaw rates however symmetric the
  airframe.
At the other axis's lines its states are its controls' response, so the two overlap there:
letting only the one that explains more of the cost join would make the model's structure
hang on a near tie, flipping from seed to seed.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.optimize
import scipy.signal

from agent.channels import POWER_ROLES
from agent.ident.aircraft.airangles import Synthesised
from agent.ident.aircraft.axes import AXES, LONGITUDINAL, moved_axes
from agent.ident.aircraft.fit import (
    COUPLED,
    AxisFit,
    added_costs,
    coupling,
    fit_axis,
    known_gain,
    lag_order_cost,
    selected,
)
from agent.ident.aircraft.predictor import (
    Predicted,
    lagged,
    refined,
    roll_imprecise,
    shows_process_noise,
)
from agent.ident.aircraft.prepare import Prepared, prepare
from agent.ident.aircraft.problem import ENGINE_ORDERS, THROTTLE_LAGS, AxisProblem
from agent.ident.aircraft.transforms import Transforms, input_band, transforms
from agent.ident.aircraft.wind import GUST_RATE_LAGS
from agent.ident.convert import StateSpace, discretize, discretize_hold
from agent.ident.document import (
    AirAngles,
    AircraftDocument,
    AxisDocument,
    Coupling,
    Engine,
    Gain,
    NoiseMisfit,
    Wind,
)
from agent.ident.errors import DataError, IdentificationFailed
from agent.ident.fit import Fit as FitInTime
from agent.ident.fit import fit, theil
from agent.ident.modal import Mode, SecondOrder, left_out, modal_analysis, second_order
from agent.ident.naming import LATERAL_MODES, LONGITUDINAL_MODES, missing_modes, name_modes
from agent.ident.okid import Experiment, channel_rms
from agent.ident.preprocess import Preprocessing
from agent.ident.refine import Refinement, second_order_std, with_uncertainty
from agent.ident.result import Identification, judged
from agent.ident.settings import Settings

# The kinematic forcing is the kinematics less their expansion about the trim, taken as the
# record's first TRIM_S (the job removes the same stretch's mean as the operating point).
TRIM_S = 0.5
# A named mode whose Cramér–Rao σ(ωn) is above this share of its ωn is said to be poorly
# resolved by the record (the suggestion's own limit, agent.models.CR_MAX: Tischler & Remple,
# 2012, ch. 11, take 20 % as the bound of an accurate parameter).
RESOLVED = 0.2
# The simulation starts each record at the mean of its first INITIAL_S of outputs, with the
# engine's lag states at rest: estimated by least squares instead, those nearly unobservable
# states take absurd values that trade one output's fit for another's.
INITIAL_S = 0.05


@dataclass(frozen=True, kw_only=True)
class Fitted:
    """The axes fitted to a record, before they are assembled: what `identify` builds its model
    from, and what a bound on that record (`agent.ident.aircraft.bound`) is computed in."""

    dt: float  # the records' sample time, s
    sp: Transforms  # the record's transforms (the controls, then the known inputs)
    augmented: Transforms  # sp with the measured states appended as inputs (the couplings')
    ready: Prepared
    fits: list[AxisFit]
    engine: dict[int, tuple[int, dict[int, float]]]
    couplings: dict[str, Coupling]
    structure: str
    batch: list[Experiment]  # the moved channels' records
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    input_roles: list[str | None]
    output_roles: list[str | None]
    present: dict[str, tuple[list[int], list[int]]]
    measured: list[int]  # input columns of a measured rpm or thrust
    notes: list[str]  # what was left out or set aside, and why
    not_moved: list[tuple[str, str]]  # modes missing because their axis did not move
    # Axis name → what its prediction-error refinement found (agent.ident.aircraft.predictor).
    predicted: dict[str, Predicted] = field(default_factory=dict)


def fitted_axes(
    raw: Sequence[Experiment],
    dt: float,
    *,
    inputs: tuple[str, ...],
    outputs: tuple[str, ...],
    input_roles: Sequence[str | None],
    output_roles: Sequence[str | None],
    present: dict[str, tuple[list[int], list[int]]],
    settings: Settings,
) -> Fitted:
    """Each axis of what the record moved fitted, and coupled where the data show it
    (`identify`'s first half)."""
    raw, inputs, outputs, input_roles, output_roles, present, moved_notes, not_moved = _only_moved(
        raw, inputs, outputs, input_roles, output_roles, present
    )
    # The transforms leave out DC, so trim errors do not matter to the fit; the time-domain
    # simulation (TIC) starts from the records' own trim, as the other methods'.
    batch = list(raw)
    # The throttle's curvature, where the longitudinal axis is fitted and no measured rpm or
    # thrust carries the engine instead (prepare's module docstring).
    curved = (
        {j: inputs[j] for j, role in enumerate(input_roles) if role == "throttle"}
        if settings.throttle_curve
        and "longitudinal" in present
        and not any(role in POWER_ROLES for role in input_roles)
        else {}
    )
    ready = prepare(
        batch,
        output_roles,
        trim_samples=max(1, round(TRIM_S / dt)),
        dt=dt,
        sideslip_drag=settings.sideslip_drag,
        alpha_products=settings.alpha_products,
        throttles=curved,
        density=settings.density,
    )
    sp = transforms(
        ready.batch,
        dt,
        settings.band_hz or input_band(batch, dt),
        held_inputs=settings.held_inputs,
        # Sampled inputs are measured positions, with their sensors' noise; held ones commands.
        measured=() if settings.held_inputs else range(len(inputs)),
        known=ready.known,
        kinematics=ready.kinematics,
        attitude=ready.attitude,
        rows=ready.rows,
    )
    throttle = [j for j, role in enumerate(input_roles) if role == "throttle"]
    measured = [j for j, role in enumerate(input_roles) if role in POWER_ROLES]
    notes = list(moved_notes)
    if measured and throttle and "longitudinal" in present:
        # The measured rpm or thrust is what the throttle's command does to the engine: both as
        # inputs would give the same path twice.
        states, ins = present["longitudinal"]
        present = {**present, "longitudinal": (states, [j for j in ins if j not in throttle])}
        notes.append(
            f"{', '.join(inputs[j] for j in throttle)} set aside: the measured "
            f"{', '.join(inputs[j] for j in measured)} carries the engine (a known input, at once)"
        )
    # The filter-error method wherever α's gust is not measured (agent.ident.aircraft.process):
    # with the vanes, the air-relative V and α feel the gust's rate row by row; with α
    # synthesised from the INS (no vanes) the state feels it too and the output, the inertial
    # α, does not see it (the noise's direct path). With the wind measured the residual is
    # the sensors' and output error holds. A measured α gust within its sensors' noise (calm
    # air; prepare) is no input: the axis is fitted as if nothing measured it, the filter error
    # used where the residual shows process noise (the nonlinearity's and the engine's, which
    # the gust's free gains had fitted instead).
    filtered = settings.process_noise and "alpha" not in ready.gusts
    synthesised = (LONGITUDINAL[0].index("alpha"),) if ready.air_angles else ()
    fits, engine = _fit_axes(
        sp,
        ready,
        present,
        throttle,
        len(batch),
        process_noise=filtered,
        synthesised=synthesised,
        still=ready.still,
    )
    engine |= {j: (0, {}) for j in measured if any(j in f.inputs for f in fits)}
    couplings: dict[str, Coupling] = {}
    structure = fits[0].name
    if len(fits) == 2:
        fits, couplings, structure = _coupled(
            sp, fits, ready, engine, r=len(inputs), experiments=len(batch)
        )
    if settings.select:
        fits, fixed = _structure(sp, fits, inputs, outputs, experiments=len(batch))
        notes.append(fixed)
    predicted: dict[str, Predicted] = {}
    # In closed loop always (output error is biased there, the prediction error consistent);
    # in open loop, where output error is consistent, only where its roll mode is imprecise
    # (agent.ident.aircraft.predictor.roll_imprecise: the rolling gust's own response then
    # holds the roll's information, which only a noise model reads).
    if settings.predictor and ready.known is not None:
        fits, predicted, failed = _by_prediction(
            sp,
            fits,
            ready,
            output_roles,
            dt=dt,
            hold="zoh" if settings.held_inputs else "foh",
            experiments=len(batch),
            closed_loop=settings.closed_loop,
        )
        notes += failed
    return Fitted(
        dt=dt,
        sp=sp,
        augmented=augment(sp),
        ready=ready,
        fits=fits,
        engine=engine,
        couplings=couplings,
        structure=structure,
        batch=batch,
        inputs=inputs,
        outputs=outputs,
        input_roles=list(input_roles),
        output_roles=list(output_roles),
        present=present,
        measured=measured,
        notes=notes,
        not_moved=not_moved,
        predicted=predicted,
    )


def _by_prediction(
    sp: Transforms,
    fits: list[AxisFit],
    ready: Prepared,
    output_roles: Sequence[str | None],
    *,
    dt: float,
    hold: str,
    experiments: int,
    closed_loop: bool,
) -> tuple[list[AxisFit], dict[str, Predicted], list[str]]:
    """The lateral axis refined by prediction error where its residual shows process noise
    and, in open loop, output error's roll mode is imprecise (`roll_imprecise`): the rolling
    gust (which nothing measures) as coloured process noise on p's equation, and the lateral
    gust on β's and r's too where it is not a known input (agent.ident.aircraft.predictor);
    what each refinement found, and a note for one that failed (the frequency-domain fit is
    kept). Not where β was synthesised from the INS (no
    vanes): the gust then forces the state and the output does not see it (the filter
    error's direct path, agent.ident.aircraft.process), which these noise states do not
    model; on the thesis's aircraft so flown the refinement took the worst mode 1.5 → 26 %
    off, and on JSBSim's glider in light turbulence its Dutch roll's worst seed 16 → 55 %."""
    if ready.air_angles:
        return fits, {}, []
    width = sp.U.shape[1]
    noisy = ("p",) if "beta" in ready.gusts else ("beta", "p", "r")
    out, found, notes = [], {}, []
    for f in fits:
        if f.name != "lateral":
            out.append(f)
            continue
        source = augment(sp) if any(j >= width for j in f.inputs) else sp
        problem = AxisProblem(
            source,
            states=f.states,
            inputs=f.inputs,
            lagged=list(f.lags),
            experiments=experiments,
            controls=f.controls,
            powers=f.lag_powers,
            zeros=f.zeros,
        )
        rows = [
            i
            for i, c in enumerate(f.states)
            if output_roles[c] in noisy and not problem.fixed_A[i].all()
        ]
        wanted = closed_loop or roll_imprecise(f)
        if not rows or not wanted or not shows_process_noise(f, problem, rows):
            out.append(f)
            continue
        try:
            better, found[f.name] = refined(f, problem, ready, sp, dt=dt, hold=hold, rows=rows)
        except IdentificationFailed as exc:
            notes.append(f"{f.name} axis: prediction error failed ({exc}); output error kept")
            better = f
        out.append(better)
    return out, found, notes


def identify(fitted: Fitted, settings: Settings) -> Identification:
    """Decoupled longitudinal and lateral models in the frequency domain, coupled where the
    data show it (`fitted_axes`), assembled into one model (module docstring), of what the
    record moved (`axes.moved_axes`): a control it left at trim is left out of the inputs, an
    axis it did not move out of the inputs and outputs, with its modes as missing, by name,
    and why."""
    dt = fitted.dt
    sp, ready, fits, engine = fitted.sp, fitted.ready, fitted.fits, fitted.engine
    batch, inputs, outputs = fitted.batch, fitted.inputs, fitted.outputs
    output_roles, present, measured = fitted.output_roles, fitted.present, fitted.measured
    couplings, structure = fitted.couplings, fitted.structure
    width = sp.U.shape[1]
    model, covariance, spread = assemble(
        fits, r=len(inputs), m=len(outputs), states_of={width + c: c for c in range(len(outputs))}
    )
    report = _report(
        sp,
        fits,
        ready,
        couplings,
        structure,
        engine,
        inputs=inputs,
        outputs=outputs,
        measured=measured,
        predicted=fitted.predicted,
    )
    hold = "zoh" if settings.held_inputs else "foh"
    discrete = _sampled(model, dt, hold, outputs)
    start = max(1, round(INITIAL_S / dt))
    n_model = model.A.shape[0]
    initial = [
        np.concatenate([e.y[:start].mean(axis=0), np.zeros(n_model - len(outputs))]) for e in batch
    ]
    if ready.known is None:
        fit_in_time = fit(discrete, batch, initial)
    else:
        fit_in_time = _fit_with_known(model, fits, ready, batch, r=len(inputs), dt=dt, hold=hold)
    residuals = np.vstack([e.y - p for e, p in zip(batch, fit_in_time.predictions, strict=True)])
    refinement = Refinement(
        gain=None,
        continuous=model,
        discrete=discrete,
        dt=dt,
        hold=hold,
        initial_states=fit_in_time.initial_states,
        noise_std=residuals.std(axis=0),
        covariance=covariance,
        spread=spread,
        cost_initial=sum(f.cost_start for f in fits),
        cost=sum(f.cost for f in fits),
        iterations=sum(f.iterations for f in fits),
        passes=1,
        converged=all(f.converged for f in fits),
    )
    modes, poles_left_out = _modes(
        model, fits, refinement, batch, dt, r=len(inputs), output_roles=output_roles
    )
    span = max(e.length for e in batch) * dt
    missing = missing_modes(modes, output_roles, span_s=span, min_msv=0.0)
    warnings = (
        [] if refinement.converged else ["the output-error fit stopped at its iteration limit"]
    )
    orders = [second_order_std(o, refinement) for o in second_order(modes)]
    warnings += _poorly_resolved(modes, orders, sp, present)
    warnings += _longer_than_the_record(modes, span)
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
        discrete=discrete,
        continuous=model,
        coordinates="outputs",
        modes=tuple(modes),
        fit=fit_in_time,
        refinement=refinement,
        warnings=(*fitted.notes, *warnings, *judged(modes, fit_in_time)),
        method="aircraft",
        aircraft=report,
        missing=(*missing, *fitted.not_moved),
        left_out=tuple(poles_left_out),
    )


def _only_moved(
    raw: Sequence[Experiment],
    inputs: tuple[str, ...],
    outputs: tuple[str, ...],
    input_roles: Sequence[str | None],
    output_roles: Sequence[str | None],
    present: dict[str, tuple[list[int], list[int]]],
) -> tuple[
    list[Experiment],
    tuple[str, ...],
    tuple[str, ...],
    list[str | None],
    list[str | None],
    dict[str, tuple[list[int], list[int]]],
    list[str],
    list[tuple[str, str]],
]:
    """The batch, channels, roles and axes of what the record moved (`axes.moved_axes`), the
    notes on what was left out and the modes that leaves missing, with why."""
    chosen = moved_axes(raw, inputs, input_roles, present)
    if not chosen.present:
        raise DataError(
            "no control moved above its sensor's noise: "
            + "; ".join(f"{axis} {why}" for axis, why in chosen.axes_left_out.items())
        )
    drop_in, drop_out = set(chosen.controls_left_out), set()
    notes = [chosen.controls_left_out[j] for j in sorted(chosen.controls_left_out)]
    missing = []
    for axis, why in chosen.axes_left_out.items():
        drop_in |= set(present[axis][1])
        drop_out |= set(present[axis][0])
        notes.append(f"{axis} axis left out: {why}")
        modes = LATERAL_MODES if axis == "lateral" else LONGITUDINAL_MODES
        missing += [(name, f"not identifiable from this record: {why}") for name in modes]
    keep_in = [j for j in range(len(inputs)) if j not in drop_in]
    keep_out = [i for i in range(len(outputs)) if i not in drop_out]
    new_in = {j: k for k, j in enumerate(keep_in)}
    new_out = {i: k for k, i in enumerate(keep_out)}
    return (
        [_columns(e, keep_in, keep_out) for e in raw] if notes else list(raw),
        tuple(inputs[j] for j in keep_in),
        tuple(outputs[i] for i in keep_out),
        [input_roles[j] for j in keep_in],
        [output_roles[i] for i in keep_out],
        {
            axis: ([new_out[i] for i in states], [new_in[j] for j in ins])
            for axis, (states, ins) in chosen.present.items()
        },
        notes,
        missing,
    )


def _columns(exp: Experiment, inputs: list[int], outputs: list[int]) -> Experiment:
    """`exp` with only the given input and output columns (its navigation whole)."""
    op = exp.operating_point
    return Experiment(
        np.asarray(exp.u)[:, inputs],
        np.asarray(exp.y)[:, outputs],
        operating_point=None if op is None else np.asarray(op)[outputs],
        navigation=exp.navigation,
        air_angles=exp.air_angles,
        flight=exp.flight,
    )


def _fit_axes(
    sp: Transforms,
    ready: Prepared,
    present: dict[str, tuple[list[int], list[int]]],
    throttle: list[int],
    experiments: int,
    process_noise: bool = True,
    synthesised: Sequence[int] = (),
    still: bool = False,
) -> list[AxisFit]:
    """Each present axis fitted alone, with its controls and the known inputs that act on it;
    the throttle and the gust rates through fitted lags; the longitudinal axis by the
    filter-error method with `process_noise` (agent.ident.aircraft.process; `synthesised`:
    its states whose air angle the INS gave, fit.fit_axis's)."""
    # The throttle's curvature joins on its own test, after the engine's order (`_curved`).
    known = {
        axis: [j for j, a in ready.extra_axes.items() if a == axis and j not in ready.curve]
        for axis in AXES
    }
    if "longitudinal" not in present:  # α barely moves: its products only add unknowns
        known["lateral"] = [j for j in known["lateral"] if j not in ready.bilinear]
    fits, engine = [], {}
    for axis, (states, ins) in present.items():
        rated = [j for j in known[axis] if j in ready.rates]  # gust rates: one lag each
        engines = [j for j in ins if j in throttle]
        powers = dict.fromkeys(rated, GUST_RATE_LAGS) | dict.fromkeys(engines, THROTTLE_LAGS)
        filtered = process_noise and axis == "longitudinal"
        # The engine's order is chosen by output error: a process-noise model fitted with
        # the wrong number of lags takes their misfit for turbulence, and no order then
        # explains more than another.
        fitted = fit_axis(
            sp,
            name=axis,
            states=states,
            inputs=[*ins, *known[axis]],
            lagged=engines + rated,
            experiments=experiments,
            controls=ins,
            powers=powers,
            process_noise=filtered and not engines,
            synthesised=synthesised,
            still=still,
        )
        for j in engines:
            order, criterion = _engine_order(sp, fitted, j, experiments)
            engine[j] = (order, criterion)
            if order != THROTTLE_LAGS:
                fitted = fit_axis(
                    sp,
                    name=axis,
                    states=states,
                    inputs=fitted.inputs,
                    lagged=[k for k in fitted.lags if k != j or order > 0],
                    experiments=experiments,
                    controls=ins,
                    powers={**fitted.lag_powers, j: order},
                )
        if ready.curve and axis == "longitudinal":
            fitted = _curved(sp, fitted, ready.curve, ins, experiments)
        if filtered and engines:
            fitted = fit_axis(
                sp,
                name=axis,
                states=states,
                inputs=fitted.inputs,
                lagged=tuple(fitted.lags),
                experiments=experiments,
                controls=ins,
                powers=fitted.lag_powers,
                process_noise=True,
                synthesised=synthesised,
                still=still,
            )
        fits.append(fitted)
    return fits, engine


def _curved(
    sp: Transforms, fitted: AxisFit, curve: Sequence[int], controls: list[int], experiments: int
) -> AxisFit:
    """`fitted` with the throttles' squares (`curve`: their known input columns) as inputs
    where the data ask for them: their gains, fitted with `fitted`'s weights, lower its
    weighted cost J by more than their number (the Akaike criterion 2 J + 2 k, as the
    engine's order is chosen). A throttle whose thrust does not bend within the record's
    deflections, or whose bend the turbulence hides, adds free gains that only fit noise: on
    JSBSim's Cessna 182 in light turbulence they took a seed's phugoid from 8 to 12 % off
    (benchmarks/README.md)."""
    before, after, _ = added_costs(sp, fitted, other_inputs=curve, experiments=experiments)
    if before - after <= len(curve):  # one gain each, on V̇ (prepare)
        return fitted
    return fit_axis(
        sp,
        name=fitted.name,
        states=fitted.states,
        inputs=[*fitted.inputs, *curve],
        lagged=tuple(fitted.lags),
        experiments=experiments,
        controls=controls,
        powers=fitted.lag_powers,
    )


def _engine_order(
    sp: Transforms, fitted: AxisFit, column: int, experiments: int
) -> tuple[int, dict[int, float]]:
    """How many lags the data give the engine between `column` (a throttle) and the thrust:
    each of ENGINE_ORDERS fitted from `fitted` with its weights, the Akaike criterion
    2 J + 2 k (J: the weighted cost, a complex residual's −log-likelihood; k: 1 for the lags'
    time constant) picks one, the fewer lags on a tie. Returns the order and each order's
    criterion less the chosen one's."""
    now = fitted.lag_powers.get(column, THROTTLE_LAGS)
    aic = {}
    for order in ENGINE_ORDERS:
        if order == now:
            cost = fitted.cost
        else:
            cost, _ = lag_order_cost(
                sp, fitted, column=column, order=order, experiments=experiments
            )
        aic[order] = 2.0 * cost + 2.0 * (order > 0)
    best = min(aic, key=lambda k: (round(aic[k], 9), k))
    return best, {k: float(v - aic[best]) for k, v in aic.items()}


def _process_share(fit: AxisFit, outputs: tuple[str, ...]) -> dict[str, float]:
    """Each output's share of its residual power the fit's process noise explains (none
    without it), over the fit's bins."""
    if fit.noise is None:
        return {}
    share = fit.noise.share(fit.A)
    return {outputs[c]: float(v) for c, v in zip(fit.states, share, strict=True)}


def _coupled(
    sp: Transforms,
    fits: list[AxisFit],
    ready: Prepared,
    engine: dict[int, tuple[int, dict[int, float]]],
    *,
    r: int,
    experiments: int,
) -> tuple[list[AxisFit], dict[str, Coupling], str]:
    """Both axes with what couples them joined (module docstring), what each test found, and
    the model's structure in words. The other axis's measured states are known inputs: their
    gains are A's coupling blocks."""
    width = sp.U.shape[1]
    augmented = augment(sp)
    own = [[j for j in f.inputs if j < r] for f in fits]  # each axis's own controls
    found: dict[str, Coupling] = {}
    fits = list(fits)
    for k, fitted in enumerate(fits):
        other = own[1 - k]
        cross = [width + c for c in fits[1 - k].states if c not in ready.attitude]
        by_inputs, moved_inputs = coupling(sp, fitted, other_inputs=other, experiments=experiments)
        by_states, moved_states = coupling(
            augmented, fitted, other_inputs=cross, experiments=experiments
        )
        found[fitted.name] = Coupling(
            by_inputs=by_inputs,
            by_states=by_states,
            response_by_inputs=moved_inputs,
            response_by_states=moved_states,
        )
        ins, controls, lags = list(fitted.inputs), list(fitted.controls), list(fitted.lags)
        powers = dict(fitted.lag_powers)
        if moved_inputs > COUPLED and fitted.name == "lateral":
            # The throttle reaches the lateral axis as it reaches the longitudinal one:
            # through the engine's lags (its torque and slipstream follow the thrust).
            thrust = [j for j in other if j in engine]
            ins, controls = ins + thrust, controls + thrust
            lags += [j for j in thrust if engine[j][0] > 0]
            powers |= {j: engine[j][0] for j in thrust if engine[j][0] > 0}
        if moved_states > COUPLED:
            ins += cross
        if ins != list(fitted.inputs):
            fits[k] = fit_axis(
                augmented,
                name=fitted.name,
                states=fitted.states,
                inputs=ins,
                lagged=tuple(lags),
                experiments=experiments,
                controls=controls,
                powers=powers,
                process_noise=fitted.noise is not None,
                synthesised=fitted.noise.direct if fitted.noise is not None else (),
                still=fitted.still,
            )
    joined = []
    for k, f in enumerate(fits):
        by = ["the throttle"] if any(j < r and j not in own[k] for j in f.inputs) else []
        by += ["the other axis's states"] if any(j >= width for j in f.inputs) else []
        if by:
            joined.append(f"{f.name} coupled by {' and '.join(by)}")
    return fits, found, "decoupled" + (f", {' and '.join(joined)}" if joined else "")


def _structure(
    sp: Transforms,
    fits: list[AxisFit],
    inputs: tuple[str, ...],
    outputs: tuple[str, ...],
    *,
    experiments: int,
) -> tuple[list[AxisFit], str]:
    """Each axis with the entries its record does not determine fixed at zero (`selected`,
    `settings.select`), and the note that lists them (ẋ_row ← column)."""
    width, r = sp.U.shape[1], len(inputs)
    chosen, listed = [], []
    for f in fits:
        source = augment(sp) if any(j >= width for j in f.inputs) else sp
        f = selected(source, f, controls=r, experiments=experiments)
        chosen.append(f)
        for matrix, i, j in f.zeros:
            by = outputs[f.states[j]] if matrix == "A" else inputs[f.inputs[j]]
            listed.append(f"{outputs[f.states[i]]}' ← {by}")
    if not listed:
        return chosen, "model structure selected: every derivative determined (none fixed)"
    return chosen, (
        f"model structure selected: {len(listed)} derivative(s) fixed at 0, their standard "
        f"error above their value: {', '.join(listed)}"
    )


def augment(sp: Transforms) -> Transforms:
    """`sp` with the measured states appended to its inputs (after its own columns): the
    inputs of an axis coupled by the other axis's states."""
    # The measured states as inputs: none is ever a control whose excited bins are chosen.
    floors = None if sp.noise is None else np.hstack([sp.noise, np.zeros(sp.Y.shape)])
    return replace(sp, U=np.hstack([sp.U, sp.Y]), noise=floors)


def _report(
    sp: Transforms,
    fits: list[AxisFit],
    ready: Prepared,
    couplings: dict[str, Coupling],
    structure: str,
    engine: dict[int, tuple[int, dict[int, float]]],
    *,
    inputs: tuple[str, ...],
    outputs: tuple[str, ...],
    measured: Sequence[int] = (),
    predicted: dict[str, Predicted] | None = None,
) -> AircraftDocument:
    """What the method found: band, axes, coupling, engine lags, wind and known gains."""
    predicted = predicted or {}
    taus = {j: tau for f in fits for j, tau in f.lags.items()}
    r, width = len(inputs), sp.U.shape[1]
    names = [*inputs, *ready.extra_names]
    drag = None
    for column, row in ready.rows.items():  # sideslip drag: V̇ = … + X_β² β²
        if column in ready.curve:  # the throttle's square acts on V̇ alone too (below)
            continue
        for f in fits:
            gain = known_gain(f, column, row)
            if gain is not None:
                drag = Gain(gain=gain[0], std=gain[1])
    products: dict[str, dict[str, Gain]] = {}
    curve: dict[str, dict[str, Gain]] = {}
    # The lateral derivatives' change with α, and the throttle's curvature (its one row).
    for columns, found in ((ready.bilinear, products), (ready.curve, curve)):
        for column in columns:
            for f in fits:
                for row in f.states:
                    gain = known_gain(f, column, row)
                    if gain is None or row in ready.attitude:
                        continue
                    if column in ready.rows and row != ready.rows[column]:
                        continue
                    found.setdefault(names[column], {})[outputs[row]] = Gain(
                        gain=gain[0], std=gain[1]
                    )
    return AircraftDocument(
        band_hz=(float(sp.band_hz[0]), float(sp.band_hz[1])),
        bins=int(sp.s.size),
        kinematics=ready.known is not None,
        wind=Wind(
            measured=bool(ready.gusts),
            gust_rms=ready.gust_rms,
            undetected=list(ready.undetected),
            air_angles="synthesised" if ready.air_angles else "vanes",
            synthesised=[_air_angles(a) for a in ready.air_angles],
        ),
        model=structure,
        axes=[
            AxisDocument(
                name=f.name,
                outputs=[outputs[i] for i in f.states],
                inputs=[names[j] if j < width else outputs[j - width] for j in f.inputs],
                iterations=f.iterations,
                converged=f.converged,
                estimator=(
                    "prediction error"
                    if f.name in predicted
                    else "output error"
                    if f.noise is None
                    else "filter error"
                ),
                process_share=_process_share(f, outputs),
                process_poles={outputs[c]: pole for c, pole in predicted[f.name].poles.items()}
                if f.name in predicted
                else {},
                tic_excited={
                    outputs[i]: float(t) for i, t in zip(f.states, f.tic_excited, strict=True)
                },
                noise_misfit={
                    outputs[i]: NoiseMisfit(ratio=row[0], low=row[1], high=row[2])
                    for i, row in zip(f.states, predicted[f.name].misfit.tolist(), strict=True)
                }
                if f.name in predicted
                else {},
            )
            for f in fits
        ],
        coupling=couplings,
        engine_lag_s={
            f.name: {inputs[j]: tau for j, tau in f.lags.items() if j < r}
            for f in fits
            if any(j < r for j in f.lags)
        },
        engine=[
            Engine(
                input=inputs[j],
                lags=order,
                time_constant_s=taus.get(j) if order else None,
                criterion=criterion,
                measured=j in measured,
            )
            for j, (order, criterion) in engine.items()
        ],
        sideslip_drag=drag,
        alpha_products=products,
        throttle_curve=curve,
        density_climb_mps=list(ready.climbs),
    )


def _air_angles(synthesised: Synthesised) -> AirAngles:
    """One record's synthesised α and β, as the document reports them."""
    return AirAngles(
        wind_mps=synthesised.wind,
        drift_mps=synthesised.drift,
        sideslip_rad=synthesised.sideslip,
        airspeed_rms_mps=synthesised.airspeed_rms,
        heading_span_deg=float(np.degrees(synthesised.heading_span)),
    )


def _modes(
    model: StateSpace,
    fits: list[AxisFit],
    refinement: Refinement,
    batch: list[Experiment],
    dt: float,
    *,
    r: int,
    output_roles: Sequence[str | None],
) -> tuple[list[Mode], list[str]]:
    """Modes of the aircraft states alone (the lag states are the engine's, equal poles
    with no modal decomposition), with each lagged input at its steady gain, their Cramér–Rao
    1-σ and their names; and the poles left out of them (`modal.left_out`)."""
    m, n = model.C.shape[0], model.A.shape[0]
    Bm = model.B[:m].copy()
    for f in fits:
        for c, j in enumerate(f.inputs):
            if j < r:  # a control (the gusts are not the model's inputs)
                Bm[list(f.states), j] = f.B[:, c]
    states_only = StateSpace(model.A[:m, :m], Bm, np.eye(m), np.zeros((m, r)))
    index = np.arange(n * n).reshape(n, n)[:m, :m].ravel()
    for_modes = replace(
        refinement,
        continuous=states_only,
        covariance=refinement.covariance[np.ix_(index, index)],
        spread=_within(refinement.spread, index),
    )
    Am, Bmd = discretize(states_only.A, states_only.B, dt)
    input_rms, output_rms = channel_rms(batch)
    modes = modal_analysis(
        Am, Bmd, states_only.C, dt, input_scale=input_rms, output_scale=output_rms
    )
    modes = with_uncertainty(modes, for_modes)
    if any(role is not None for role in output_roles):
        axes = _mode_axes(modes, states_only.A, fits)
        modes = name_modes(modes, output_roles, min_msv=0.0, axes=axes)
    return modes, left_out(Am, dt, states_only.A)


def _fit_with_known(
    model: StateSpace,
    fits: Sequence[AxisFit],
    ready: Prepared,
    batch: Sequence[Experiment],
    *,
    r: int,
    dt: float,
    hold: str,
) -> FitInTime:
    """The model's time-domain fit driven by everything the record measured that it was
    fitted with: its controls, and the known inputs (the measured gusts, their rates through
    their fitted lags, sideslip drag, the α products, the throttle's square) and the
    kinematics' nonlinear rest, with
    their fitted gains. The model's outputs are the inertial states where the wind is
    measured; each prediction goes back to the recorded channel (less the same gust the
    record's inertial output adds), so residuals and TIC are on what was recorded."""
    n, m = model.A.shape[0], model.C.shape[0]
    width = ready.batch[0].u.shape[1]
    known = width - r
    Bk = np.zeros((n, known))
    lags: dict[int, tuple[float, int]] = {}
    for f in fits:
        for c, j in enumerate(f.inputs):
            if r <= j < width:
                Bk[list(f.states), j - r] = f.B[:, c]
                if j in f.lags:
                    lags[j - r] = (f.lags[j], f.lag_powers.get(j, THROTTLE_LAGS))
    forcing = np.vstack([np.eye(m), np.zeros((n - m, m))])
    B = np.hstack([model.B, Bk, forcing])
    extended = discretize_hold(model.A, B, model.C, np.zeros((m, B.shape[1])), dt, hold)
    start = max(1, round(INITIAL_S / dt))
    runs, initial = [], []
    for raw, prepared, kinematic in zip(batch, ready.batch, ready.known, strict=True):
        extra = np.array(prepared.u[:, r:], dtype=float)
        for k, (tau, order) in lags.items():
            for _ in range(order):
                extra[:, k] = lagged(extra[:, k], tau, dt)
        u = np.hstack([raw.u, extra, kinematic])
        runs.append(Experiment(u, prepared.y))
        initial.append(np.concatenate([prepared.y[:start].mean(axis=0), np.zeros(n - m)]))
    inertial = fit(extended, runs, initial)
    if not all(np.all(np.isfinite(p)) for p in inertial.predictions):
        return inertial  # diverged: TIC 1 on every output, as bad a fit as TIC can say
    predictions = tuple(
        p - (run.y - raw.y) for p, run, raw in zip(inertial.predictions, runs, batch, strict=True)
    )
    return FitInTime(
        predictions=predictions,
        initial_states=inertial.initial_states,
        tic=theil(np.vstack(predictions), np.vstack([e.y for e in batch])),
    )


def _mode_axes(modes: Sequence[Mode], A: np.ndarray, fits: Sequence[AxisFit]) -> list[str | None]:
    """Each mode's axis by continuity from the axes' own models: the eigenvalues of A with the
    blocks that couple the axes zeroed are each an axis's, and the model's eigenvalues are
    matched one to one to them (least total distance), as the coupling grows from nothing to
    what was fitted. None for every mode with one axis."""
    if len(fits) != 2:
        return [None] * len(modes)
    own = []
    for f in fits:
        states = list(f.states)
        for pole in np.linalg.eigvals(A[np.ix_(states, states)]):
            if pole.imag >= -1e-9 * max(abs(pole), 1.0):
                own.append((complex(pole), "lon" if f.name == "longitudinal" else "lat"))
    if len(own) != len(modes):
        return [None] * len(modes)
    cost = np.array([[abs(m.eigenvalue - pole) for pole, _ in own] for m in modes])
    rows, cols = scipy.optimize.linear_sum_assignment(cost)
    axes: list[str | None] = [None] * len(modes)
    for i, j in zip(rows, cols, strict=True):
        axes[i] = own[j][1]
    return axes


def _poorly_resolved(
    modes: Sequence[Mode],
    orders: Sequence[SecondOrder],
    sp: Transforms,
    present: dict[str, tuple[list[int], list[int]]],
) -> list[str]:
    """A named mode whose Cramér–Rao σ(ωn) exceeds RESOLVED of its ωn, said by name, with the
    share of its axis's controls' power the record put within a factor 2 of ωn: why the
    record resolves it poorly, the manoeuvre's fault or the noise's. A mode of two real poles
    is judged once, as the one mode it is (`orders`): near a double root its poles alone are
    ill-determined where its ωn is not."""
    pairs = {o.name: o for o in orders if o.frequency_std is not None}
    judged = [
        (m.name, m.frequency, m.uncertainty.frequency, "")
        for m in modes
        if m.name and m.name not in pairs and m.uncertainty is not None and m.frequency > 0
    ]
    judged += [
        (o.name, o.frequency, o.frequency_std, " (as one mode of two real poles)")
        for o in pairs.values()
    ]
    notes = []
    for name, frequency, sigma, how in judged:
        spread = sigma / frequency
        if not spread > RESOLVED:
            continue
        axis = "lateral" if name in LATERAL_MODES else "longitudinal"
        controls = present.get(axis, ([], []))[1]
        power = np.sum(np.abs(sp.U[:, controls]) ** 2, axis=1) if controls else np.zeros(0)
        w = np.abs(sp.s)
        near = (w >= frequency / 2) & (w <= 2 * frequency)
        share = float(power[near].sum() / power.sum()) if power.size and power.sum() > 0 else 0
        notes.append(
            f"{name} poorly resolved by this record: σ(ωn) {spread:.0%} of its "
            f"{frequency:.3g} rad/s{how}; the {axis} controls put {share:.1%} of their power "
            "within a factor 2 of it"
            + (f" (the analysed band starts at {sp.band_hz[0]:.3g} Hz)" if not near.any() else "")
        )
    return notes


def _longer_than_the_record(modes: Sequence[Mode], span: float) -> list[str]:
    """A named oscillation whose period is longer than the longest record, said by name: the
    record holds less than a cycle of it, and its ωn and ζ rest on the model's structure more
    than on the data, whatever its σ says: a repeat of the manoeuvre can give another."""
    notes = []
    for m in modes:
        damped = abs(m.eigenvalue.imag)
        if not m.name or damped <= 0 or 2 * np.pi / damped <= span:
            continue
        period = 2 * np.pi / damped
        notes.append(
            f"{m.name} not determined by this record: its period of {period:.3g} s is longer "
            f"than the record ({span:.3g} s), less than one cycle of it; its ωn and ζ rest on "
            "the model's structure, and a repeat manoeuvre can give others (a record of two "
            "periods or more determines it)"
        )
    return notes


def _sampled(model: StateSpace, dt: float, hold: str, outputs: Sequence[str]) -> StateSpace:
    """The whole-aircraft model sampled at dt. An output with no response above its noise (a
    dead sensor's noise alone) gets gains of 10¹⁰ in the other equations and the model an
    unstable pole thousands or millions of 1/s fast, which no sampling shows (or survives): a
    clear failure naming that output, not an overflow or a divergence deep in the modal
    analysis. An aircraft's own unstable modes (a spiral) grow by far less than e per sample."""
    with np.errstate(all="ignore"):
        discrete = discretize_hold(model.A, model.B, model.C, model.D, dt, hold)
    finite = all(np.all(np.isfinite(x)) for x in (discrete.A, discrete.B))
    eigenvalues = np.linalg.eigvals(model.A) if np.all(np.isfinite(model.A)) else np.array([np.inf])
    if finite and np.max(eigenvalues.real) * dt <= 1.0:
        return discrete
    pole = np.max(np.abs(eigenvalues))
    m = len(outputs)
    gains = np.max(np.abs(model.A[:m, :m]), axis=0)  # what each output's changes are worth
    where = outputs[int(np.argmax(gains))]
    raise IdentificationFailed(
        f"the identified model has a pole of {pole:.3g} 1/s, far beyond what sampling at "
        f"{dt:g} s can show, and gains up to {gains.max():.3g} on {where}: an output with no "
        f"response above its noise (a dead sensor) does that; check {where}'s signal or "
        "leave it out of the outputs"
    )


def _within(spread, index: np.ndarray) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """`Refinement.spread` for the entries `index` of its vector, renumbered in their order
    (the columns elsewhere dropped)."""
    where = {int(k): i for i, k in enumerate(index)}
    out = []
    for G, pos in spread:
        keep = np.array([int(k) in where for k in pos], dtype=bool)
        if keep.any():
            out.append((G[:, :, keep], np.array([where[int(k)] for k in pos[keep]])))
    return tuple(out)


def assemble(
    fits: Sequence[AxisFit], *, r: int, m: int, states_of: dict[int, int] | None = None
) -> tuple[StateSpace, np.ndarray, tuple[tuple[np.ndarray, np.ndarray], ...]]:
    """One continuous model (states: the m outputs, then the lag states of each lagged input
    of each axis, its number of lags), the covariance of [vec Ac, vec Bc, vec C, vec D]
    (zero where fixed), and each axis's bins' shares of a contrast's variance with the
    positions in that vector of their columns (`Refinement.spread`). `states_of`: an input
    column that is another axis's state → that state."""
    states_of = states_of or {}
    lagged = [(f, j) for f in fits for j in f.lags if j < r]  # the gust rates' are no state
    n = m + sum(f.lag_powers.get(j, THROTTLE_LAGS) for f, j in lagged)
    A, B = np.zeros((n, n)), np.zeros((n, r))
    index_a = np.arange(n * n).reshape(n, n)
    index_b = n * n + np.arange(n * r).reshape(n, r)
    size = n * n + n * r + m * n + m * r
    cov = np.zeros((size, size))
    spreads = []
    extra = m
    for f in fits:
        st = list(f.states)
        A[np.ix_(st, st)] = f.A
        where_b = np.full((len(st), len(f.inputs)), -1)  # where each B entry went
        for c, j in enumerate(f.inputs):
            if j >= r and j in states_of:  # another axis's state: a coupling of A
                A[st, states_of[j]] = f.B[:, c]
                where_b[:, c] = index_a[st, states_of[j]]
                continue
            if j >= r:  # a measured gust: it drove the fit, it is not an input of the model
                continue
            if j in f.lags:  # u → lag → lag → the axis: B's column acts on the last lag state
                tau, order = f.lags[j], f.lag_powers.get(j, THROTTLE_LAGS)
                chain = list(range(extra, extra + order))
                B[chain[0], j] = 1.0 / tau
                for a, b in itertools.pairwise(chain):
                    A[b, a] = 1.0 / tau
                for k in chain:
                    A[k, k] = -1.0 / tau
                A[st, chain[-1]] = f.B[:, c]
                where_b[:, c] = index_a[st, chain[-1]]
                extra += order
            else:
                B[st, j] = f.B[:, c]
                where_b[:, c] = index_b[st, j]
        pos = np.concatenate([index_a[np.ix_(st, st)].ravel(), where_b.ravel()])
        kept = pos >= 0
        cov[np.ix_(pos[kept], pos[kept])] = f.covariance[np.ix_(kept, kept)]
        if f.spread is not None:
            spreads.append((f.spread[:, :, kept], pos[kept]))
    C = np.hstack([np.eye(m), np.zeros((m, n - m))])
    return StateSpace(A, B, C, np.zeros((m, r))), cov, tuple(spreads)
