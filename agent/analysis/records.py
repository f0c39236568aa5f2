"""Flight records as CSV: reading, validation, time selection and trim removal.

A record is a CSV file with a header row, a `time` column in seconds (uniformly sampled, or
in uniform segments between gaps: `segments`) and named numeric columns. Every problem is
reported as a `RecordError` naming the file, the line and the column, so a bad file is fixed
rather than debugged.
"""

from __future__ import annotations

import csv
import itertools
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from agent.analysis.units import TIME_UNITS, split_header
from agent.logs import csv_number

# Sampling jitter allowed, as a fraction of the median step: loggers stamp samples with some
# scheduling noise, but beyond 1 % the record is not uniformly sampled and OKID's
# discrete-time model would be wrong.
MAX_JITTER = 0.01
# Larger files are not flight records of one excitation; refuse rather than exhaust memory.
MAX_ROWS = 5_000_000
# A step in time this many sample times long or more is a gap: a logger paused, or two
# manoeuvres written into one file. The record is split there into its uniform segments,
# identified together as a batch (`segments`); a step between MAX_JITTER and this is no gap
# but irregular sampling, which is refused.
GAP_STEPS = 1.5
# A comment line that names the record's columns which are commands held between updates
# (servo outputs: `sysid import` writes it), not sampled measurements.
COMMANDS = "# commands:"
# A segment of fewer samples than this between gaps (1 s at 100 Hz, 4 s at 25 Hz) holds no
# manoeuvre an identification could use: it is left out, and the note says so.
MIN_SEGMENT = 100


class RecordError(ValueError):
    """A record cannot be used as given; the message says where and why (`missing`: the
    columns asked for that the header lacks, when that is why)."""

    def __init__(self, message: str, missing: tuple[str, ...] = ()):
        super().__init__(message)
        self.missing = missing


@dataclass(frozen=True)
class Record:
    """Selected columns of one CSV record, uniformly sampled."""

    path: Path
    time: np.ndarray
    columns: dict[str, np.ndarray]
    dt: float
    # Column → the unit its header declares (`alpha [deg]`; agent.analysis.units), the
    # values as written: `agent.analysis.identify` converts them.
    units: dict[str, str] = field(default_factory=dict)
    # The columns its comment lines declare commands (COMMANDS): held between samples.
    commands: frozenset[str] = frozenset()

    def matrix(self, names: Sequence[str]) -> np.ndarray:
        """The named columns as an (l × len(names)) array."""
        return np.column_stack([self.columns[n] for n in names])


def read_record(
    path: str | Path, names: Sequence[str], optional: Sequence[str] = (), absent: Sequence[str] = ()
) -> Record:
    """Read `time` and the named columns; check they are finite and uniformly sampled. The
    `optional` columns are read too where the header has them and every cell is a finite
    number; otherwise they are left out of the record. The named columns also in `absent`
    may be missing from the header (α and β, which can be synthesised); where the header has
    them they are read as strictly as the others.

    A UTF-8 byte-order mark (Excel's "CSV UTF-8") is skipped. The data rows go through numpy's
    C reader (`np.loadtxt`) into one float array, about 8 bytes a cell; a file it refuses is
    read again row by row to say which line and cell is wrong."""
    path = Path(path)
    try:
        with path.open(newline="", encoding="utf-8-sig") as handle:
            # Our flight and excitation logs start with "# " comment lines (units, config hash).
            comments, commands = 0, set()
            while (line := _line(path, handle)).startswith("#"):
                comments += 1
                if line.startswith(COMMANDS):
                    commands |= {n.strip() for n in line[len(COMMANDS) :].split(",") if n.strip()}
            if not line.strip():
                raise RecordError(f"{path}: the file is empty; expected a header row")
            header = [h.strip() for h in next(csv.reader([line]))]
            _check_header(path, header)
            declared = [split_header(h) for h in header]
            header = [n for n, _ in declared]
            header_units = {n: u for n, u in declared if u is not None}
            names = [n for n in names if n in header or n not in absent]
            index = _column_index(path, header, ["time", *names])
            extra = [
                n
                for n in dict.fromkeys(optional)
                if n not in names and n != "time" and header.count(n) == 1
            ]
            index += [header.index(n) for n in extra]
            wanted = ["time", *names, *extra]
            start = handle.tell()
            values = None
            if _widths_agree(path, comments + 1, len(header)):
                values = _fast_rows(handle, len(header), index)
            # Non-finite cells: the row-by-row reader names them, or leaves an optional out.
            if values is None or not np.isfinite(values).all():
                handle.seek(start)
                reader = csv.reader(_lines(path, handle))
                values = _read_rows(
                    path, reader, len(header), index, wanted, 2 + comments, lenient=len(extra)
                )
    except OSError as exc:
        raise RecordError(f"{path}: cannot be read ({exc.strerror or exc})") from exc
    except UnicodeDecodeError as exc:
        raise RecordError(f"{path}: not a text CSV file ({exc.reason})") from exc
    except csv.Error as exc:
        raise RecordError(f"{path}: not a readable CSV file ({exc})") from exc
    _check_last_line_ends(path)
    time = values[:, 0]
    columns = {name: values[:, j + 1] for j, name in enumerate([*names, *extra])}
    for name in extra:
        if not np.isfinite(columns[name]).all():
            del columns[name]
    scale = TIME_UNITS.get(header_units.pop("time", "s"))
    if scale is None:
        raise RecordError(f"{path}: the time column's unit must be one of {', '.join(TIME_UNITS)}")
    time = time * scale
    units = {n: u for n, u in header_units.items() if n in columns}
    return Record(
        path=path,
        time=time,
        columns=columns,
        dt=_median_step(path, time),
        units=units,
        commands=frozenset(commands),
    )


# The longest line a record may have: a flight record's row is a few hundred characters; a
# file without newlines (a binary file, /dev/zero) is refused at this length, not read whole.
MAX_LINE = 1 << 20


def _line(path: Path, handle) -> str:
    line = handle.readline(MAX_LINE + 1)
    if len(line) > MAX_LINE:
        raise RecordError(f"{path}: a line longer than {MAX_LINE} characters; not a CSV record")
    return line


def _lines(path: Path, handle):
    while line := _line(path, handle):
        yield line


# The end of a record looked at for its last line end: a row is far shorter.
TAIL = 1 << 16


def _check_last_line_ends(path: Path) -> None:
    """A last line without a line end may have been cut mid-number (a copy or a write that
    stopped), and a number cut short still reads as a number: refused, with what to do."""
    with path.open("rb") as raw:
        size = raw.seek(0, 2)
        raw.seek(max(0, size - TAIL))
        tail = raw.read(TAIL).rstrip(b" \t\r")
        if not tail or tail.endswith(b"\n"):
            return
        raw.seek(0)
        line_no = 1 + sum(chunk.count(b"\n") for chunk in iter(lambda: raw.read(TAIL), b""))
    raise RecordError(
        f"{path} line {line_no}: the last line has no line end, so it may have been cut "
        "mid-number; if the line is whole, end it with a newline, else delete it"
    )


def _check_header(path: Path, header: list[str]) -> None:
    if any("\x00" in h for h in header):
        raise RecordError(f"{path}: NUL bytes in the header: a binary file, not a CSV record")
    if len(header) == 1 and header[0].count(";") >= 1:
        raise RecordError(
            f"{path}: the header has one column, {header[0][:80]!r}: the fields are separated "
            "by ';' (a spreadsheet's regional setting); save it with ',' separators"
        )


# The bytes `_widths_agree` looks at in one piece.
WIDTH_CHUNK = 1 << 24


def _widths_agree(path: Path, skip: int, width: int) -> bool:
    """Whether every data line (after the `skip` comment and header lines) has `width` fields,
    counted as commas, vectorised: numpy's reader reads only the wanted columns and would not
    notice a row with a field too many. False also for a quoted field (a comma may be inside
    it): the row-by-row reader then checks."""
    with path.open("rb") as raw:
        for _ in range(skip):
            raw.readline(MAX_LINE + 1)
        rest = b""
        while True:
            chunk = raw.read(WIDTH_CHUNK)
            data = rest + chunk
            if not chunk:
                cut = len(data)
            else:
                cut = data.rfind(b"\n") + 1
                if cut == 0:
                    if len(data) > MAX_LINE:
                        return False
                    rest = data
                    continue
            body, rest = np.frombuffer(data[:cut], dtype=np.uint8), data[cut:]
            if body.size:
                if (body == ord('"')).any():
                    return False
                ends = np.flatnonzero(body == ord("\n"))
                if not chunk and (ends.size == 0 or ends[-1] != body.size - 1):
                    ends = np.append(ends, body.size)  # the last line without its newline
                commas = np.concatenate([[0], np.cumsum(body == ord(","))])
                starts = np.concatenate([[0], ends[:-1] + 1])
                per_line = commas[ends] - commas[starts]
                lengths = ends - starts
                # Blank lines (length 0, or a lone carriage return) are skipped by both readers.
                blank = (lengths == 0) | (
                    (lengths == 1) & (body[np.minimum(starts, body.size - 1)] == ord("\r"))
                )
                if np.any(per_line[~blank] != width - 1):
                    return False
            if not chunk:
                return True


def _fast_rows(handle, width: int, index: list[int]) -> np.ndarray | None:
    """The columns `index` of every data row, parsed by numpy's C reader; None when it refuses
    the file (a bad cell, a short row, a blank row of commas, an over-long line): the
    row-by-row reader then says where."""
    try:
        with warnings.catch_warnings():  # an empty file: the row-by-row reader says so
            warnings.simplefilter("ignore", UserWarning)
            values = np.loadtxt(
                handle, delimiter=",", usecols=index, ndmin=2, max_rows=MAX_ROWS + 1, comments=None
            )
    except (ValueError, OverflowError):
        return None
    if not MAX_ROWS >= values.shape[0] >= 2:
        return None  # the row-by-row reader gives the reason
    return values


def _column_index(path: Path, header: list[str], wanted: list[str]) -> list[int]:
    missing = [n for n in dict.fromkeys(wanted) if n not in header]
    if missing:
        raise RecordError(
            f"{path}: no column(s) {', '.join(repr(n) for n in missing)}; "
            f"the header has {', '.join(header)}",
            missing=tuple(missing),
        )
    duplicated = sorted({n for n in wanted if header.count(n) > 1})
    if duplicated:
        raise RecordError(f"{path}: column(s) {', '.join(duplicated)} appear more than once")
    return [header.index(n) for n in wanted]


def _read_rows(
    path: Path,
    reader: csv.reader,
    width: int,
    index: list[int],
    names: list[str],
    first: int,
    lenient: int = 0,
) -> np.ndarray:
    """The named columns as floats; the last `lenient` of them take NaN for a bad cell."""
    strict = len(names) - lenient
    rows: list[list[float]] = []
    line_no = first
    for line_no, row in _numbered(path, reader, first):
        if not row or all(not cell.strip() for cell in row):
            continue
        if len(row) != width:
            raise RecordError(f"{path} line {line_no}: {len(row)} fields, the header has {width}")
        if len(rows) >= MAX_ROWS:
            raise RecordError(f"{path}: more than {MAX_ROWS} rows; split the record")
        parsed = []
        for k, (j, name) in enumerate(zip(index, names, strict=True)):
            cell = row[j].strip()
            if k >= strict:
                try:
                    parsed.append(csv_number(cell))
                except ValueError:
                    parsed.append(np.nan)
                continue
            try:
                value = csv_number(cell)
            except ValueError:
                hint = " (write numbers without '_' separators)" if "_" in cell else ""
                raise RecordError(
                    f"{path} line {line_no}: {cell!r} in column '{name}' is not a number{hint}"
                ) from None
            if not np.isfinite(value):
                raise RecordError(
                    f"{path} line {line_no}: non-finite value {cell!r} in column '{name}'; "
                    "remove or repair the row — gaps cannot be identified across"
                )
            parsed.append(value)
        rows.append(parsed)
    if len(rows) < 2:
        raise RecordError(f"{path}: {len(rows)} data row(s); a record needs at least 2")
    return np.asarray(rows)


def _numbered(path: Path, reader, first: int):
    """(line number, row) from the reader; a malformed line (a cell over the csv module's
    field limit, NUL bytes) is a RecordError naming it."""
    line_no = first
    while True:
        try:
            row = next(reader)
        except StopIteration:
            return
        except csv.Error as exc:
            raise RecordError(f"{path} line {line_no}: not a readable CSV line ({exc})") from exc
        yield line_no, row
        line_no += 1


def time_steps(path: Path, time: np.ndarray, spec: str = ".6g") -> np.ndarray:
    """The steps between successive times; a RecordError names the first data row whose time
    does not increase (its times formatted with `spec`)."""
    steps = np.diff(time)
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0))
        raise RecordError(
            f"{path}: time does not increase at data row {k + 2} "
            f"({time[k]:{spec}} s → {time[k + 1]:{spec}} s)"
        )
    return steps


def _median_step(path: Path, time: np.ndarray) -> float:
    """The record's sample time: its median step (the time checked to increase; a single
    sample has none, and `select` refuses it)."""
    if time.size < 2:
        return float("nan")
    return float(np.median(time_steps(path, time)))


def segments(record: Record) -> tuple[list[Record], list[str]]:
    """The record's uniformly sampled segments, split at its gaps (a step of GAP_STEPS sample
    times or more), with a note for each split and each segment left out (shorter than
    MIN_SEGMENT samples); a record without gaps is one segment and no note. Sampling that is
    irregular without a gap (a step more than MAX_JITTER off the median, not a gap) is a
    RecordError: it must be resampled, not cut."""
    path, time, dt = record.path, record.time, record.dt
    steps = time_steps(path, time)
    gaps = np.flatnonzero(steps >= GAP_STEPS * dt)
    jitter = np.abs(steps - dt) / dt
    jitter[gaps] = 0.0
    if jitter.size and jitter.max() > MAX_JITTER:
        k = int(np.argmax(jitter))
        raise RecordError(
            f"{path}: sampling is not uniform: step {steps[k]:.6g} s at {time[k]:.6g} s against "
            f"a median of {dt:.6g} s ({100 * jitter[k]:.1f} % > {100 * MAX_JITTER:.0f} %; a "
            f"step of {GAP_STEPS:g}× the median or more is a gap, and the record is split "
            "there); resample the record"
        )
    if not gaps.size:
        return [record], []
    bounds = [0, *(int(k) + 1 for k in gaps), time.size]
    kept, notes, short = [], [], []
    for a, b in itertools.pairwise(bounds):
        if b - a < MIN_SEGMENT:
            short.append(f"{time[a]:.6g}…{time[b - 1]:.6g} s ({b - a} samples)")
            continue
        columns = {name: values[a:b] for name, values in record.columns.items()}
        kept.append(replace(record, time=time[a:b], columns=columns))
    listed = ", ".join(f"{steps[k]:.6g} s at {time[k]:.6g} s" for k in gaps[:5])
    more = f" and {gaps.size - 5} more" if gaps.size > 5 else ""
    notes.append(
        f"{path.name}: {gaps.size} gap(s) in time ({listed}{more}): identified as "
        f"{len(kept)} uniform segment(s) of the batch"
    )
    if short:
        notes.append(
            f"{path.name}: segment(s) shorter than {MIN_SEGMENT} samples left out: "
            + ", ".join(short)
        )
    if not kept:
        raise RecordError(
            f"{path}: every segment between its {gaps.size} gap(s) is shorter than "
            f"{MIN_SEGMENT} samples; nothing left to identify"
        )
    return kept, notes


def select(record: Record, start: float | None, end: float | None) -> Record:
    """The samples with start ≤ time ≤ end."""
    keep = np.ones(record.time.size, dtype=bool)
    if start is not None:
        keep &= record.time >= start
    if end is not None:
        keep &= record.time <= end
    if keep.sum() < 2:
        raise RecordError(
            f"{record.path}: fewer than 2 samples between {start} s and {end} s "
            f"(the record spans {record.time[0]:.6g}…{record.time[-1]:.6g} s)"
        )
    columns = {name: values[keep] for name, values in record.columns.items()}
    time = record.time[keep]
    return replace(record, time=time, columns=columns, dt=_median_step(record.path, time))


def trim_values(record: Record, names: Sequence[str], seconds: float) -> dict[str, float]:
    """Mean of each named column over the first `seconds` of the record (at least one sample).

    A window reaching the end of the record would average the excitation into the trim, so it
    is refused.
    """
    count = max(1, int(np.sum(record.time < record.time[0] + seconds - 1e-9 * record.dt)))
    if count >= record.time.size:
        raise RecordError(
            f"{record.path}: the {seconds:g} s trim window covers the whole selected record "
            f"({record.time[-1] - record.time[0]:.6g} s); shorten --trim or widen --start/--end"
        )
    return {name: float(np.mean(record.columns[name][:count])) for name in names}
