"""`sysid identify`: CSV records in, one batch identification out."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from agent.analysis import units as unit_rules
from agent.analysis.records import (
    COMMANDS,
    Record,
    RecordError,
    read_record,
    segments,
    select,
    trim_values,
)
from agent.config import IdentificationConfig as IdentConfig
from agent.ident import Experiment, Identification, Settings, identify
from agent.ident.aircraft.airangles import Sources, fill
from agent.ident.convert import StateSpace
from agent.ident.document import ResultDocument, ValidationDocument
from agent.ident.fit import fit, validation_fit
from agent.ident.job import prepared

# Two records are one batch only if their sample times agree this closely.
DT_TOLERANCE = 0.01


@dataclass(frozen=True)
class Request:
    """What to identify, as given on the command line (already merged with config)."""

    paths: tuple[Path, ...]
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    start: float | None = None
    end: float | None = None
    trim_seconds: float = 0.5  # 0: no trim removal
    # The INS heading and velocity columns (NAVIGATION_ROLES order), used where a record has
    # them all: the aircraft method measures the wind with them, as onboard.
    navigation: tuple[str, ...] = ()
    # Where α and β come from (vanes, or synthesised from the INS and an estimated wind where
    # a record has no vanes'); None: as recorded, never synthesised.
    air_angles: Sources | None = None
    # Column → its unit (`--units`), over what the header declares (agent.analysis.units).
    units: Mapping[str, str] = field(default_factory=dict)
    # Column → its role (the config's channel names): what unit it is identified in.
    roles: Mapping[str, str] = field(default_factory=dict)
    # Role → column of the aircraft states not among the outputs (a lateral run's airspeed and
    # θ), read where a record has them: the whole-aircraft method's kinematics
    # (`Experiment.flight`).
    flight: Mapping[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Outcome:
    """The identification with what it was computed from."""

    result: Identification
    trim: list[dict[str, float]]  # per experiment (a record, or its segment), in order
    records: int  # experiments: a record split at its gaps counts each segment
    samples: int
    tic_validation: np.ndarray | None = None  # own records, x(0) and biases estimated
    validation: ValidationDocument | None = None  # held-out records (--validate)

    def document(self) -> ResultDocument:
        """The result as `sysid identify --json` prints it, with its validation scores."""
        doc = self.result.document(self.trim)
        update: dict = {"validation": self.validation}
        if self.tic_validation is not None:
            scores = map(float, self.tic_validation)
            update["tic_validation"] = dict(zip(doc.outputs, scores, strict=True))
        return doc.model_copy(update=update)


def parse_trim(text: str) -> float:
    """`first:SECONDS` → SECONDS, `none` → 0 (no trim removal); ValueError otherwise."""
    if text.strip().lower() == "none":
        return 0.0
    kind, _, value = text.partition(":")
    if kind.strip().lower() != "first" or not value:
        raise ValueError(f"--trim must be first:SECONDS or none, got {text!r}")
    seconds = float(value)
    if not seconds > 0:
        raise ValueError(f"--trim first:SECONDS needs SECONDS > 0, got {value}")
    return seconds


@dataclass(frozen=True)
class Loaded:
    """The request's experiments: one per record, or per uniform segment of a record with
    gaps (`records.segments`), in order."""

    experiments: list[Experiment]
    dt: float
    trim: list[dict[str, float]]  # per experiment
    samples: int
    notes: tuple[str, ...]  # gaps split, segments left out, air angles synthesised
    commands: frozenset[str] = frozenset()  # columns every record declares commands


def load_experiments(request: Request) -> Loaded:
    """Read, select (the window first: a gap outside it is no concern), split at gaps and
    de-trim every record; all must share one sample time. Each experiment carries the trim
    removed from its outputs (its operating point) and, where the record has every
    `navigation` column, the navigation: the aircraft method's kinematics and wind."""
    overlap = set(request.inputs) & set(request.outputs)
    if overlap:
        raise RecordError(f"column(s) {', '.join(sorted(overlap))} are both input and output")
    names = list(request.inputs) + list(request.outputs)
    sources = request.air_angles
    synthesisable = sources is not None and sources.mode != "vanes"
    angles = {sources.alpha, sources.beta} & set(request.outputs) if synthesisable else set()
    flight = {r: n for r, n in request.flight.items() if n not in names}
    optional = (*request.navigation, *(sources.needed if angles else ()), *flight.values())
    records: list[Record] = []
    air: list = []
    notes: list[str] = []
    for path in request.paths:
        try:
            whole = read_record(path, names, optional=optional, absent=tuple(angles))
        except RecordError as exc:
            raise RecordError(str(exc) + _without(exc.missing, request)) from None
        whole, read = _in_units(whole, request)
        notes += read
        parts, split = segments(select(whole, request.start, request.end))
        notes += split
        for record in parts:
            made = None
            if angles:
                try:
                    columns, made = fill(record.columns, request.outputs, sources)
                except ValueError as exc:
                    raise RecordError(f"{path}: {exc}") from None
                record = replace(record, columns=columns)
                if made is not None:
                    notes.append(f"{path.name}: {made.note()}")
            records.append(record)
            air.append(made)
    dt = records[0].dt
    for rec in records[1:]:
        if abs(rec.dt - dt) > DT_TOLERANCE * dt:
            raise RecordError(
                f"{rec.path} is sampled every {rec.dt:.6g} s but {records[0].path} every "
                f"{dt:.6g} s; a batch needs one sample rate"
            )
    experiments, trim = [], []
    for rec, made in zip(records, air, strict=True):
        offsets = (
            trim_values(rec, names, request.trim_seconds)
            if request.trim_seconds > 0
            else dict.fromkeys(names, 0.0)
        )
        trim.append(offsets)
        u = rec.matrix(request.inputs) - [offsets[n] for n in request.inputs]
        operating_point = np.array([offsets[n] for n in request.outputs])
        y = rec.matrix(request.outputs) - operating_point
        navigation = None
        if request.navigation and all(n in rec.columns for n in request.navigation):
            navigation = rec.matrix(request.navigation)
        states = {r: rec.columns[n] for r, n in flight.items() if n in rec.columns}
        experiments.append(
            Experiment(
                u=u,
                y=y,
                operating_point=operating_point,
                navigation=navigation,
                air_angles=made,
                flight=states or None,
            )
        )
    return Loaded(
        experiments=experiments,
        dt=dt,
        trim=trim,
        samples=sum(r.time.size for r in records),
        notes=tuple(dict.fromkeys(notes)),
        commands=frozenset.intersection(*(r.commands for r in records)),
    )


def _without(missing: Sequence[str], request: Request) -> str:
    """The options that identify the record without the inputs it lacks (a longitudinal
    record of a glider, or of an aircraft whose throttle was not logged, under --axes
    longitudinal), when only inputs are missing and some remain; else nothing."""
    rest = [n for n in request.inputs if n not in missing]
    if not missing or not rest or any(n not in request.inputs for n in missing):
        return ""
    return (
        f"; without {', '.join(missing)}: --inputs {','.join(rest)} "
        f"--outputs {','.join(request.outputs)}"
    )


def _in_units(record: Record, request: Request) -> tuple[Record, list[str]]:
    """The record's columns in the units their roles are identified in: each declared unit
    (`--units` over the header's) converted, each undeclared column checked for values no
    flight reaches in its role's unit (agent.analysis.units); with a note of the units read."""
    declared = {**record.units, **request.units}
    columns = dict(record.columns)
    read = []
    for name, values in record.columns.items():
        role = request.roles.get(name)
        try:
            if name in declared:
                columns[name], what = unit_rules.converted(values, name, declared[name], role)
                read.append(what)
            elif (why := unit_rules.implausible(values, name, role)) is not None:
                raise RecordError(f"{record.path}: {why}")
        except unit_rules.UnitError as exc:
            raise RecordError(f"{record.path}: {exc}") from None
    notes = [f"{record.path.name}: units: {'; '.join(read)}"] if read else []
    return replace(record, columns=columns), notes


def scores(
    doc: ResultDocument, experiments: Sequence[Experiment], dt: float, request: Request
) -> tuple[np.ndarray, np.ndarray]:
    """The model's TIC per output on `experiments` (the request's columns, sampled every
    `dt`, preprocessed as its own data were): from each record's trim (x(0) = 0, no bias),
    and with its initial state and a bias on each output estimated, as a validation scores it
    (`validation_fit`). The model's own inputs and outputs only: a control the record left at
    trim, or an axis it did not move, is not in the model."""
    ins = [list(request.inputs).index(n) for n in doc.inputs]
    outs = [list(request.outputs).index(n) for n in doc.outputs]
    data = tuple((e.u[:, ins], e.y[:, outs]) for e in experiments)
    batch, _ = prepared(doc.preprocessing, dt, data)
    model = StateSpace(*(np.asarray(m, dtype=float) for m in (doc.A, doc.B, doc.C, doc.D)))
    start = [np.zeros(model.A.shape[0])] * len(batch)
    return fit(model, batch, initial_states=start).tic, validation_fit(model, batch).tic


def held_out(
    request: Request, doc: ResultDocument, dt: float, paths: Sequence[Path]
) -> ValidationDocument:
    """The model on held-out records (`--validate`), read as the request's own."""
    loaded = load_experiments(replace(request, paths=tuple(paths)))
    if abs(loaded.dt - dt) > DT_TOLERANCE * dt:
        raise RecordError(
            f"{paths[0]} is sampled every {loaded.dt:.6g} s but the model's records every "
            f"{dt:.6g} s; a validation record needs their sample rate"
        )
    from_trim, tic = scores(doc, loaded.experiments, dt, request)
    names = doc.outputs
    return ValidationDocument(
        files=[str(p) for p in paths],
        tic=dict(zip(names, map(float, tic), strict=True)),
        tic_avg=float(np.mean(tic)),
        tic_from_trim=dict(zip(names, map(float, from_trim), strict=True)),
        tic_from_trim_avg=float(np.mean(from_trim)),
    )


def run(
    request: Request, config: IdentConfig, settings: Settings, validate: Sequence[Path] = ()
) -> Outcome:
    """Identify the request's records as one batch; `validate`: held-out records the model
    is then scored on (`held_out`)."""
    loaded = load_experiments(request)
    experiments, dt, trim, samples, notes = (
        loaded.experiments,
        loaded.dt,
        loaded.trim,
        loaded.samples,
        loaded.notes,
    )
    if settings.held_inputs is None and set(request.inputs) <= loaded.commands:
        # What the columns are, where the record says: servo outputs, held between updates.
        settings = replace(settings, held_inputs=True)
        notes = (
            f"inputs taken as commands held between samples: the record declares "
            f"{', '.join(request.inputs)} commands ('{COMMANDS} …', servo outputs)",
            *notes,
        )
    roles: Sequence[str | None] = [config.channels.role_of(n) for n in request.outputs]
    result = identify(
        experiments,
        dt,
        input_names=request.inputs,
        output_names=request.outputs,
        output_roles=roles,
        input_roles=[config.channels.role_of(n) for n in request.inputs],
        settings=settings,
    )
    result = replace(result, warnings=(*notes, *result.warnings))
    doc = result.document(trim)
    _, own = scores(doc, experiments, dt, request)
    validation = held_out(request, doc, dt, validate) if validate else None
    return Outcome(
        result=result,
        trim=trim,
        records=len(experiments),
        samples=samples,
        tic_validation=own,
        validation=validation,
    )
