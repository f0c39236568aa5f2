"""Identified models (and their data) to MATLAB .mat and JSON, and their stability and control
derivatives to CSV (`sysid export`).

Sources: the agent's result log (`NNNN_results_DATE.jsonl`: every identification of a flight),
a model store file (`models/<axes>_nominal.json` or `_previous.json`, with the data set it was
identified from, in the `.npz` beside it), or the ground console's log (`NNNN_ground_DATE.jsonl`:
the results as they came over the radio — discrete matrices only).

One MATLAB struct per model, named after its id (`lat_3` for `lat-3`; where two ids give one
name, the later ones `lat_3_2`, `lat_3_3`…), `model_ids`, a cell array of the original ids, and
`model_variables`, the struct name of each. The fields (also the JSON keys):

| field | meaning |
|---|---|
| id, axes | model id, identification type |
| dt | sample time of the discrete model (s) |
| inputs, outputs | channel names (cell arrays of strings), in matrix order |
| A, B, C, D | discrete-time model x[k+1] = A x[k] + B u[k], y[k] = C x[k] + D u[k] |
| Ac, Bc, Cc, Dc | continuous-time model (empty when the log has none) |
| coordinates | "outputs" (the states are the outputs: Ac, Bc are the derivatives) or "era" |
| Ac_std, Bc_std | Cramér–Rao standard errors of Ac, Bc in output coordinates (empty without) |
| u0, y0 | trim: the input and output values removed before identification (empty if unknown) |
| eigenvalues | continuous-time eigenvalues (complex column) |
| mode_names | aircraft mode names ('' when not named) |
| frequency_hz, damping | of each eigenvalue |
| tic, tic_avg | Theil inequality coefficient per output and average |
| u, y | (model store only) the data set: cell arrays, one matrix per experiment |

Matrices are in the model's own units: surfaces in degrees, throttle in µs, angles in rad,
rates in rad/s, airspeed in m/s, deviations from u0, y0.
"""

from __future__ import annotations

import json
import re
import zipfile
from pathlib import Path
from typing import BinaryIO, Protocol

import numpy as np
from pydantic import BaseModel, ConfigDict

from agent.analysis import derivatives
from agent.ident.document import ResultDocument
from agent.link import messages

TWO_PI = 2 * np.pi
# The longest line of a result or ground log, or model store file: one identified model
# (matrices, modes, the frequency fit) is far under a megabyte at order 100. A longer line (a
# file with no line ends: /dev/zero, a binary file) is refused at this length, not read whole;
# so is a source larger than MAX_SOURCE.
MAX_LINE = 16 << 20
MAX_SOURCE = 1 << 30


class ExportError(ValueError):
    """A source that cannot be exported; the message says which file and why."""


class Models(list):
    """The models of a source, in its order; `skipped`: the numbers of the lines that were not
    JSON (a torn last line after a power cut, or damage), which `sysid export` reports."""

    skipped: tuple[int, ...] = ()


def load_models(path: str | Path) -> Models:
    """Every model in a result log, a model store file or a ground log, as export dicts."""
    path = Path(path)
    try:
        with path.open("rb") as handle:
            if path.suffix != ".json":
                return _from_lines(path, _lines(path, handle))
            text = _bounded(path, handle.read(MAX_LINE + 1), "the file")
    except OSError as exc:
        raise ExportError(f"{path}: cannot be read ({exc.strerror or exc})") from exc
    try:
        loaded = json.loads(text)
    except ValueError as exc:
        raise ExportError(f"{path}: not JSON ({exc})") from exc
    if isinstance(loaded, dict) and "model_id" not in loaded and "A" in loaded:
        return Models([_from_identified(path, loaded)])
    try:
        stored = StoreFile.model_validate(loaded)
        model = _from_result(stored.model_id, stored.axes, stored.result, stored.the_trim())
    except (ValueError, KeyError, TypeError) as exc:
        raise ExportError(
            f"{path}: not a model store file nor a `sysid identify --json` result ({exc})"
        ) from exc
    return Models([_with_data(path, stored, model)])


def _from_identified(path: Path, loaded: dict) -> dict:
    """A `sysid identify --json` result as an export dict: its id the file's name, its axes
    `record`; the trim exported where it is one record's (a batch's records each have their
    own operating point, all kept in the result itself)."""
    try:
        result = ResultDocument.model_validate(loaded)
    except (ValueError, TypeError) as exc:
        raise ExportError(f"{path}: not a `sysid identify --json` result ({exc})") from exc
    trim = None
    if len(result.trim) == 1:
        (point,) = result.trim
        trim = Trim(
            inputs={n: point[n] for n in result.inputs},
            outputs={n: point[n] for n in result.outputs},
        )
    return _from_result(path.stem, "record", result, trim)


def _bounded(path: Path, data: bytes, what: str) -> str:
    """`data` as text, refused when longer than MAX_LINE or not UTF-8."""
    if len(data) > MAX_LINE:
        raise ExportError(
            f"{path}: {what} is longer than {MAX_LINE} bytes; give a result log, a model "
            "store file or a ground log"
        )
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ExportError(
            f"{path}: not a UTF-8 text file ({what}, byte {exc.start}: {exc.reason}); give a "
            "result log, a model store file or a ground log"
        ) from exc


def _lines(path: Path, handle):
    """(number, text) of each line, each at most MAX_LINE bytes, MAX_SOURCE in all."""
    total, number = 0, 0
    while data := handle.readline(MAX_LINE + 1):
        number += 1
        total += len(data)
        if total > MAX_SOURCE:
            raise ExportError(f"{path}: larger than {MAX_SOURCE} bytes; not a log of results")
        yield number, _bounded(path, data, f"line {number}")


class Trim(BaseModel):
    """The trim removed before identification, by channel (the agent's `window_and_trim`)."""

    model_config = ConfigDict(frozen=True)
    inputs: dict[str, float]
    outputs: dict[str, float]


class ResultLine(BaseModel):
    """A line of the agent's result log: one identification and what it was made of."""

    model_config = ConfigDict(frozen=True, extra="ignore")  # window, suggestion: not exported
    model_id: str
    axes: str
    result: ResultDocument
    trim: Trim | None = None


class _Earlier(BaseModel):
    """Where a model store file written before kept its trim."""

    model_config = ConfigDict(frozen=True, extra="ignore")
    trim: Trim | None = None


class StoreFile(BaseModel):
    """A model store file (agent.models.ModelStore): its data set is in the .npz beside it,
    `count` experiments."""

    model_config = ConfigDict(frozen=True, extra="ignore")
    model_id: str
    axes: str
    result: ResultDocument
    count: int | None = None
    trim: Trim | None = None
    extra: _Earlier | None = None

    def the_trim(self) -> Trim | None:
        if self.trim is not None or self.extra is None:
            return self.trim
        return self.extra.trim


def _from_lines(path: Path, lines) -> Models:
    """The models of a result log or a ground log, one JSON object a line."""
    models, skipped = Models(), []
    for number, line in lines:
        if not line.strip():
            continue
        try:
            record = json.loads(line)
        except ValueError:
            skipped.append(number)  # reported, never silently dropped
            continue
        try:
            model = _from_record(record)
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise ExportError(f"{path}:{number}: not a result record ({exc})") from exc
        if model is not None:
            models.append(model)
    if not models:
        unreadable = f" ({len(skipped)} line(s) not JSON)" if skipped else ""
        raise ExportError(f"{path}: no identified model in this file{unreadable}")
    models.skipped = tuple(skipped)
    return models


def _from_record(record: object) -> dict | None:
    """The model of a result log's line or of a result heard in a ground log; None for any
    other line."""
    if not isinstance(record, dict):
        return None
    if "result" in record and "model_id" in record:  # the agent's result log
        line = ResultLine.model_validate(record)
        return _from_result(line.model_id, line.axes, line.result, line.trim)
    message = record.get("message")
    if record.get("dir") == "rx" and isinstance(message, dict) and message.get("kind") == "result":
        heard = messages.from_dict(message)
        if isinstance(heard, messages.Result):
            return _from_message(heard)
    return None


def _matrix(value) -> np.ndarray:
    return np.atleast_2d(np.asarray(value if value is not None else [], dtype=float))


class _Matrices(Protocol):
    A: list[list[float]]
    B: list[list[float]]
    C: list[list[float]]
    D: list[list[float]]


def _state_space(model: _Matrices | None, suffix: str = "") -> dict:
    """A, B, C, D (each named with `suffix`) of a model; empty matrices without one."""
    values = (None,) * 4 if model is None else (model.A, model.B, model.C, model.D)
    return {f"{k}{suffix}": _matrix(v) for k, v in zip("ABCD", values, strict=True)}


def _modes(names: list[str | None], eigenvalues: list[complex], damping: list) -> dict:
    lam = np.array(eigenvalues, dtype=complex)
    return {
        "eigenvalues": lam.reshape(-1, 1),
        "mode_names": [name or "" for name in names],
        "frequency_hz": np.abs(lam) / TWO_PI,
        "damping": np.array([_or_nan(z) for z in damping]),
    }


def _or_nan(value: float | None) -> float:
    return np.nan if value is None else float(value)


def _trim(trim: Trim | None, inputs, outputs) -> dict:
    if trim is None:
        return {"u0": np.zeros((0,)), "y0": np.zeros((0,))}
    return {
        "u0": np.array([trim.inputs[n] for n in inputs]),
        "y0": np.array([trim.outputs[n] for n in outputs]),
    }


def _from_result(model_id: str, axes: str, r: ResultDocument, trim: Trim | None) -> dict:
    refinement = r.refinement
    return {
        "id": model_id,
        "axes": axes,
        "dt": float(r.dt),
        "inputs": list(r.inputs),
        "outputs": list(r.outputs),
        **_state_space(r),
        **_state_space(r.continuous, "c"),
        "coordinates": r.coordinates,
        "Ac_std": _matrix(None if refinement is None else refinement.Ac_std),
        "Bc_std": _matrix(None if refinement is None else refinement.Bc_std),
        **_trim(trim, r.inputs, r.outputs),
        **_modes(
            [m.name for m in r.modes],
            [complex(*m.eigenvalue) for m in r.modes],
            [m.damping for m in r.modes],
        ),
        "tic": np.asarray([r.tic[o] for o in r.outputs], dtype=float),  # kept by name
        "tic_avg": float(r.tic_avg),
    }


def _from_message(m: messages.Result) -> dict:
    return {
        "id": m.model_id,
        "axes": m.axes,
        "dt": float(m.dt),
        "inputs": list(m.inputs),
        "outputs": list(m.outputs),
        **_state_space(m),
        **{f"{k}c": np.zeros((0, 0)) for k in ("A", "B", "C", "D")},
        "coordinates": "",
        **{f"{k}c_std": np.zeros((0, 0)) for k in ("A", "B")},
        **_trim(None, m.inputs, m.outputs),
        **_modes(
            [x.name for x in m.modes],
            [complex(x.real, x.imag) for x in m.modes],
            [x.damping for x in m.modes],
        ),
        "tic": np.asarray(m.tic, dtype=float),
        "tic_avg": float(m.tic_avg),
    }


def _with_data(path: Path, stored: StoreFile, model: dict) -> dict:
    """The model with the store's data set (the .npz beside it), when there is one."""
    data = path.with_suffix(".npz")
    if data.exists():
        try:
            if stored.count is None:
                raise KeyError("count")
            with np.load(data, allow_pickle=False) as arrays:
                model["u"] = [arrays[f"u{k}"] for k in range(stored.count)]
                model["y"] = [arrays[f"y{k}"] for k in range(stored.count)]
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as exc:
            raise ExportError(
                f"{data}: the model's data set is damaged ({type(exc).__name__}: {exc})"
            ) from exc
    return model


def variable_name(model_id: str) -> str:
    """A MATLAB identifier for a model id: letters, digits, underscores, a letter first."""
    name = re.sub(r"\W", "_", model_id)
    return name if name[:1].isalpha() else f"m_{name}"


def matlab_names(ids: list[str]) -> list[str]:
    """A distinct MATLAB identifier per model, in order: `variable_name`, then _2, _3… where
    two ids map to one name (lat-1 and lat_1; the same id from two boots of the agent)."""
    names: list[str] = []
    taken = {"model_ids", "model_variables"}
    for model_id in ids:
        base = name = variable_name(model_id)
        k = 1
        while name in taken:
            k += 1
            name = f"{base}_{k}"
        taken.add(name)
        names.append(name)
    return names


def to_mat(models: list[dict], path: str | Path | BinaryIO) -> None:
    """The models as a MATLAB .mat file at `path`, or into a binary file object."""
    from scipy.io import savemat

    variables: dict[str, object] = {}
    names = matlab_names([m["id"] for m in models])
    for model, name in zip(models, names, strict=True):
        struct = dict(model)
        for key in ("inputs", "outputs", "mode_names"):
            struct[key] = np.array(struct[key], dtype=object)
        for key in ("u", "y"):
            if key in struct:
                cell = np.empty(len(struct[key]), dtype=object)
                cell[:] = struct[key]
                struct[key] = cell
        variables[name] = struct
    variables["model_ids"] = np.array([m["id"] for m in models], dtype=object)
    variables["model_variables"] = np.array(names, dtype=object)
    target = path if hasattr(path, "write") else str(path)
    savemat(target, variables, do_compression=True, oned_as="column")


def to_json(models: list[dict]) -> str:
    def plain(value):
        if isinstance(value, np.ndarray):
            if np.iscomplexobj(value):
                return [[z.real, z.imag] for z in value.ravel()]  # [re, im] pairs
            if value.dtype.kind == "f":  # NaN (an unknown damping) is null in JSON
                return np.where(np.isnan(value), None, value).tolist()
            return value.tolist()
        if isinstance(value, list):
            return [plain(v) for v in value]
        return value

    return json.dumps([{k: plain(v) for k, v in m.items()} for m in models])


def to_csv(models: list[dict]) -> str:
    """The derivatives with their standard errors (`agent.analysis.derivatives`) of every
    model in output coordinates; ExportError when none is."""
    tables = [
        (
            m["id"],
            derivatives.from_matrices(
                m["outputs"], m["inputs"], m["Ac"], m["Bc"], m["Ac_std"], m["Bc_std"]
            ),
        )
        for m in models
        if m["coordinates"] == "outputs" and m["Ac"].size
    ]
    if not tables:
        raise ExportError(
            "no model in output coordinates: derivatives need the continuous model whose "
            "states are the outputs (a ground log holds discrete matrices only)"
        )
    return derivatives.to_csv(tables)
