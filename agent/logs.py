"""Flight logs (thesis §2.2.1): the full-flight data log, one input/output log per excitation,
and the execution log — written off the event loop, crash-safe.

One writer thread owns every log file. The loop hands it whole lines (or recorder rows, which
the thread formats) through one bounded queue; a full queue drops the line and counts it. The
queue is a `queue.SimpleQueue`, whose put takes no Python-level lock and may interrupt another
put on the same thread: a line logged from any thread, at any point — a library's thread, or
a thread already inside a put — never waits for a lock, so logging can never deadlock here.
Each line goes to the file in a single write() of complete bytes, so a process killed at any
moment leaves only whole lines (the reader still ignores a final line with no line end, which
only a power cut can leave). Files are fsynced at least once a second: a power cut loses at
most the last second.

Names: NNNN_kind[_single|_batch]_YYYYMMDD.ext — a running number per log directory, the kind
(flight, exec, or the identification type of an excitation: lateral, longitudinal, full), the
batch flag for excitation logs, and the UTC date.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import hashlib
import itertools
import json
import logging
import os
import queue
import re
import threading
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

# Lines waiting for the writer thread: 20 s of 100 Hz frames plus events and excitation logs.
QUEUE_LINES = 4096
# fsync every file with new data at least this often (the power-cut loss bound).
FSYNC_S = 1.0
# How long close() waits for the writer to drain before giving up (a stuck disk).
CLOSE_TIMEOUT_S = 10.0
NAME = re.compile(r"^(\d{4})_")
# Files that could not be created, remembered (the newest).
FAILURES_KEPT = 20


def next_number(directory: Path) -> int:
    """One more than the largest running number in the directory (1 when empty)."""
    numbers = [int(m.group(1)) for p in directory.iterdir() if (m := NAME.match(p.name))]
    return max(numbers, default=0) + 1


def log_name(number: int, kind: str, ext: str, batch: bool | None = None, when=None) -> str:
    """NNNN_kind[_single|_batch]_YYYYMMDD.ext."""
    day = (when or dt.datetime.now(dt.UTC)).strftime("%Y%m%d")
    flag = "" if batch is None else ("_batch" if batch else "_single")
    return f"{number:04d}_{kind}{flag}_{day}.{ext}"


def config_hash(text: str) -> str:
    """SHA-256 of the configuration in force, so a log names the settings it was made with."""
    return hashlib.sha256(text.encode()).hexdigest()


def csv_header(
    kind: str, columns: Sequence[str], units: Sequence[str], config_sha256: str, extra: str = ""
) -> bytes:
    """Comment lines (what, when, config hash, units), then the column names."""
    stamp = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
    units_line = ",".join(f"{c}={u}" for c, u in zip(columns, units, strict=True))
    lines = [
        f"# suas-sysid {kind} log, created {stamp}",
        f"# config sha256 {config_sha256}",
        f"# units: {units_line}",
    ]
    if extra:
        lines.append(f"# {extra}")
    lines.append(",".join(columns))
    return ("\n".join(lines) + "\n").encode()


_TEMPLATES: dict[tuple[int, bool], str] = {}


def format_row(row: np.ndarray, exact: bool = False) -> bytes:
    """One CSV line: time with µs resolution, values to 9 significant digits, NaN empty.
    `exact`: values to 17 significant digits, which read back to the same float64 — the
    excitation logs, so that a replay computes on exactly the numbers the aircraft did.
    One %-format per row (13 µs for the agent's 83 columns, against 20 µs cell by cell): the
    flight log's rows are formatted on the event loop, so the writer thread never holds the
    GIL for long while the loop waits for it."""
    width = len(row)
    template = _TEMPLATES.get((width, exact))
    if template is None:
        cell = ",%.17g" if exact else ",%.9g"
        template = _TEMPLATES[width, exact] = "%.6f" + cell * (width - 1) + "\n"
    # A cell reads "nan" only for NaN (numbers never start with n): an empty cell.
    return (template % tuple(row.tolist())).replace(",nan", ",").encode()


@dataclass(frozen=True)
class _Create:
    path: Path


class LogWriter:
    """The writer thread: open files, append lines, fsync; see the module docstring."""

    def __init__(
        self, directory: Path, *, queue_lines: int = QUEUE_LINES, fsync_s: float = FSYNC_S
    ):
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self._first_number = next_number(self.directory)
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._bound = queue_lines
        self._fsync_s = fsync_s
        self._fds: dict[int, int] = {}
        self._sizes: dict[int, int] = {}  # bytes of whole lines in each open file
        self._paths: dict[int, Path] = {}
        self._dirty: set[int] = set()
        self._handles = itertools.count(1)
        self.dropped = 0
        self.errors = 0
        self.lost_lines = 0  # lines the disk refused (full, or failing): counted, not written
        self.failing: str | None = None  # the last write error while writes are failing
        self.failures: list[str] = []  # files that could not be created, and why
        self._thread = threading.Thread(target=self._serve, name="log-writer", daemon=True)
        self._thread.start()

    def open(self, name: str, header: bytes = b"") -> int:
        """Create a log file (never overwrites) and queue its header; returns its handle.
        The file is created on the writer thread: creating a file can wait on the journal
        while the other logs are being synced, and the caller is the event loop."""
        handle = next(self._handles)
        path = self.directory / name
        self._paths[handle] = path
        self._put((handle, _Create(path)), block=True)
        if header:
            self._put((handle, header), block=True)
        return handle

    def next_number(self) -> int:
        """The next running number: after those on disk when the writer started (listed once:
        listing a directory while the logs are synced can take 0.1 s, too long for the loop)
        and those this writer has opened since."""
        queued = [int(m.group(1)) for p in self._paths.values() if (m := NAME.match(p.name))]
        return max(self._first_number, max(queued, default=0) + 1)

    def path(self, handle: int) -> Path:
        return self._paths[handle]

    def write(self, handle: int, line: bytes | np.ndarray) -> bool:
        """Queue a line (bytes ending in a newline), or a recorder row or 2-D block of rows (one
        queue slot, formatted on the writer thread with `format_row(exact=True)`); False if
        dropped."""
        return self._put((handle, line), block=False)

    def close_file(self, handle: int) -> None:
        self._put((handle, None), block=True)

    def _put(self, item, *, block: bool) -> bool:
        """Hand an item to the writer thread without waiting for any lock (see the module
        docstring). A line (`block` False) beyond the bound is dropped and counted; files to
        create or close and excitation logs (`block` True) are always queued: they are few, and
        dropping one would lose a whole log. The drop count is kept without a lock, so two
        threads dropping at the same instant may count one."""
        if not block and self._queue.qsize() >= self._bound:
            self.dropped += 1
            return False
        self._queue.put(item)
        return True

    def close(self) -> None:
        """Write everything queued, fsync, close every file and stop the thread."""
        if self._thread.is_alive():
            self._put((0, None), block=True)
            self._thread.join(CLOSE_TIMEOUT_S)

    def _serve(self) -> None:
        last_sync = time.monotonic()
        while True:
            try:
                handle, data = self._queue.get(timeout=self._fsync_s / 2)
            except queue.Empty:
                handle, data = -1, None
            if handle == 0:
                self._sync()
                for fd in self._fds.values():
                    os.close(fd)
                self._fds.clear()
                return
            if handle > 0:
                self._apply(handle, data)
            if time.monotonic() - last_sync >= self._fsync_s:
                self._sync()
                last_sync = time.monotonic()

    def _apply(self, handle: int, data) -> None:
        if isinstance(data, _Create):
            try:
                flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_APPEND
                self._fds[handle] = os.open(data.path, flags, 0o644)
                self._sizes[handle] = 0
            except OSError as exc:
                self.errors += 1
                self.failures.append(f"{data.path}: cannot be created ({exc.strerror or exc})")
                del self.failures[:-FAILURES_KEPT]
            return
        fd = self._fds.get(handle)
        if fd is None:
            return
        if data is None:  # close this file
            with contextlib.suppress(OSError):
                os.fsync(fd)
            os.close(self._fds.pop(handle))
            self._sizes.pop(handle, None)
            self._dirty.discard(handle)
            return
        if isinstance(data, np.ndarray):
            lines = [format_row(r, exact=True) for r in np.atleast_2d(data)]
        else:
            lines = [data]
        for k, line in enumerate(lines):
            # One write per whole line: a kill leaves whole lines (a short write, which only a
            # full disk gives, is completed or cut back below).
            written, problem = 0, None
            try:
                while written < len(line):  # a short write: the rest, to learn why
                    written += os.write(fd, line[written:])
            except OSError as exc:
                problem = exc.strerror or str(exc)
            if problem is None:
                self._sizes[handle] += written
                continue
            # Disk full (or failing): cut the file back to its last whole line, so what was
            # written before stays readable and a later line never lands after half of one;
            # count what was not written and go on (the next line tries again).
            with contextlib.suppress(OSError):
                os.ftruncate(fd, self._sizes[handle])
            self.errors += 1
            self.lost_lines += len(lines) - k
            self.failing = problem
            return
        self.failing = None
        self._dirty.add(handle)

    def _sync(self) -> None:
        for handle in list(self._dirty):
            fd = self._fds.get(handle)
            if fd is not None:
                try:
                    os.fsync(fd)
                except OSError:
                    self.errors += 1
        self._dirty.clear()


class JsonLinesHandler(logging.Handler):
    """The execution log: one JSON object per logging event, through the writer thread."""

    def __init__(self, writer: LogWriter, handle: int, clock=None):
        super().__init__()
        self._writer, self._handle, self._clock = writer, handle, clock
        self.unformattable = 0  # records whose message could not be formatted (kept, raw)

    def handle(self, record: logging.LogRecord) -> logging.LogRecord | bool:
        """Filter and emit without the handler's lock (logging.Handler.handle takes one): emit
        only formats and hands one line to the writer's lock-free queue, so it is safe on any
        thread and re-entered on one — where a lock held by the interrupted call would
        deadlock."""
        passed = self.filter(record)
        if isinstance(passed, logging.LogRecord):  # Python 3.12+: a filter may replace it
            record = passed
        if passed:
            self.emit(record)
        return passed

    def emit(self, record: logging.LogRecord) -> None:
        try:
            line = self._line(record)
        except RecursionError:
            raise
        except Exception:  # a library's bad format string, say: counted, kept unformatted
            # Not logging.Handler.handleError: it writes a traceback to stderr, which takes the
            # stream's lock, and this may run at any point on any thread.
            self.unformattable += 1
            line = self._raw_line(record)
        self._writer.write(self._handle, line)

    @staticmethod
    def _raw_line(record: logging.LogRecord) -> bytes:
        template = record.msg if isinstance(record.msg, str) else type(record.msg).__name__
        event = {
            "t": time.monotonic(),
            "level": record.levelname,
            "logger": record.name,
            "message": f"unformattable log record: {template}",
        }
        return (json.dumps(event) + "\n").encode()

    def _line(self, record: logging.LogRecord) -> bytes:
        event = {
            "utc": dt.datetime.fromtimestamp(record.created, dt.UTC).isoformat(),
            # time.monotonic: the loop clock's base, and safe on any thread (libraries log
            # from their own).
            "t": time.monotonic(),
            "level": record.levelname,
            "logger": record.name,
            "message": record.getMessage(),
        }
        if record.exc_info:
            event["exception"] = self.format(record).splitlines()[-1]
        return (json.dumps(event) + "\n").encode()


# A number as a CSV cell holds one: what float() reads, less what no CSV writer means by a
# number (Python's digit separators, 1_000; non-ASCII digits; padding). nan and inf are read,
# for the finite checks downstream to name.
_NUMBER = re.compile(
    r"[+-]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|(?i:inf|infinity|nan))", re.ASCII
)
# In an ASCII text, what float() would take in a cell that _NUMBER refuses: a whole log is
# searched at once, and float() refuses the rest cell by cell.
_NOT_CSV = re.compile(r"[_ \t\r\v\f]")


class LogError(ValueError):
    """A log that cannot be read as one; the message names the line (and column)."""


def csv_number(cell: str) -> float:
    """The number in a CSV cell; ValueError for what float() reads but a CSV reader should
    not (1_000, ' 1', non-ASCII digits)."""
    if not _NUMBER.fullmatch(cell):
        hint = " (write numbers without '_' separators)" if "_" in cell else ""
        raise ValueError(f"{cell!r} is not a number{hint}")
    return float(cell)


# The longest line read from a log: a row of every channel is a few hundred bytes; a file
# with no line ends (/dev/zero, a binary file) is refused at this length, not read whole.
MAX_LINE = 1 << 20
# The most data rows read from one log, as `sysid identify` reads at most 5 million rows of a
# record: 14 hours of a 100 Hz flight log. A larger file is refused, not held.
MAX_ROWS = 5_000_000
# Data lines checked and parsed together: the text in hand at once is this many lines.
BLOCK_LINES = 1024


def read_log(path: Path, columns: Iterable[str] | None = None) -> tuple[list[str], np.ndarray]:
    """A flight or excitation log: (column names, rows); empty cells are NaN. `columns`: keep
    only these (those the header has, in its order); None keeps every column. Comment lines
    are skipped; a last line without a line end (a power cut mid-write) is ignored. A line
    that is not a row of numbers is a LogError naming its line and column; so is a line over
    MAX_LINE bytes, and a log over MAX_ROWS rows. Read a block of lines at a time, so memory
    is what is kept, not the file."""
    lines = _content_lines(Path(path))
    first = next(lines, None)
    if first is None:
        raise LogError(
            "no header row, only comment lines: the log was cut before its first row "
            "(a power cut or a full disk); leave it out"
        )
    header = first[1].split(",")
    wanted = None if columns is None else set(columns)
    keep = [j for j, name in enumerate(header) if wanted is None or name in wanted]
    blocks, body = [], []
    for count, numbered in enumerate(lines, start=1):
        if count > MAX_ROWS:
            raise LogError(f"more than {MAX_ROWS} data rows, the most one log may have; cut it")
        body.append(numbered)
        if len(body) == BLOCK_LINES:
            blocks.append(_rows(header, body)[:, keep])
            body = []
    blocks.append(_rows(header, body)[:, keep])
    return [header[j] for j in keep], np.concatenate(blocks)


def _content_lines(path: Path) -> Iterator[tuple[int, str]]:
    """(line number, text) of each whole line that is neither blank nor a comment."""
    with path.open("rb") as handle:
        number = 0
        while line := handle.readline(MAX_LINE + 1):
            number += 1
            if len(line) > MAX_LINE:
                raise LogError(f"line {number} is longer than {MAX_LINE} bytes: not a log")
            if not line.endswith(b"\n"):
                return  # unfinished: a power cut mid-write
            text = line[:-1].decode().removesuffix("\r")  # CR LF: line ends a copy changed
            if text.strip() and not text.startswith("#"):
                yield number, text


def _rows(header: list[str], body: list[tuple[int, str]]) -> np.ndarray:
    """The lines of `body` ((line number, text)) as rows of floats; a LogError names the
    first that is not a row of numbers."""
    data_lines = [ln for _, ln in body]
    joined = "\n".join(data_lines)
    try:
        if joined.count(",") != (len(header) - 1) * len(body) or not joined.isascii():
            raise ValueError
        if _NOT_CSV.search(joined):
            raise ValueError
        # Ragged rows (a comma moved between lines) raise here too.
        data = np.array(
            [[float(c) if c else np.nan for c in ln.split(",")] for ln in data_lines], dtype=float
        )
    except ValueError:
        raise LogError(_bad_line(header, body)) from None
    return data.reshape(len(body), len(header))


def _bad_line(header: list[str], body: list[tuple[int, str]]) -> str:
    """What is wrong with the first line of `body` with a field too many or too few, or a
    cell that is not a number."""
    for line_no, ln in body:
        cells = ln.split(",")
        if len(cells) != len(header):
            return (
                f"line {line_no}: {len(cells)} fields, the header has {len(header)} "
                "(lines joined or cut by a bad copy?); repair or delete the line"
            )
        for j, (name, cell) in enumerate(zip(header, cells, strict=True)):
            try:
                if cell:
                    csv_number(cell)
            except ValueError as exc:
                return (
                    f"line {line_no}, column {j + 1} ({name!r}): {exc}; "
                    "repair the cell or delete the line"
                )
    return "not a table of numbers"


def units_of(names: Iterable[str], table: dict[str, tuple[str, str]]) -> list[str]:
    return [table.get(n, ("", ""))[0] or "-" for n in names]


class Logbook:
    """The logs of one agent run: the flight log (every recorder frame), the execution log,
    and an input/output log per excitation window."""

    def __init__(
        self,
        writer: LogWriter,
        columns: Sequence[str],
        units: Sequence[str],
        config_sha256: str,
        rate_hz: float | None = None,
    ):
        self._writer, self._columns, self._units = writer, list(columns), list(units)
        self._sha, self._rate_hz = config_sha256, rate_hz
        number = writer.next_number()
        header = csv_header("flight", self._columns, self._units, config_sha256)
        self.flight = writer.open(log_name(number, "flight", "csv"), header)
        self.execution = writer.open(log_name(number, "exec", "jsonl"))

    def row(self, row: np.ndarray) -> None:
        """A recorder frame into the flight log (dropped and counted if the queue is full),
        formatted here, on the caller's thread (see format_row)."""
        self._writer.write(self.flight, format_row(row))

    def linkage(self, plan_id: str, follows) -> None:
        """Each surface's linkage on a finished run (agent.excitation.follow: measured per
        commanded deflection, its even part per |commanded| deflection, and the lag of the best
        correlation) as one execution-log line
        `sysid tune --exec-log` reads."""
        event = {
            "utc": dt.datetime.now(dt.UTC).isoformat(),
            "t": time.monotonic(),
            "level": "INFO",
            "logger": "agent.linkage",
            "message": f"{plan_id}: the surfaces' linkage",
            "plan": plan_id,
            "linkage": {
                f.control: {
                    "gain": f.gain,
                    "even": f.even,
                    "knee": f.knee,
                    "lag_s": f.lag_s,
                    "correlation": f.correlation,
                }
                for f in follows
            },
        }
        self._writer.write(self.execution, (json.dumps(event) + "\n").encode())

    def gains(self, action: str, proposal: str | None, values: dict, reason: str) -> None:
        """An autopilot gain change (agent/runtime/gains.py: applied, reverted, failed) as one
        execution-log line: the values read back and why."""
        self.event(
            "agent.gains",
            f"gains {action} {proposal or ''}: {reason}".strip(),
            action=action,
            proposal=proposal,
            gains=values,
        )

    def event(self, logger: str, message: str, **fields) -> None:
        """One execution-log line with fields of its own beside the message."""
        event = {
            "utc": dt.datetime.now(dt.UTC).isoformat(),
            "t": time.monotonic(),
            "level": "INFO",
            "logger": logger,
            "message": message,
            **fields,
        }
        self._writer.write(self.execution, (json.dumps(event) + "\n").encode())

    def excitation(self, window, rows: np.ndarray, batch: bool = False) -> Path:
        """Write one excitation's input/output log; returns its path."""
        number = self._writer.next_number()
        extra = (
            f"excitation plan {window.plan_id}, {window.outcome}"
            f"{': ' + window.reason if window.reason else ''}, "
            + ("flown on the sticks (FBWA: closed loop), " if window.closed_loop else "")
            + f"window {window.start:.6f} – {window.end:.6f} s"
            + (f", recorded at {self._rate_hz:.17g} Hz" if self._rate_hz else "")
        )
        header = csv_header(window.axes, self._columns, self._units, self._sha, extra)
        handle = self._writer.open(log_name(number, window.axes, "csv", batch=batch), header)
        self._writer._put((handle, rows), block=True)
        self._writer.close_file(handle)
        return self._writer.path(handle)

    def handler(self, clock=None) -> JsonLinesHandler:
        return JsonLinesHandler(self._writer, self.execution, clock)
