"""`sysid identify`: the JSON contract, batches, and every kind of bad input.

Bad input tried: NaN and inf rows, a non-numeric cell, a constant input column, a record too
short for the requested p, one too short even for the automatic p = 1 and one too short for
the aircraft method's parameters, a column that does not exist, a row with too many fields,
non-uniform time (a step 25 % long: irregular, refused; a gap of 1.5 sample times or more
splits the record into a batch of its segments), time going backwards, an empty file, two
files at different rates, a missing file, an input also given as output, and no --inputs at
all. Each gives a clear message and exit 2 (bad input), never a traceback.
"""

from __future__ import annotations

import csv
import errno
import json
import os
import signal
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from agent.cli import main
from agent.ident import reference
from agent.ident.document import ResultDocument
from tests.capped import sysid
from tests.waiting import until_sync

ROOT = Path(__file__).resolve().parents[1]
# An interrupted command's exit: its interpreter has already started, so this only bounds a
# hang (a command that ignored SIGINT), well inside the suite's per-test timeout.
INTERRUPTED_DEADLINE_S = 60
LAT = ["--inputs", "aileron,rudder", "--outputs", "beta,p,r,phi"]
CONTRACT = {
    "dt",
    "order",
    "inputs",
    "outputs",
    "A",
    "B",
    "C",
    "D",
    "Ac",
    "Bc",
    "stable",
    "tic",
    "tic_avg",
    "modes",
    "method",
    "preprocessing",
    "okid",
    "aircraft",
}
OKID_KEYS = {"markov", "markov_auto", "singular_values", "tic_avg", "frequency"}
MODE_KEYS = {
    "name",
    "eigenvalue",
    "frequency_rad_s",
    "damping",
    "time_constant_s",
    "msv",
    "mci",
    "moi",
    "emac",
    "mpc",
    "cmi",
    "eigenvalue_std",
    "frequency_std_rad_s",
    "damping_std",
}


def write(path: Path, columns: dict[str, np.ndarray]) -> Path:
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(columns)
        for row in zip(*columns.values(), strict=True):
            writer.writerow([repr(float(v)) for v in row])
    return path


@pytest.fixture
def lateral_csv(tmp_path):
    return write(tmp_path / "lat.csv", reference.make_record(reference.LATERAL).columns())


def run_json(capsys, *args) -> tuple[int, dict]:
    code = main(["identify", *args, "--json"])
    out = capsys.readouterr().out
    assert out.count("\n") == 1, "exactly one JSON object on stdout"
    return code, json.loads(out)


def test_json_contract_on_a_noise_free_record(capsys, lateral_csv):
    # OKID/ERA is exact on the thesis's discrete plant; named by role, `auto` would fit the
    # aircraft method, whose continuous-time spectra are not (see the next test).
    code, doc = run_json(capsys, str(lateral_csv), *LAT, "--method", "time")
    assert code == 0
    assert set(doc) >= CONTRACT
    assert doc["dt"] == pytest.approx(0.02)
    assert doc["order"] == 4
    # OKID/ERA's own part: p (chosen: every p tried is listed), the Hankel singular values,
    # the OKID/ERA model's fit; no whole-aircraft part.
    assert set(doc["okid"]) == OKID_KEYS
    assert doc["okid"]["markov"] in {t["markov"] for t in doc["okid"]["markov_auto"]}
    assert len(doc["okid"]["singular_values"]) >= doc["order"]
    assert doc["okid"]["frequency"] is None
    assert doc["aircraft"] is None
    # The document reads back as the one typed form every consumer uses.
    assert ResultDocument.model_validate(doc).model_dump(mode="json") == doc
    assert doc["inputs"] == ["aileron", "rudder"]
    assert np.allclose(doc["Ac"], reference.LATERAL.A, rtol=0, atol=1e-6)
    assert np.allclose(doc["Bc"], reference.LATERAL.B, rtol=0, atol=1e-6)
    assert doc["stable"] is True
    assert doc["tic_avg"] < 1e-6
    assert set(doc["tic"]) == {"beta", "p", "r", "phi"}
    assert all(set(m) == MODE_KEYS for m in doc["modes"])
    names = {m["name"] for m in doc["modes"]}
    assert names == {"Dutch roll", "roll", "spiral"}
    dutch = next(m for m in doc["modes"] if m["name"] == "Dutch roll")
    assert dutch["eigenvalue"] == pytest.approx([-3.69210903, 3.18186935], rel=1e-6)
    assert dutch["time_constant_s"] is None
    trim = doc["trim"][0]
    assert trim["beta"] == pytest.approx(reference.LATERAL.trim_outputs[0], rel=1e-9)


def test_auto_is_the_aircraft_method_for_an_axis_named_by_role_unless_okid_is_asked_for(
    capsys, lateral_csv
):
    """An axis's four outputs named by role: the aircraft method, whose A is close to the
    truth without OKID's exactness on a discrete plant (the DFT of samples is not the
    continuous transform). --markov, --order or --no-refine ask for OKID and get it."""
    code, doc = run_json(capsys, str(lateral_csv), *LAT)
    assert code == 0
    assert doc["method"] == "aircraft"
    assert np.allclose(doc["Ac"], reference.LATERAL.A, rtol=0.05, atol=0.01)
    # The method's own part, and no OKID part (no p, no Hankel singular values).
    assert doc["okid"] is None
    assert [axis["name"] for axis in doc["aircraft"]["axes"]] == ["lateral"]
    for extra in (["--markov", "3"], ["--order", "4"], ["--no-refine"]):
        code, doc = run_json(capsys, str(lateral_csv), *LAT, *extra)
        assert code == 0
        assert doc["method"] == "time", extra
        assert doc["aircraft"] is None
    assert doc["okid"]["markov_auto"] is not None  # --no-refine: p still chosen


def test_json_reports_cramer_rao_uncertainty_and_preprocessing(capsys, tmp_path):
    model = reference.LATERAL
    noise = {"beta": 0.002, "p": 0.005, "r": 0.005, "phi": 0.002}
    path = write(tmp_path / "noisy.csv", reference.make_record(model, noise=noise).columns())
    code, doc = run_json(capsys, str(path), *LAT)
    assert code == 0
    assert doc["refinement"]["hold"] == "zoh"
    assert "okid_tic_avg" not in doc["refinement"]  # OKID/ERA's own fit is its part's
    assert doc["preprocessing"]["record_dt"] == pytest.approx(0.02)
    for mode in doc["modes"]:
        re_std, _im_std = mode["eigenvalue_std"]
        assert 0 < re_std < 0.05 * abs(mode["eigenvalue"][0])
        assert mode["frequency_std_rad_s"] > 0
    # The estimated noise is what the record carries.
    assert doc["refinement"]["noise_std"]["p"] == pytest.approx(0.005, rel=0.15)
    assert np.array(doc["refinement"]["Ac_std"]).shape == (4, 4)

    code, doc = run_json(capsys, str(path), *LAT, "--no-refine", "--decimation", "2")
    assert code == 0
    assert doc["refinement"] is None
    assert doc["dt"] == pytest.approx(0.04)
    assert all(m["eigenvalue_std"] is None for m in doc["modes"])


def test_frequency_method_from_the_command_line(capsys, tmp_path):
    model = reference.LATERAL
    u = reference.thesis_multisine(model, 0.02, duration=60.0)
    y = reference.simulate(model, u, 0.02)
    columns = {"time": np.arange(u.shape[0]) * 0.02, "aileron": u[:, 0], "rudder": u[:, 1]}
    columns.update({name: y[:, j] for j, name in enumerate(model.outputs)})
    path = write(tmp_path / "periodic.csv", columns)
    code, doc = run_json(capsys, str(path), *LAT, "--method", "frequency", "--trim", "none")
    assert code == 0
    assert doc["method"] == "frequency"
    spectra = doc["okid"]["frequency"]
    assert spectra["periodic"] is True
    assert spectra["segment_s"] == pytest.approx(20.0)
    assert spectra["markov_from"] == "observer fit to the FRF"
    assert np.allclose(doc["Ac"], model.A, rtol=0.01, atol=0.01)
    code, doc = run_json(capsys, str(path), *LAT, "--method", "frequency", "--period", "7.3")
    assert code == 0  # a wrong period is not an error: it leaks, and says so
    assert any("leakage" in w or "period" in w for w in doc["warnings"])
    # Bad input tried: a negative period and one longer than the record.
    for period, message in (
        ("-3", "give a finite, positive number of seconds"),
        ("500", "excitation period"),
    ):
        code, doc = run_json(capsys, str(path), *LAT, "--method", "frequency", "--period", period)
        assert code == 2
        assert message in doc["error"]["message"]


def test_a_pole_at_z_0_is_left_out_of_the_json_with_a_note_never_a_null_eigenvalue(
    capsys, tmp_path
):
    """Bad input tried: a record whose aileron reaches the plant one sample late, identified
    at order 5: ERA realises the delay as a pole at z ≈ 0, which `--json` printed as a mode of
    eigenvalue [null, null] with "divide by zero in log" on stderr, and exit 0. Now the mode
    is left out, the document says why, and no numpy warning is raised."""
    model, dt = reference.LATERAL, 0.02
    record = reference.make_record(model, dt=dt)
    late = record.inputs.copy()
    late[1:, 0] = record.inputs[:-1, 0]
    y = reference.simulate(model, late - np.asarray(model.trim_inputs), dt)
    columns = record.columns() | dict(zip(model.outputs, y.T, strict=True))
    path = write(tmp_path / "late.csv", columns)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        code = main(["identify", str(path), *LAT, "--method", "time", "--order", "5", "--json"])
    out = capsys.readouterr().out
    assert code == 0
    doc = json.loads(out)
    assert all(isinstance(v, float) for m in doc["modes"] for v in m["eigenvalue"])
    assert {m["name"] for m in doc["modes"]} == {"Dutch roll", "roll", "spiral"}
    (note,) = doc["poles_left_out"]
    assert "a pole at z ≈ 0" in note
    assert "left out of the modes" in note
    assert doc["missing_modes"] == []


def test_text_output_has_the_mode_table(capsys, lateral_csv):
    assert main(["identify", str(lateral_csv), *LAT, "--markov", "2"]) == 0
    out = capsys.readouterr().out
    assert "Dutch roll" in out
    assert "spiral" in out
    assert "TIC:" in out
    assert "EMAC" in out


def test_axes_from_config_and_given_order(capsys, lateral_csv):
    code, doc = run_json(capsys, str(lateral_csv), "--axes", "lateral", "--order", "2")
    assert code == 0
    assert doc["order"] == 2
    assert doc["outputs"] == ["beta", "p", "r", "phi"]
    assert doc["Ac"] is None  # two states for four outputs: no output coordinates
    assert doc["coordinates"] == "era"


def test_batch_of_two_files_and_time_window(capsys, tmp_path):
    files = [
        write(tmp_path / f"r{s}.csv", reference.make_record(reference.LATERAL, seed=s).columns())
        for s in (1, 2)
    ]
    code, doc = run_json(
        capsys, *map(str, files), *LAT, "--start", "0.2", "--end", "25", "--method", "time"
    )
    assert code == 0
    assert len(doc["trim"]) == 2
    assert np.allclose(doc["Ac"], reference.LATERAL.A, atol=1e-6)


def _joined(tmp_path, jump_s: float = 30.08, tail: int = 0) -> tuple[Path, list[Path]]:
    """Two 10 s records written as one file, the second's time jumping `jump_s` past the
    first's end (a research aircraft's lateral files: two manoeuvres with a 30.08 s jump),
    and `tail` samples after a second jump; with the two as files of their own."""
    parts = [reference.make_record(reference.LATERAL, seed=s, duration=10.0) for s in (1, 2)]
    columns = [p.columns() for p in parts]
    if tail:
        columns.append({k: v[:tail] for k, v in columns[0].items()})
    joined: dict[str, list] = {k: [] for k in columns[0]}
    offset = 0.0
    for c in columns:
        for k, v in c.items():
            joined[k].append(v + offset if k == "time" else v)
        offset = joined["time"][-1][-1] + jump_s - c["time"][0]
    path = write(tmp_path / "joined.csv", {k: np.concatenate(v) for k, v in joined.items()})
    files = [write(tmp_path / f"part{k}.csv", c) for k, c in enumerate(columns[:2])]
    return path, files


def test_a_record_with_gaps_is_split_into_a_batch_of_its_segments(capsys, tmp_path):
    """Bad input tried: two manoeuvres joined in one file by a 30.08 s jump in time, and a
    third stretch of 50 samples after another jump. The file is identified as the batch of
    its uniform segments (the same model as the two written as files of their own), the
    short stretch left out, and the notes say both; a window that leaves the gap out is one
    record and no note."""
    joined, files = _joined(tmp_path, tail=50)
    code, doc = run_json(capsys, str(joined), *LAT, "--method", "time")
    assert code == 0
    assert len(doc["trim"]) == 2
    notes = [w for w in doc["warnings"] if w.startswith("joined.csv:")]
    assert any(
        "2 gap(s) in time (30.08 s at" in w and "2 uniform segment(s) of the batch" in w
        for w in notes
    ), notes
    assert any("shorter than 100 samples left out" in w and "(50 samples)" in w for w in notes)
    code, batch = run_json(capsys, *map(str, files), *LAT, "--method", "time")
    assert code == 0
    assert np.allclose(doc["Ac"], batch["Ac"], rtol=1e-9, atol=1e-12)
    # The window first: the gap outside it is no concern.
    code, first = run_json(capsys, str(joined), *LAT, "--method", "time", "--end", "10")
    assert code == 0
    assert len(first["trim"]) == 1
    assert not any(w.startswith("joined.csv:") for w in first["warnings"])


def test_a_record_whose_segments_are_all_short_is_refused(capsys, tmp_path):
    """Bad input tried: a file whose samples come in bursts of 50 between jumps: nothing an
    identification could use, said so (exit 2), not a batch of fragments."""
    rows = reference.make_record(reference.LATERAL, duration=10.0).columns()
    time = rows["time"].copy()
    time[50:] += 5.0
    time[100:] += 5.0
    rows = {**rows, "time": time}
    path = write(tmp_path / "bursts.csv", {k: v[:150] for k, v in rows.items()})
    code, doc = run_json(capsys, str(path), *LAT, "--trim", "none")
    assert code == 2
    assert (
        "every segment between its 2 gap(s) is shorter than 100 samples" in doc["error"]["message"]
    )


def test_trim_none_keeps_the_offset_and_fails_honestly(capsys, lateral_csv):
    """Without trim removal the constant trim offsets are unmodelled: the fit is poor."""
    code, doc = run_json(capsys, str(lateral_csv), *LAT, "--trim", "none", "--markov", "2")
    assert code == 0
    assert doc["trim"] == [dict.fromkeys(["aileron", "rudder", "beta", "p", "r", "phi"], 0.0)]
    assert doc["tic_avg"] > 0.01


def _corrupt(tmp_path, name, edit) -> Path:
    record = reference.make_record(reference.LATERAL, duration=10.0)
    columns = {k: v.astype(object) for k, v in record.columns().items()}
    rows = [list(r) for r in zip(*columns.values(), strict=True)]
    header = list(columns)
    header, rows = edit(header, rows)
    path = tmp_path / name
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        writer.writerows(rows)
    return path


def _set(row_index, column, value):
    def edit(header, rows):
        rows[row_index][header.index(column)] = value
        return header, rows

    return edit


def _constant_rudder(header, rows):
    for row in rows:
        row[header.index("rudder")] = 0.0
    return header, rows


def _jitter(header, rows):
    rows[100][0] = float(rows[100][0]) + 0.005
    return header, rows


def _backwards(header, rows):
    rows[50][0], rows[51][0] = rows[51][0], rows[50][0]
    return header, rows


def _extra_field(header, rows):
    rows[10].append(1.0)
    return header, rows


def _rename_p(header, rows):
    header[header.index("p")] = "P"
    return header, rows


def _empty(header, rows):
    return header, []


BAD = [
    ("nan.csv", _set(200, "p", "nan"), [], "line 202: non-finite value 'nan' in column 'p'"),
    ("inf.csv", _set(30, "beta", "inf"), [], "non-finite value 'inf' in column 'beta'"),
    ("text.csv", _set(5, "r", "n/a"), [], "'n/a' in column 'r' is not a number"),
    # float() reads 1_000 as 1000; a CSV reader must not.
    ("underscore.csv", _set(120, "p", "1_000"), [], "line 122: '1_000' in column 'p' is not a"),
    # OKID/ERA needs every input moved; the aircraft method leaves one out and says so
    # (test_a_control_the_record_did_not_move_is_left_out_by_name).
    ("const.csv", _constant_rudder, ["--method", "time"], "input 'rudder' is constant"),
    ("short.csv", lambda h, r: (h, r[:60]), ["--markov", "10"], "need at least"),
    (
        "short_auto.csv",
        lambda h, r: (h, r[100:112]),
        ["--trim", "none", "--method", "time"],
        "12 samples give 11 regression rows",
    ),
    (
        "short_aircraft.csv",
        lambda h, r: (h, r[100:112]),
        ["--trim", "none"],
        "frequency bins cannot determine",
    ),
    ("missing.csv", _rename_p, [], "no column(s) 'p'"),
    ("fields.csv", _extra_field, [], "line 12: 8 fields, the header has 7"),
    ("jitter.csv", _jitter, [], "sampling is not uniform"),
    ("back.csv", _backwards, [], "time does not increase"),
    ("empty.csv", _empty, [], "0 data row(s)"),
]


@pytest.mark.parametrize(("name", "edit", "extra", "message"), BAD, ids=[b[0] for b in BAD])
def test_bad_data_is_a_clear_error_with_exit_2(tmp_path, capsys, name, edit, extra, message):
    path = _corrupt(tmp_path, name, edit)
    with warnings.catch_warnings():  # a library's warning (numpy's on an empty file) is none
        warnings.simplefilter("error")
        assert main(["identify", str(path), *LAT, *extra]) == 2
    err = capsys.readouterr().err
    assert message in err, err
    assert "Traceback" not in err
    code = main(["identify", str(path), *LAT, *extra, "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert code == 2
    assert doc["error"]["exit"] == 2
    assert message in doc["error"]["message"]


def test_a_control_the_record_did_not_move_is_left_out_by_name(tmp_path, capsys):
    """Bad input: a lateral record whose rudder column is constant. The aircraft method
    identifies what the aileron moved, without the rudder, and says so; it does not refuse the
    record nor fit the rudder to nothing."""
    path = _corrupt(tmp_path, "still.csv", _constant_rudder)
    code, doc = run_json(capsys, str(path), *LAT)
    assert code == 0
    assert doc["method"] == "aircraft"
    assert doc["inputs"] == ["aileron"]
    assert any(w.startswith("rudder not moved by this record (constant") for w in doc["warnings"])


HEADER = "time,aileron,rudder,beta,p,r,phi\n"
RAW = [
    ("nul.csv", b"\x00" * 4096, "NUL bytes in the header: a binary file"),
    ("nonewline.csv", b"0," * (1 << 20), "a line longer than 1048576 characters"),
    (
        "cell.csv",
        (HEADER + "0,1,2,3,4,5," + "7" * 200_000 + "\n0.02,1,2,3,4,5,6\n").encode(),
        "line 2: not a readable CSV line (field larger than field limit",
    ),
    (
        "semicolon.csv",
        (HEADER.replace(",", ";") + "0;1;2;3;4;5;6\n").encode(),
        "the fields are separated by ';'",
    ),
    (
        "latin1.csv",
        HEADER.encode() + "0,1,2,3,4,5,6 \xb0\n".encode("latin-1"),
        "not a text CSV file",
    ),
]


def test_a_last_line_cut_mid_number_is_refused_with_what_to_do(tmp_path, capsys, lateral_csv):
    """Bad input tried: a record whose last line lost its line end and its last digits (a copy
    that stopped): the cut number used to be read as it stood. A record ending with a line end
    and blank space after it is read."""
    whole = lateral_csv.read_bytes()
    cut = tmp_path / "cut.csv"
    cut.write_bytes(whole.rstrip(b"\r\n")[:-2])
    lines = whole.count(b"\n")
    assert main(["identify", str(cut), *LAT, "--json"]) == 2
    message = json.loads(capsys.readouterr().out)["error"]["message"]
    assert f"line {lines}: the last line has no line end" in message
    assert "end it with a newline, else delete it" in message
    spaced = tmp_path / "spaced.csv"
    spaced.write_bytes(whole + b"  \n\n ")
    assert main(["identify", str(spaced), *LAT, "--method", "time", "--json"]) == 0
    capsys.readouterr()


@pytest.mark.parametrize(("name", "content", "message"), RAW, ids=[r[0] for r in RAW])
def test_files_that_are_not_csv_records_are_a_clear_error(tmp_path, capsys, name, content, message):
    """Bad input tried: a file of NUL bytes, one with no newline (as /dev/zero), a 200 KB cell
    (beyond the csv module's field limit), a spreadsheet's ';'-separated export, a Latin-1
    byte: exit 2 with the reason, no traceback, with and without --json."""
    path = tmp_path / name
    path.write_bytes(content)
    assert main(["identify", str(path), *LAT]) == 2
    err = capsys.readouterr().err
    assert message in err, err
    assert "Traceback" not in err
    assert main(["identify", str(path), *LAT, "--json"]) == 2
    assert message in json.loads(capsys.readouterr().out)["error"]["message"]


def test_a_utf8_byte_order_mark_is_read(tmp_path, capsys):
    """Excel's "CSV UTF-8" starts the file with a byte-order mark: the record reads as without
    it, to the same model."""
    plain = write(tmp_path / "plain.csv", reference.make_record(reference.LATERAL).columns())
    marked = tmp_path / "marked.csv"
    marked.write_bytes(b"\xef\xbb\xbf" + plain.read_bytes())
    assert main(["identify", str(plain), *LAT, "--json"]) == 0
    expected = json.loads(capsys.readouterr().out)
    assert main(["identify", str(marked), *LAT, "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["tic_avg"] == expected["tic_avg"]


def test_files_at_different_rates_cannot_be_batched(tmp_path, capsys):
    a = write(tmp_path / "a.csv", reference.make_record(reference.LATERAL).columns())
    b = write(tmp_path / "b.csv", reference.make_record(reference.LATERAL, dt=0.01).columns())
    assert main(["identify", str(a), str(b), *LAT]) == 2
    assert "a batch needs one sample rate" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["nowhere.csv", *LAT], "cannot be read"),
        (["{lat}", "--inputs", "aileron,beta", "--outputs", "beta,p"], "both input and output"),
        (["{lat}"], "give --inputs and --outputs"),
    ],
)
def test_bad_usage_exit_2(capsys, lateral_csv, args, message):
    args = [a.replace("{lat}", str(lateral_csv)) for a in args]
    assert main(["identify", *args]) == 2
    assert message in capsys.readouterr().err


def test_bad_option_values_are_usage_errors(lateral_csv, capsys):
    for bad in (["--markov", "0"], ["--trim", "last:3"], ["--order", "x"]):
        assert main(["identify", str(lateral_csv), *LAT, *bad]) == 2
        assert "usage: sysid identify" in capsys.readouterr().err


def test_identification_failure_is_exit_1(tmp_path, capsys):
    """Order above what the data holds: the data is fine, the identification is not."""
    path = write(tmp_path / "lat.csv", reference.make_record(reference.LATERAL).columns())
    assert main(["identify", str(path), *LAT, "--markov", "1", "--order", "6"]) == 1
    err = capsys.readouterr().err
    assert "identification failed" in err
    assert "rank" in err


def test_console_script_and_module_entry_point(lateral_csv):
    """The real entry point, in a subprocess: `python -m agent identify … --json`."""
    proc = subprocess.run(
        [sys.executable, "-m", "agent", "identify", str(lateral_csv), *LAT, "--json"],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        cwd=ROOT,
    )
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["order"] == 4


def _writer_once_read(fifo: Path, proc: subprocess.Popen) -> int:
    """The FIFO's write end, once the command has opened its read end (ENXIO until then)."""

    def opened() -> int | None:
        assert proc.poll() is None, f"ended before reading its input: {proc.communicate()}"
        try:
            return os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
        except OSError as exc:
            if exc.errno != errno.ENXIO:
                raise
            return None

    return until_sync(opened, f"the command to open {fifo.name}", pause_s=0.01)


@pytest.mark.parametrize("command", ["identify", "analyze"])
def test_ctrl_c_under_json_is_exit_130_with_one_json_object(tmp_path, command):
    """Input: Ctrl-C (SIGINT) while `sysid identify|analyze LOG --json` reads its log, a FIFO
    whose writer has sent nothing yet (the command is then surely at work, inside its run).
    It used to end with a KeyboardInterrupt traceback and an empty stdout."""
    fifo = tmp_path / "lat.csv"
    os.mkfifo(fifo)
    argv = [sys.executable, "-m", "agent", command, str(fifo), *LAT, "--json"]
    # A terminal's Ctrl-C reaches a command that has SIGINT's default: a suite started in the
    # background by a non-interactive shell ignores SIGINT, its children inherit that, and
    # Python then leaves it ignored (the command hung for the whole deadline). An ignored
    # disposition is inherited across exec, a handled one is reset to the default.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        proc = subprocess.Popen(argv, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    finally:
        signal.signal(signal.SIGINT, previous)
    writer = None
    try:
        writer = _writer_once_read(fifo, proc)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=INTERRUPTED_DEADLINE_S)
    finally:
        if writer is not None:
            os.close(writer)
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130, err.decode()
    assert out.count(b"\n") == 1, out
    assert json.loads(out)["error"] == {
        "kind": "interrupted",
        "message": "interrupted (Ctrl-C)",
        "exit": 130,
    }
    assert b"Traceback" not in err
    assert f"sysid {command}: error: interrupted (Ctrl-C)".encode() in err


def test_more_bad_records_each_named(tmp_path, capsys, lateral_csv):
    """Empty time window, trim covering the record, duplicated column, non-UTF-8 bytes,
    a constant output, an oversized file: each exit 2 with the reason."""
    cases = [
        ([str(lateral_csv), *LAT, "--start", "40", "--end", "50"], "fewer than 2 samples"),
        ([str(lateral_csv), *LAT, "--end", "0.3"], "trim window covers the whole"),
    ]
    dup = tmp_path / "dup.csv"
    dup.write_text(lateral_csv.read_text().replace("phi", "p", 1))
    cases.append(([str(dup), "--inputs", "aileron,rudder", "--outputs", "p,r"], "more than once"))
    binary = tmp_path / "binary.csv"
    binary.write_bytes(b"time,aileron\n\xff\xfe\x00garbage\n")
    cases.append(([str(binary), *LAT], "not a text CSV file"))
    record = reference.make_record(reference.LATERAL)
    columns = record.columns()
    columns["phi"] = np.full_like(columns["phi"], 0.01)
    flat = write(tmp_path / "flat.csv", columns)
    cases.append(([str(flat), *LAT], "output 'phi' is constant"))
    for args, message in cases:
        assert main(["identify", *args]) == 2, message
        err = capsys.readouterr().err
        assert message in err, err
        assert "Traceback" not in err


def test_oversized_record_is_refused(monkeypatch, capsys, lateral_csv):
    monkeypatch.setattr("agent.analysis.records.MAX_ROWS", 100)
    assert main(["identify", str(lateral_csv), *LAT]) == 2
    assert "more than 100 rows" in capsys.readouterr().err


def test_invalid_config_in_working_directory_stops_identify(tmp_path, monkeypatch, capsys):
    path = write(tmp_path / "lat.csv", reference.make_record(reference.LATERAL).columns())
    (tmp_path / "config.toml").write_text("[identification]\nmarkov = -3\n")
    monkeypatch.chdir(tmp_path)
    assert main(["identify", str(path), *LAT]) == 2
    assert "identification.markov" in capsys.readouterr().err


def test_short_record_in_a_batch_is_named_not_dropped(tmp_path, capsys):
    long_ = write(tmp_path / "long.csv", reference.make_record(reference.LATERAL).columns())
    cols = reference.make_record(reference.LATERAL).columns()
    short = write(tmp_path / "short.csv", {k: v[100:104] for k, v in cols.items()})
    assert main(["identify", str(long_), str(short), *LAT, "--markov", "5", "--trim", "none"]) == 2
    assert "experiment 1 has 4 samples, too few for 5 Markov" in capsys.readouterr().err


USAGE = [
    ["identify", "--json", "--order", "x", "a.csv"],
    ["identify", "--json"],
    ["analyze", "--json", "--bogus", "logs"],
    ["report", "--json", "logs"],
    ["excite", "--json", "--preset", "sideways"],
    ["sim", "--json", "--speed-kts", "fast"],
]


@pytest.mark.parametrize("argv", USAGE, ids=[" ".join(a) for a in USAGE])
def test_a_usage_error_under_json_is_one_json_object(capsys, argv):
    """Bad input tried: a non-numeric --order, a missing file argument, an unknown option, a
    missing --out, an unknown preset, a non-numeric speed: argparse's refusal is exit 2 and, under
    --json, exactly one JSON object on stdout (its usage still on stderr)."""
    assert main(argv) == 2
    out, err = capsys.readouterr()
    doc = json.loads(out)  # exactly one object: anything more fails to parse
    assert doc["error"]["kind"] == "usage"
    assert doc["error"]["exit"] == 2
    assert doc["error"]["message"] in err
    assert "usage:" in err


def test_odd_settings_and_values_get_one_clear_reason(tmp_path, capsys):
    """Bad input tried: --period nan (a ValueError traceback before), --order 1000 (its
    reason used to be repeated for each of 13 p), a record's inputs scaled by 1e200 (called
    "nothing moved" before: its squares overflow)."""
    path = write(tmp_path / "lat.csv", reference.make_record(reference.LATERAL).columns())
    assert main(["identify", str(path), *LAT, "--method", "frequency", "--period", "nan"]) == 2
    assert "--period: nan: give a finite, positive number of seconds" in capsys.readouterr().err
    assert main(["identify", str(path), *LAT, "--order", "1000"]) == 1
    err = capsys.readouterr().err
    assert err.count("order 1000 is outside") == 1, err
    assert "p = 1, 2, 3" in err
    columns = reference.make_record(reference.LATERAL).columns()
    # The inputs alone: outputs that large are refused first, as no flight in radians.
    huge = {k: (v * 1e200 if k in ("aileron", "rudder") else v) for k, v in columns.items()}
    big = write(tmp_path / "big.csv", huge)
    assert main(["identify", str(big), *LAT]) == 2
    err = capsys.readouterr().err
    assert "overflow" in err
    assert "nothing moved" not in err


def test_a_decimation_asks_for_okid_and_the_aircraft_method_refuses_it(capsys, lateral_csv):
    """Input: --decimation 2 on a lateral record named by role. `auto` used to pick the
    aircraft method and ignore the factor (the result said decimation 1); a decimation is
    OKID's, so it now asks for OKID, and `--method aircraft --decimation 2` is refused with
    what to do. A factor of 1 (none) is what the aircraft method does anyway."""
    code, doc = run_json(capsys, str(lateral_csv), *LAT, "--decimation", "2")
    assert code == 0
    assert doc["method"] == "time"
    assert doc["preprocessing"]["decimation"] == 2
    aircraft = [str(lateral_csv), *LAT, "--method", "aircraft", "--decimation"]
    code, doc = run_json(capsys, *aircraft, "2")
    assert code == 2
    message = doc["error"]["message"]
    assert "method 'aircraft' fits the record's spectra at its own rate and takes no " in message
    assert "give --method time or frequency" in message
    code, doc = run_json(capsys, *aircraft, "1")
    assert code == 0
    assert doc["method"] == "aircraft"


def test_a_decimation_beyond_the_bound_is_refused_before_any_filter(tmp_path, lateral_csv):
    """Bad input tried: `identify --method time --decimation 10000000`, and the same factor as
    `[identification] decimation` in a config (`config check` used to accept it): the
    filter, 2 × 10⁸ taps, was built before the record's length was checked (1.6 GB, or a
    MemoryError traceback). In a process of its own with a memory limit."""
    args = ("identify", str(lateral_csv), *LAT, "--method", "time")
    done = sysid(*args, "--decimation", "10000000", cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert "--decimation 10000000: give 1 to 1000" in done.stderr
    (tmp_path / "config.toml").write_text("[identification]\ndecimation = 10000000\n")
    done = sysid(*args, cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert "identification.decimation" in done.stderr
    assert "an integer from 1 to 1000, got 10000000" in done.stderr


def test_an_input_the_aircraft_method_cannot_place_is_refused_by_name(capsys, tmp_path):
    """Bad input tried: a lateral record with a measured column given as a third input whose
    name no channel role carries (a research aircraft's thrust column was dropped so, its
    only trace deep in the result), and the elevator given with only lateral outputs. Each is
    refused by name with the reason and the way out (exit 2); OKID/ERA (--method time) takes
    the unknown one."""
    columns = reference.make_record(reference.LATERAL, duration=10.0).columns()
    rng = np.random.default_rng(3)
    columns["T_meas"] = 100 + rng.standard_normal(columns["time"].size)
    columns["elevator"] = 0.1 * rng.standard_normal(columns["time"].size)
    path = write(tmp_path / "thrust.csv", columns)
    outputs = ["--outputs", "beta,p,r,phi"]
    code, doc = run_json(capsys, str(path), "--inputs", "aileron,rudder,T_meas", *outputs)
    assert code == 2
    message = doc["error"]["message"]
    assert "input 'T_meas' has no role the aircraft method knows" in message
    assert "thrust = 'T_meas'" in message
    code, doc = run_json(capsys, str(path), "--inputs", "aileron,rudder,elevator", *outputs)
    assert code == 2
    assert "input 'elevator' (elevator) moves the longitudinal axis" in doc["error"]["message"]
    assert "airspeed, alpha, q, theta missing" in doc["error"]["message"]
    args = ["--inputs", "aileron,rudder,T_meas", *outputs, "--method", "time"]
    code, doc = run_json(capsys, str(path), *args)
    assert code == 0
    assert doc["inputs"] == ["aileron", "rudder", "T_meas"]


def _in_degrees(tmp_path, name: str, header: dict[str, str] | None = None) -> Path:
    """The A.2 lateral record with its angles in degrees and rates in deg/s, its header's
    cells renamed by `header` (a unit declared there), and the time in ms where asked."""
    columns = reference.make_record(reference.LATERAL, duration=10.0).columns()
    scaled = {
        k: (np.degrees(v) if k in ("beta", "p", "r", "phi") else v) for k, v in columns.items()
    }
    if header and "time" in header:
        scaled["time"] = scaled["time"] * 1000
    return write(tmp_path / name, {(header or {}).get(k, k): v for k, v in scaled.items()})


def test_a_record_in_degrees_is_named_so_and_read_once_its_units_are_declared(capsys, tmp_path):
    """Bad input tried: the A.2 lateral record with its angles in degrees and its rates in
    deg/s under plain names (a business jet's CSV in degrees was read as radians: a spurious
    −1035 1/s mode and no warning). Refused, naming the column, what it reaches and the two
    ways to declare its unit; identified once they are declared, in the header (`beta [deg]`,
    `r (deg/s)`, `time [ms]`) or by --units, to the model of the same record in radians, with
    the units read echoed in the result; a unit not known, or of another kind than the
    column's role (a speed for an angle), a --units entry without its unit and a time column
    declared in degrees are refused by name."""
    plain = _in_degrees(tmp_path, "plain.csv")
    code, doc = run_json(capsys, str(plain), *LAT, "--method", "time")
    assert code == 2
    message = doc["error"]["message"]
    beta = reference.make_record(reference.LATERAL, duration=10.0).columns()["beta"]
    peak = np.degrees(np.max(np.abs(beta)))
    assert f"column 'beta' (beta) reaches {peak:.4g}; in rad no flight goes beyond 1" in message
    assert "these look like degrees" in message
    assert "'beta [deg]'" in message
    assert "--units beta=deg" in message
    si = write(
        tmp_path / "si.csv", reference.make_record(reference.LATERAL, duration=10.0).columns()
    )
    code, reference_doc = run_json(capsys, str(si), *LAT, "--method", "time")
    assert code == 0
    header = {"time": "time [ms]", "beta": "beta [deg]", "p": "p [deg/s]", "r": "r (deg/s)"}
    header["phi"] = "phi [degrees]"
    declared = _in_degrees(tmp_path, "declared.csv", header)
    code, doc = run_json(capsys, str(declared), *LAT, "--method", "time")
    assert code == 0, doc
    assert np.allclose(doc["Ac"], reference_doc["Ac"], rtol=1e-6, atol=1e-9)
    assert doc["dt"] == pytest.approx(reference_doc["dt"])
    (units,) = [w for w in doc["warnings"] if w.startswith("declared.csv: units:")]
    assert "beta in deg, converted to rad" in units
    assert "r in deg/s, converted to rad/s" in units
    given = ["--units", "beta=deg,p=deg/s,r=deg/s,phi=deg"]
    code, doc = run_json(capsys, str(plain), *LAT, "--method", "time", *given)
    assert code == 0, doc
    assert np.allclose(doc["Ac"], reference_doc["Ac"], rtol=1e-6, atol=1e-9)
    assert main(["identify", str(plain), *LAT, "--units", "beta=furlongs"]) == 2
    assert "unit 'furlongs' is not one of rad, deg" in capsys.readouterr().err
    code, doc = run_json(capsys, str(plain), *LAT, "--units", "beta=kt")
    assert code == 2
    assert "'beta' is declared in kt, but its role beta is angle (rad)" in doc["error"]["message"]
    # A --units entry without its unit, and a time column declared in degrees.
    assert main(["identify", str(plain), *LAT, "--units", "beta"]) == 2
    assert "--units takes NAME=UNIT,…; got 'beta'" in capsys.readouterr().err
    odd = _in_degrees(tmp_path, "odd_time.csv", {"time": "time [deg]"})
    code, doc = run_json(capsys, str(odd), *LAT)
    assert code == 2
    assert "the time column's unit must be one of s, sec" in doc["error"]["message"]


def test_a_longitudinal_record_without_a_throttle_column_is_told_how(capsys, tmp_path):
    """Bad input tried: `--axes longitudinal` on a record with no throttle column (a glider's,
    or a business jet's whose thrust was not logged): refused naming the column, and with
    the options that identify it without it."""
    columns = reference.make_record(reference.MODELS["longitudinal"], duration=10.0).columns()
    del columns["throttle"]
    path = write(tmp_path / "glider.csv", columns)
    code, doc = run_json(capsys, str(path), "--axes", "longitudinal")
    assert code == 2
    message = doc["error"]["message"]
    assert "no column(s) 'throttle'" in message
    assert "without throttle: --inputs elevator --outputs Vt,alpha,q,theta" in message


def test_sim_lists_its_aircraft_and_asks_for_the_speed_of_one_it_does_not_know(capsys):
    """`sysid sim --list-aircraft`: the aircraft JSBSim holds, the benchmark's six with the
    speed each flies at (their default). Bad input tried: an aircraft whose trim speed is not
    known, without --speed-kts: refused (exit 2) by name before anything flies, where 60 kt
    would have stalled it or failed its trim."""
    from agent.sim.aircraft import FLOWN

    assert main(["sim", "--list-aircraft", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert set(FLOWN) <= set(doc["aircraft"])
    assert doc["benchmark"]["t6texan2"]["speed_kts"] == FLOWN["t6texan2"][0]
    assert "c310" in doc["aircraft"]
    assert main(["sim", "--list-aircraft"]) == 0
    assert "t6texan2     150 kt" in capsys.readouterr().out
    code, doc = main(["sim", "--aircraft", "c310", "--json"]), json.loads(capsys.readouterr().out)
    assert code == 2
    assert "give --speed-kts for c310" in doc["error"]["message"]


def test_a_lateral_csv_with_airspeed_and_pitch_columns_has_its_kinematics(capsys, tmp_path):
    """A lateral run (--outputs beta,p,r,phi) of a CSV that also records the airspeed and θ
    (the config's Vt and theta): they are read as the flight's states and the kinematics are
    known (a research aircraft's lateral file reported `kinematics: false`); the same file
    without those columns has none."""
    from tests.ident.test_aircraft import DT, gusty_record

    u, air, op, _, _ = gusty_record(seed=5, gust=0.0)
    x = air + op
    columns = {"time": np.arange(len(u)) * DT, "aileron": u[:, 2], "rudder": u[:, 3]}
    columns |= dict(zip(("beta", "p", "r", "phi"), x[:, 4:8].T, strict=True))
    lateral = ["--inputs", "aileron,rudder", "--outputs", "beta,p,r,phi"]
    bare = write(tmp_path / "bare.csv", columns)
    full = write(tmp_path / "full.csv", {**columns, "Vt": x[:, 0], "theta": x[:, 3]})
    code, doc = run_json(capsys, str(full), *lateral)
    assert code == 0
    assert doc["aircraft"]["kinematics"] is True
    code, doc = run_json(capsys, str(bare), *lateral)
    assert code == 0
    assert doc["aircraft"]["kinematics"] is False


def test_held_or_sampled_inputs_are_chosen_by_the_data_and_said(capsys, tmp_path):
    """`held_inputs = "auto"` on a CSV record: computed commands (the A.2 record's multisine,
    and the same played as a staircase updated every 4 samples) are held between samples;
    measured positions (the same with a potentiometer's 0.07° of noise) are interpolated —
    held, a research aircraft's roll mode came out 5 % off where interpolated it was 1 % —
    and the result says which, by name."""
    columns = reference.make_record(reference.LATERAL, duration=10.0).columns()
    noisy = dict(columns)
    rng = np.random.default_rng(0)
    for c in ("aileron", "rudder"):
        noisy[c] = columns[c] + rng.normal(0.0, 0.07, columns[c].size)
    stairs = {
        **columns,
        **{c: np.repeat(columns[c][::4], 4)[: columns[c].size] for c in ("aileron", "rudder")},
    }
    notes = {}
    for name, values in (("clean", columns), ("noisy", noisy), ("stairs", stairs)):
        code, doc = run_json(capsys, str(write(tmp_path / f"{name}.csv", values)), *LAT)
        assert code == 0, doc
        notes[name] = [w for w in doc["warnings"] if w.startswith("inputs taken as")]
    assert notes["clean"] == [notes["stairs"][0]]
    assert notes["clean"][0].startswith("inputs taken as commands held between samples")
    (sampled,) = notes["noisy"]
    assert "sampled positions, interpolated between samples: aileron, rudder" in sampled
    # What the columns are, where the record says (`sysid import` writes it for the servo
    # outputs): commands, held, whatever their data look like.
    declared = tmp_path / "declared.csv"
    text = (tmp_path / "noisy.csv").read_text()
    declared.write_text("# commands: aileron, rudder\n" + text)
    code, doc = run_json(capsys, str(declared), *LAT)
    assert code == 0
    (note,) = [w for w in doc["warnings"] if w.startswith("inputs taken as")]
    assert "the record declares aileron, rudder commands" in note
    config = tmp_path / "held.toml"
    config.write_text("[identification]\nheld_inputs = false\n")
    code, doc = run_json(capsys, str(tmp_path / "clean.csv"), *LAT, "--config", str(config))
    assert code == 0
    assert not [w for w in doc["warnings"] if w.startswith("inputs taken as")]


def test_a_held_out_manoeuvre_is_scored_as_a_validation_scores_it(capsys, tmp_path):
    """`--validate FILE`: the model on a repeat manoeuvre (another seed of the A.2 record)
    that does not start trimmed — cut 3 s into its excitation, so its first half second is
    no trim. With the record's initial state and output biases estimated it scores as the
    model deserves; from the trim it is punished for the record's start (a user rejected a
    good model at 0.314 that way). Both are reported, in text and --json, and the model's
    own records get the estimated-start score beside the raw one. Bad input tried: a
    validation record at another sample rate, refused by name."""
    fitted = write(tmp_path / "fit.csv", reference.make_record(reference.LATERAL).columns())
    repeat = reference.make_record(reference.LATERAL, seed=2).columns()
    start = int(4.0 / 0.02)  # 1 s of lead-in, then 3 s into the excitation
    moving = write(tmp_path / "repeat.csv", {k: v[start:] for k, v in repeat.items()})
    code, doc = run_json(capsys, str(fitted), *LAT, "--validate", str(moving))
    assert code == 0
    v = doc["validation"]
    assert v["files"] == [str(moving)]
    assert v["tic_avg"] < 0.05
    assert v["tic_from_trim_avg"] > 2 * v["tic_avg"]
    assert set(doc["tic_validation"]) == set(doc["tic"])
    assert sum(doc["tic_validation"].values()) <= sum(doc["tic"].values()) + 1e-9
    assert main(["identify", str(fitted), *LAT, "--validate", str(moving)]) == 0
    text = capsys.readouterr().out
    assert f"validation on {moving} (initial state and output biases estimated)" in text
    assert "from its trim (x(0) = 0, no biases)" in text
    slow = {k: v[::2] for k, v in repeat.items()}
    other = write(tmp_path / "slow.csv", slow)
    code, doc = run_json(capsys, str(fitted), *LAT, "--validate", str(other))
    assert code == 2
    assert "a validation record needs their sample rate" in doc["error"]["message"]


def test_the_model_structure_is_selected_by_what_the_record_determines(capsys, tmp_path):
    """`--select`: the A.2 lateral aircraft with no yaw acceleration from the roll rate (ṙ ← p
    set to 0) and no sideslip from the aileron, flown with 0.01 rad of noise. Without
    selection ṙ ← p is fitted to noise (its standard error above its value); with it, that
    derivative is fixed at 0 and listed, every derivative left free stands above its
    standard error, and the held-out manoeuvre is predicted no worse."""
    import dataclasses

    A, B = reference.LATERAL.A.copy(), reference.LATERAL.B.copy()
    A[2, 1] = 0.0
    B[0, 0] = 0.0
    plant = dataclasses.replace(reference.LATERAL, A=A, B=B)
    noise = {"beta": 0.01, "p": 0.01, "r": 0.01, "phi": 0.003}
    fitted, repeat = (
        write(
            tmp_path / f"{name}.csv", reference.make_record(plant, seed=seed, noise=noise).columns()
        )
        for name, seed in (("fit", 1), ("repeat", 2))
    )
    args = [str(fitted), *LAT, "--validate", str(repeat)]
    code, free = run_json(capsys, *args)
    assert code == 0
    code, chosen = run_json(capsys, *args, "--select")
    assert code == 0

    def t(doc):
        values = np.abs(np.hstack([doc["Ac"], doc["Bc"]]))
        std = np.hstack([doc["refinement"]["Ac_std"], doc["refinement"]["Bc_std"]])
        return np.where(std > 0, values / np.where(std > 0, std, 1.0), np.inf)

    assert t(free)[2, 1] < 1.0  # fitted to the noise
    (note,) = [w for w in chosen["warnings"] if w.startswith("model structure selected")]
    assert "r' ← p" in note
    assert chosen["Ac"][2][1] == 0.0
    assert np.all(t(chosen)[np.isfinite(t(chosen))] >= 1.0)
    assert chosen["validation"]["tic_avg"] <= free["validation"]["tic_avg"] * 1.01
    assert not [w for w in free["warnings"] if w.startswith("model structure selected")]
