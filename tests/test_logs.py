"""Logs: names and running numbers, headers, the writer thread, drops, and kill -9 safety."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from agent.excitation.scheduler import Window
from agent.logs import Logbook, LogWriter, config_hash, log_name, next_number, read_log

ROOT = Path(__file__).resolve().parents[1]


def test_names_combine_number_kind_batch_flag_and_date(tmp_path):
    assert next_number(tmp_path) == 1
    (tmp_path / "0007_flight_20261122.csv").touch()
    (tmp_path / "notes.txt").touch()
    assert next_number(tmp_path) == 8
    import datetime as dt

    day = dt.datetime(2026, 11, 22, tzinfo=dt.UTC)
    assert (
        log_name(8, "lateral", "csv", batch=False, when=day) == "0008_lateral_single_20261122.csv"
    )
    assert log_name(9, "full", "csv", batch=True, when=day) == "0009_full_batch_20261122.csv"
    assert log_name(10, "flight", "csv", when=day) == "0010_flight_20261122.csv"


def test_logbook_flight_excitation_and_execution_logs(tmp_path):
    writer = LogWriter(tmp_path)
    try:
        book = Logbook(writer, ["time", "p", "p_age"], ["s", "rad/s", "s"], config_hash("x=1"))
        for k in range(5):
            book.row(np.array([k * 0.01, np.nan if k == 2 else 0.1 * k, 0.001]))
        rows = np.array([[1.0, 0.5, 0.0], [1.01, 0.6, 0.0]])
        path = book.excitation(
            Window("lat1", "lateral", 1.0, 1.01, "aborted", "pilot switch low"), rows
        )
        import logging

        logger = logging.getLogger("test.exec")
        logger.addHandler(handler := book.handler())
        logger.warning("airdata: %s", "port lost")
        logger.removeHandler(handler)
    finally:
        writer.close()
    flight = writer.path(book.flight)
    text = flight.read_text()
    assert text.startswith("# suas-sysid flight log, created ")
    assert f"# config sha256 {config_hash('x=1')}" in text
    assert "# units: time=s,p=rad/s,p_age=s" in text
    header, data = read_log(flight)
    assert header == ["time", "p", "p_age"]
    assert data.shape == (5, 3)
    assert np.isnan(data[2, 1])  # a gap stays a gap
    assert path.name.endswith("_lateral_single_" + flight.name.split("_")[-1])
    assert "pilot switch low" in path.read_text()
    assert read_log(path)[1].tolist() == rows.tolist()
    execution = writer.path(book.execution).read_text().splitlines()
    assert '"message": "airdata: port lost"' in execution[0]


def test_an_excitation_log_reads_back_the_exact_float64_values_and_the_rate(tmp_path):
    """Replay must compute on the aircraft's numbers: values that 9 digits would round (random
    float64, subnormal, huge, a gap) read back bit for bit, and the header names the rate."""
    rng = np.random.default_rng(7)
    rows = np.column_stack([100.0 + 0.01 * np.arange(50), rng.normal(size=(50, 3))])
    rows[3, 1], rows[4, 2], rows[5, 3], rows[6, 1] = 5e-324, -1.7976931348623157e308, np.nan, 0.1
    writer = LogWriter(tmp_path)
    try:
        book = Logbook(writer, ["time", "a", "b", "c"], ["s", "-", "-", "-"], "0" * 64, 400.0)
        path = book.excitation(Window("lat1", "lateral", 100.1, 100.4, "finished", ""), rows)
        sticks = Window("lat2", "lateral", 101.0, 101.2, "finished", "", closed_loop=True)
        closed = book.excitation(sticks, rows)
    finally:
        writer.close()
    # A run played on the sticks (FBWA) says so in its log; one on the surfaces does not.
    assert "flown on the sticks (FBWA: closed loop)" in closed.read_text().split("\ntime,")[0]
    assert "sticks" not in path.read_text().split("\ntime,")[0]
    _, back = read_log(path)
    assert np.array_equal(back[:, 1:], rows[:, 1:], equal_nan=True)
    assert np.abs(back[:, 0] - rows[:, 0]).max() < 1e-6  # time: µs
    assert "recorded at 400 Hz" in path.read_text().split("\ntime,")[0]
    assert not np.array_equal(np.float64(f"{rows[0, 1]:.9g}"), rows[0, 1])  # 9 digits would not


def test_a_full_queue_drops_and_counts_but_never_tears_a_line(tmp_path):
    writer = LogWriter(tmp_path, queue_lines=2)
    handle = writer.open("0001_flight_x.csv", b"time,a\n")
    accepted = sum(writer.write(handle, f"{k},{k}\n".encode()) for k in range(20_000))
    writer.close()
    lines = (tmp_path / "0001_flight_x.csv").read_text().splitlines()
    assert writer.dropped == 20_000 - accepted
    assert len(lines) == 1 + accepted
    assert all(a == b for a, b in (ln.split(",") for ln in lines[1:]))


WRITER = """
import sys, numpy as np
from pathlib import Path
from agent.logs import Logbook, LogWriter
writer = LogWriter(Path(sys.argv[1]))
cols = ["time"] + [f"c{j}" for j in range(40)]
book = Logbook(writer, cols, ["s"] * len(cols), "0" * 64)
print("ready", flush=True)
k = 0
while True:
    row = np.full(len(cols), 1.0 / 3.0) * k
    row[0] = k * 0.01
    book.row(row)
    k += 1
"""


@pytest.mark.parametrize("delay", [0.7, 1.3])
def test_kill_9_leaves_only_whole_lines(tmp_path, delay):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [sys.executable, "-c", WRITER, str(tmp_path)], stdout=subprocess.PIPE, env=env
    )
    try:
        assert proc.stdout.readline().strip() == b"ready"
        time.sleep(delay)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
        proc.stdout.close()
    (log,) = tmp_path.glob("*_flight_*.csv")
    raw = log.read_bytes()
    assert raw.endswith(b"\n")  # killed between lines, never inside one
    lines = raw.decode().split("\n")[:-1]
    body = [ln for ln in lines if not ln.startswith("#")][1:]
    assert len(body) > 100
    for line in body:  # every line parses: 41 fields, all numbers
        cells = line.split(",")
        assert len(cells) == 41
        [float(c) for c in cells]


def test_sysid_identify_reads_flight_logs_and_names_the_right_line(tmp_path):
    from agent.analysis.records import RecordError, read_record

    writer = LogWriter(tmp_path)
    book = Logbook(writer, ["time", "p"], ["s", "rad/s"], "0" * 64)
    for k in range(4):
        book.row(np.array([k * 0.01, 0.1 * k]))
    book.row(np.array([0.04, np.nan]))
    writer.close()
    path = writer.path(book.flight)
    # 3 comment lines, the header (line 4), rows from line 5: the gap is on line 9.
    with pytest.raises(RecordError, match=r"line 9: '' in column 'p' is not a number"):
        read_record(path, ["p"])
    clean = tmp_path / "clean.csv"
    clean.write_text("\n".join(path.read_text().splitlines()[:-1]) + "\n")
    record = read_record(clean, ["p"])
    assert record.columns["p"].tolist() == pytest.approx([0.0, 0.1, 0.2, 0.3])
    assert record.dt == pytest.approx(0.01)


def test_files_opened_in_quick_succession_get_their_own_numbers(tmp_path):
    # Files are created on the writer thread; numbering must not wait for them to exist.
    writer = LogWriter(tmp_path)
    try:
        names, handles = [], []
        for _ in range(3):  # as Logbook.excitation does it: number, then open
            names.append(log_name(writer.next_number(), "lateral", "csv"))
            handles.append(writer.open(names[-1], b"# header\n"))
    finally:
        writer.close()
    assert len(set(names)) == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(names)
    assert writer.errors == 0
    assert [writer.path(h).read_text() for h in handles] == ["# header\n"] * 3


def test_a_file_that_cannot_be_created_is_counted_and_named(tmp_path):
    writer = LogWriter(tmp_path)
    (tmp_path / "0001_flight_x.csv").write_text("someone else's")
    handle = writer.open("0001_flight_x.csv", b"# ours\n")  # exists: never overwritten
    writer.write(handle, b"1,2\n")
    writer.close()
    assert (tmp_path / "0001_flight_x.csv").read_text() == "someone else's"
    assert writer.errors == 1
    assert "0001_flight_x.csv: cannot be created (File exists)" in writer.failures[0]


def test_a_full_disk_loses_only_new_lines_and_every_line_before_stays_whole(small_disk):
    """Bad input tried: the log directory's file system fills up mid-flight (a real 256 KiB
    tmpfs), then space comes back."""
    cols = ["time", *(f"c{k}" for k in range(20))]
    writer = LogWriter(small_disk, fsync_s=0.05)
    book = Logbook(writer, cols, ["s"] * len(cols), "0" * 64)
    filler = small_disk / "filler"
    k = 0

    def rows(n: int) -> None:
        nonlocal k
        for _ in range(n):
            row = np.full(len(cols), 1.0 / 3.0) * k
            row[0] = k * 0.01
            book.row(row)
            k += 1
            time.sleep(0.0005)

    rows(200)
    # Fill the disk with another file until the kernel refuses.
    with open(filler, "wb", buffering=0) as handle, contextlib.suppress(OSError):
        while True:
            handle.write(b"x" * 4096)
    rows(300)  # these cannot be written
    deadline = time.monotonic() + 5
    while writer.lost_lines == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert writer.lost_lines > 0
    assert writer.failing is not None
    filler.unlink()  # space again
    rows(200)
    writer.close()
    assert writer.failing is None  # writing resumed by itself
    header, data = read_log(writer.path(book.flight))  # every line whole and parsable
    assert header == cols
    times = np.round(data[:, 0] / 0.01).astype(int)
    assert times[:200].tolist() == list(range(200))  # everything before the fault is there
    assert times[-1] == k - 1  # and writing resumed after it
    assert len(data) + writer.lost_lines == k  # every row written or counted as lost
    raw = writer.path(book.flight).read_bytes()
    assert raw.endswith(b"\n")


def test_a_record_that_cannot_be_formatted_is_kept_and_counted(tmp_path):
    # Bad input: a library's log call whose arguments do not fit its format string.
    import json
    import logging

    from agent.logs import JsonLinesHandler

    writer = LogWriter(tmp_path)
    handler = JsonLinesHandler(writer, writer.open("0001_exec_x.jsonl"))
    logger = logging.getLogger("test.unformattable")
    logger.addHandler(handler)
    logger.propagate = False
    try:
        logger.warning("two values %d %d", 1)  # raises inside getMessage
        logger.warning("fine %d", 2)
    finally:
        logger.removeHandler(handler)
        writer.close()
    lines = [json.loads(x) for x in (tmp_path / "0001_exec_x.jsonl").read_text().splitlines()]
    assert [e["message"] for e in lines] == ["unformattable log record: two values %d %d", "fine 2"]
    assert handler.unformattable == 1
