"""One identification as a job for a worker process: a window of recorded data in, the result's
document (agent.ident.document) or a failure with its reason out. Pure functions of picklable
arguments, so the agent's event loop only hands them to a pre-started process and never waits
on them; the process itself (its priority, its life tied to the agent's) is
agent.runtime.worker's.
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from agent.channels import AXIS_SETS
from agent.ident import Experiment, Settings, frf, identify
from agent.ident.aircraft.airangles import Sources, fill
from agent.ident.document import PreprocessingDocument, ResultDocument
from agent.ident.errors import DataError, IdentificationFailed
from agent.ident.fit import fit
from agent.ident.preprocess import preprocess

# Gaps (NaN) up to this long are bridged linearly; longer ones fail the job with the reason.
MAX_GAP_S = 0.1


@dataclass(frozen=True, kw_only=True)
class Job:
    model_id: str
    axes: str
    record_dt: float
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    roles: tuple[str, ...]
    experiments: tuple[tuple[np.ndarray, np.ndarray], ...]
    settings: Settings = field(default_factory=Settings)
    window: dict[str, np.ndarray] | None = None
    """Raw recorded columns of a new excitation, made into the last experiment here, in the
    worker (bridging, edge cut, trim): numpy on the loop thread while a log is being written
    made the GIL change hands at every call and stalled the loop by 50–300 ms."""
    trim_s: float = 0.5
    navigation: tuple[str, ...] = ()
    """The INS heading and velocity channels in the window (NAVIGATION_ROLES order): the
    aircraft method measures the wind with them. A window without them is identified without."""
    contexts: tuple[tuple, ...] = ()
    """Per experiment, its operating point and navigation (`Experiment`) where they are known
    (a replayed log), for the aircraft method's kinematics and wind, and optionally third how
    its α and β were synthesised (`Experiment.air_angles`) and fourth its flight states
    (`Experiment.flight`); empty: none."""
    input_roles: tuple[str, ...] = ()
    """The inputs' roles ("" for none); empty: those of `axes`' axis set."""
    air_angles: Sources | None = None
    """Where the window's α and β come from (`agent.ident.aircraft.airangles.fill`): the
    vanes', or synthesised from the INS and an estimated wind; None: as recorded."""
    flight: tuple[tuple[str, str], ...] = ()
    """(role, channel) of the aircraft states the outputs leave out (a lateral run's airspeed
    and θ): read from the window where it has them whole, the aircraft method's kinematics
    (`Experiment.flight`)."""


def window_and_trim(values: dict[str, np.ndarray], inputs, outputs, dt: float, trim_s: float):
    """(u, y) from recorded columns — short gaps bridged, trim (the mean of the first trim_s)
    removed — and that trim by channel, the model's operating point:
    {"inputs": {name: value}, "outputs": {name: value}}. `window_navigation` gives the
    navigation over the same rows."""
    (u, y), (u0, y0) = _window(values, inputs, outputs, dt, trim_s)
    trim = {
        "inputs": dict(zip(inputs, map(float, u0), strict=True)),
        "outputs": dict(zip(outputs, map(float, y0), strict=True)),
    }
    return (u - u0, y - y0), trim


def _window(values, inputs, outputs, dt: float, trim_s: float):
    keep = _complete(values, inputs, outputs)
    u = np.column_stack([_bridge(values[n][keep], dt, n) for n in inputs])
    y = np.column_stack([_bridge(values[n][keep], dt, n) for n in outputs])
    count = max(1, round(trim_s / dt))
    return (u, y), (u[:count].mean(axis=0), y[:count].mean(axis=0))


def _complete(values, inputs, outputs) -> slice:
    """The window's rows from the first to the last where every channel to identify has data
    (at the edges a channel may have none yet, or no longer)."""
    every = np.column_stack([values[n] for n in [*inputs, *outputs]])
    complete = np.flatnonzero(np.isfinite(every).all(axis=1))
    if complete.size < 2:
        raise DataError("the window holds no complete row of the channels to identify")
    return slice(complete[0], complete[-1] + 1)


def window_navigation(values, inputs, outputs, names) -> np.ndarray | None:
    """The navigation columns `names` over the rows `window_and_trim` keeps, or None (see
    `_navigation`)."""
    return _navigation(values, names, _complete(values, inputs, outputs))


def window_flight(values, inputs, outputs, flight) -> dict[str, np.ndarray] | None:
    """The flight states (role → absolute values) over the rows `window_and_trim` keeps:
    each (role, channel) of `flight` the window has with data in every row; None for none."""
    keep = _complete(values, inputs, outputs)
    out = {}
    for role, name in flight:
        if name in values and np.isfinite(column := np.asarray(values[name][keep])).all():
            out[role] = column
    return out or None


def _navigation(values, names, keep: slice) -> np.ndarray | None:
    """The navigation columns over the rows the window kept, or None when one is missing or
    has a gap (an INS dropout: the identification goes on without the measured wind)."""
    if len(names) != 4 or not all(n in values for n in names):
        return None
    nav = np.column_stack([values[n][keep] for n in names])
    return nav if np.isfinite(nav).all() else None


def _bridge(x: np.ndarray, dt: float, name: str) -> np.ndarray:
    bad = ~np.isfinite(x)
    if not bad.any():
        return x
    edges = np.diff(np.concatenate([[0], bad.astype(int), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    longest = int(np.max(ends - starts))
    if longest * dt > MAX_GAP_S:
        raise DataError(
            f"channel {name!r} has a {longest * dt:.2f} s gap in the window "
            f"(at most {MAX_GAP_S:g} s is bridged)"
        )
    t = np.arange(x.size)
    return np.interp(t, t[~bad], x[~bad])


@dataclass(frozen=True, kw_only=True)
class Outcome:
    """What a job gives back: the identification, or why there is none."""

    model_id: str
    ok: bool
    reason: str = ""
    """Why it failed ("" when ok)."""
    axes: str = ""
    result: ResultDocument | None = None
    """The identification's document when ok."""
    experiment: tuple[np.ndarray, np.ndarray] | None = None
    """With a `window`: the experiment made of it (u, y), trim removed."""
    trim: dict | None = None
    """With a `window`: the trim removed, by channel (`window_and_trim`)."""
    fitted: object | None = None
    """Method "aircraft", one record: the axes as fitted to it (`Identification.fitted`), which
    the sizing prices other records' models on (agent.ident.aircraft.linearity)."""


def run(job: Job) -> Outcome:
    """Identify; never raises for bad data: an Outcome with ok False and the reason instead."""
    contexts = job.contexts or ((None, None),) * len(job.experiments)
    pairs = zip(job.experiments, contexts, strict=True)
    experiments = [
        Experiment(
            u,
            y,
            operating_point=c[0],
            navigation=c[1],
            air_angles=(*c, None, None)[2],
            flight=(*c, None, None)[3],
        )
        for (u, y), c in pairs
    ]
    extra: dict = {}
    made = None
    if job.window is not None:
        window = job.window
        try:
            if job.air_angles is not None:
                window, made = fill(window, job.outputs, job.air_angles)
            (u, y), trim = window_and_trim(
                window, job.inputs, job.outputs, job.record_dt, job.trim_s
            )
        except (DataError, KeyError, ValueError) as exc:
            return Outcome(
                model_id=job.model_id, ok=False, reason=f"window unusable: {exc}", axes=job.axes
            )
        extra = {"experiment": (u, y), "trim": trim}
        # Its absolute trim and navigation, for the aircraft method's kinematics and wind.
        op = np.array([trim["outputs"][n] for n in job.outputs])
        nav = window_navigation(window, job.inputs, job.outputs, job.navigation)
        states = window_flight(window, job.inputs, job.outputs, job.flight)
        experiments.append(
            Experiment(u, y, operating_point=op, navigation=nav, air_angles=made, flight=states)
        )
    try:
        result = identify(
            experiments,
            job.record_dt,
            input_names=job.inputs,
            output_names=job.outputs,
            output_roles=job.roles,
            input_roles=_input_roles(job),
            settings=job.settings,
        )
    except (DataError, IdentificationFailed, np.linalg.LinAlgError, ValueError) as exc:
        return Outcome(model_id=job.model_id, ok=False, reason=str(exc), axes=job.axes, **extra)
    notes = tuple(e.air_angles.note() for e in experiments if e.air_angles is not None)
    if notes:
        result = replace(result, warnings=(*dict.fromkeys(notes), *result.warnings))
    if len(experiments) == 1:  # a batch's fit is of several records: no one amplitude
        extra["fitted"] = result.fitted
    return Outcome(model_id=job.model_id, ok=True, axes=job.axes, result=result.document(), **extra)


def _input_roles(job: Job) -> tuple[str | None, ...] | None:
    if job.input_roles:
        return tuple(r or None for r in job.input_roles)
    return AXIS_SETS[job.axes][0] if job.axes in AXIS_SETS else None


def prepared(
    preprocessing: PreprocessingDocument,
    record_dt: float,
    experiments: tuple[tuple[np.ndarray, np.ndarray], ...],
):
    """Other data (or the model's own) preprocessed as a model's data was: (batch, prep)."""
    return preprocess(
        [Experiment(u, y) for u, y in experiments],
        record_dt,
        decimation=preprocessing.decimation,
        band_hz=preprocessing.band_hz,
        held_inputs=preprocessing.held_inputs_shifted,
        smoothing_s=preprocessing.smoothing_s,
    )


def cross_tic(
    result: ResultDocument,
    record_dt: float,
    experiments: tuple[tuple[np.ndarray, np.ndarray], ...],
    channels: tuple[Sequence[str], Sequence[str]] | None = None,
) -> float:
    """TIC_avg of an identified model (its discrete A, B, C, D) on other data, preprocessed
    as the model's own data was (thesis 5.3: TIC_jN, TIC_Nj). `channels`: the data's inputs
    and outputs, when they may not be the model's (the model's are taken from them by name;
    DataError when the data lack one)."""
    if channels is not None:
        experiments = of_result(result, *channels, experiments)
    batch, _ = prepared(result.preprocessing, record_dt, experiments)
    return fit(result.model(), batch).tic_avg


def of_result(
    result: ResultDocument,
    inputs: Sequence[str],
    outputs: Sequence[str],
    experiments: Sequence[tuple[np.ndarray, np.ndarray]],
) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """The experiments' columns (named `inputs`, `outputs`) the result's model has, in its
    order: the aircraft method leaves out what a record did not move (DataError when the
    data lack one of the model's channels)."""
    lacking = [n for n in result.inputs if n not in inputs]
    lacking += [n for n in result.outputs if n not in outputs]
    if lacking:
        raise DataError(f"the data have no {', '.join(lacking)}")
    cols_u = [list(inputs).index(n) for n in result.inputs]
    cols_y = [list(outputs).index(n) for n in result.outputs]
    return tuple((np.asarray(u)[:, cols_u], np.asarray(y)[:, cols_y]) for u, y in experiments)


def uncompared(candidate: ResultDocument, nominal: ResultDocument) -> str:
    """Why two models of one axis set cannot be judged on each other's data ("" when they
    can): one has channels the other lacks, because its record did not move them."""
    ours, theirs = {*candidate.inputs, *candidate.outputs}, {*nominal.inputs, *nominal.outputs}
    if ours == theirs:
        return ""
    parts = []
    if theirs - ours:
        parts.append(f"this run's model has no {', '.join(sorted(theirs - ours))}")
    if ours - theirs:
        parts.append(f"the nominal has no {', '.join(sorted(ours - theirs))}")
    return "; ".join(parts) + " (a record that did not move them)"


def frequency_response(
    preprocessing: PreprocessingDocument,
    record_dt: float,
    experiments: tuple[tuple[np.ndarray, np.ndarray], ...],
    input_index: int,
    output_index: int,
    points: int,
) -> dict:
    """A model's measured frequency response for one pair on its own data, preprocessed as the
    model's was (`agent.ident.frf.measured`), at most `points` of the input's excited
    frequencies (log-spaced): {averaging, segments, freq_hz, mag_db, phase_deg, coherence}."""
    batch, prep = prepared(preprocessing, record_dt, experiments)
    measured = frf.measured(batch, prep.dt)
    excited = np.flatnonzero(measured.excited(input_index))
    if excited.size > points:  # log-spaced: as many per decade
        f = np.log(measured.freqs[excited])
        wanted = np.linspace(f[0], f[-1], points)
        excited = excited[np.unique(np.abs(f[None, :] - wanted[:, None]).argmin(axis=1))]
    h = measured.H[excited, output_index, input_index]
    gamma = measured.coherence[excited, output_index, input_index]
    return {
        "averaging": measured.averaging,
        "segments": measured.segments,
        "freq_hz": [round(float(x), 5) for x in measured.freqs[excited]],
        "mag_db": [round(float(x), 2) for x in 20 * np.log10(np.abs(h))],
        "phase_deg": [round(float(x), 1) for x in np.degrees(np.angle(h))],
        "coherence": [None if not np.isfinite(g) else round(float(g), 3) for g in gamma],
    }


def warm() -> None:
    """Import and exercise the numerics once, so the first real job pays no start-up cost."""
    rng = np.random.default_rng(0)
    u = rng.normal(size=(400, 1))
    y = np.cumsum(u, axis=0) * 0.01 + rng.normal(size=(400, 1)) * 1e-3
    with contextlib.suppress(DataError, IdentificationFailed, np.linalg.LinAlgError):
        identify(Experiment(u, y), 0.02, settings=Settings(refine=False))
