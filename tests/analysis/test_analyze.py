"""`sysid analyze` on excitation logs: per excitation, batch, a p sweep with the thesis's
table-6.6 view and a recommendation, cross-validation, the agent's log naming, parallel
processes and a Dask cluster started by the test.

The logs are the appendix A.2 lateral model flown three times with different multisine seeds
and sensor noise, written as the agent writes excitation logs (comment header, plan id).

Bad input tried: a sweep that is not markov/order or not integers, an excitation that is not
there, a missing file, --cross with --batch.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from agent.analysis import analyze as an
from agent.analysis import findings
from agent.analysis.identify import Request
from agent.config import Config
from agent.ident import reference
from agent.ident.document import ResultDocument
from agent.ident.settings import Settings
from tests.capped import sysid

ROOT = Path(__file__).resolve().parents[2]
NOISE = {"beta": 2e-3, "p": 2e-3, "r": 1e-3, "phi": 1e-3}
MODEL = reference.MODELS["lateral"]


def excitation_logs(directory: Path, count: int = 3) -> list[Path]:
    paths = []
    for k in range(count):
        record = reference.make_record(MODEL, seed=10 + k, noise=NOISE, duration=25.0)
        cols = record.columns()
        path = directory / f"{k + 2:04d}_lateral_single_20261122.csv"
        lines = [
            "# suas-sysid lateral log, created 2026-11-22",
            f"# excitation plan lateral-{k + 1}, finished, window 0 – 25 s",
            ",".join(cols),
        ]
        table = np.column_stack(list(cols.values()))
        lines += [",".join(f"{v:.9g}" for v in row) for row in table]
        path.write_text("\n".join(lines) + "\n")
        paths.append(path)
    return paths


def truth() -> dict[str, complex]:
    lam = np.linalg.eigvals(MODEL.A)
    pairs = [z for z in lam if z.imag > 1e-6]
    return {"Dutch roll": pairs[0]}


def cases_for(paths, **kwargs):
    config = Config().identification
    inputs, outputs = config.channels.axis_set("lateral")
    request = Request(tuple(paths), inputs, outputs)
    roles = [config.channels.role_of(n) for n in outputs]
    # The agent's own logs: the surfaces' sampled positions, as `sysid analyze` reads them.
    settings = Settings.from_config(config, sampled_inputs=True, refine=False)
    return an.build_cases(request, roles, settings, **kwargs)[0]


def test_per_excitation_sweep_and_recommendation(tmp_path):
    paths = excitation_logs(tmp_path)
    cases = cases_for(paths, batch=False, sweep=("markov", [1, 2, 3, 4]))
    assert len(cases) == 12
    outcomes = an.run_cases(cases, workers=2)  # two spawned processes
    assert all(o.ok for o in outcomes)
    table = findings.sweep_table(cases, outcomes)
    assert [row.setting for row in table] == [{"markov": p} for p in (1, 2, 3, 4)]
    assert all(row.identified == 3 for row in table)
    assert [row.markov for row in table] == [[p] for p in (1, 2, 3, 4)]
    dr = truth()["Dutch roll"]
    for row in table:
        for lam in row.modes["Dutch roll"]:
            assert abs(complex(*lam) - dr) / abs(dr) < 0.15
    best = findings.recommend(table, excitations=3)
    assert best is not None
    tics = [row.tic_avg for row in table]
    assert best.tic_avg <= min(tics) * (1 + findings.TIC_MARGIN)
    assert best.spread["Dutch roll"] < findings.CONSISTENT
    text = findings.analysed(paths, cases, outcomes, excitations=3, sweep=True).text()
    assert "excitation 1 (markov=1): p 1, n " in text
    assert f"recommended: markov={best.setting['markov']}" in text


def test_cross_validation_and_batch(tmp_path):
    paths = excitation_logs(tmp_path)
    cases = cases_for(paths, batch=False, sweep=None)
    outcomes = an.run_cases(cases)
    matrix = findings.cross_validation(cases, outcomes)
    assert len(matrix) == 3
    assert all(len(row) == 3 for row in matrix)
    for i in range(3):  # each model on its own data is what its result says
        assert matrix[i][i] == pytest.approx(outcomes[i].result.tic_avg, rel=0.05)
    assert max(max(row) for row in matrix) < 0.3  # same aircraft: every model fits all data
    (batch,) = cases_for(paths, batch=True, sweep=None)
    assert len(batch.job.experiments) == 3
    assert an.run_cases([batch])[0].ok


def test_a_log_flown_on_the_sticks_is_replayed_as_a_closed_loop_record(tmp_path):
    # The agent's log of a run played on the sticks (FBWA) says so in its header
    # (agent.logs); its replay is identified as a closed-loop record, as onboard, and a batch
    # with one such run too. A foreign CSV whose comment says the same is not the agent's log:
    # nothing is read into it.
    paths = excitation_logs(tmp_path)
    lines = paths[1].read_text().splitlines()
    lines[1] = lines[1].replace(", window", ", flown on the sticks (FBWA: closed loop), window")
    paths[1].write_text("\n".join(lines) + "\n")
    foreign = tmp_path / "other.csv"
    foreign.write_text("# flown on the sticks\n" + "\n".join(paths[0].read_text().splitlines()[2:]))
    assert [an.flown_on_sticks(p) for p in (*paths, foreign)] == [False, True, False, False]
    single = cases_for(paths, batch=False, sweep=None)
    assert [c.job.settings.closed_loop for c in single] == [False, True, False]
    (batch,) = cases_for(paths, batch=True, sweep=None)
    assert batch.job.settings.closed_loop
    (alone,) = cases_for([paths[0], paths[2]], batch=True, sweep=None)
    assert not alone.job.settings.closed_loop


def test_command_line_with_a_dask_cluster(tmp_path):
    from dask.distributed import LocalCluster

    (tmp_path / "logs").mkdir()
    excitation_logs(tmp_path / "logs")  # a directory of logs, picked by number and plan id
    with LocalCluster(
        n_workers=1,
        threads_per_worker=1,
        processes=False,
        protocol="tcp",
        host="127.0.0.1",
        dashboard_address=None,
    ) as cluster:
        done = subprocess.run(
            [
                sys.executable,
                "-m",
                "agent",
                "analyze",
                str(tmp_path / "logs"),
                "--axes",
                "lateral",
                "--excitation",
                "2",
                "--excitation",
                "lateral-3",
                "--sweep",
                "markov=1:2",
                "--no-refine",
                "--scheduler",
                cluster.scheduler_address,
                "--json",
            ],
            capture_output=True,
            text=True,
            timeout=180,
            cwd=tmp_path,
            env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "OPENBLAS_NUM_THREADS": "1"},
        )
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    assert [Path(p).name[:4] for p in report["logs"]] == ["0002", "0004"]
    assert len(report["cases"]) == 4
    # Each case carries its identification's document, as `sysid identify --json` prints it.
    results = [ResultDocument.model_validate(c["result"]) for c in report["cases"]]
    assert all(r.refinement is None for r in results)  # --no-refine: no refinement
    assert [r.okid.markov for r in results] == [1, 1, 2, 2]
    assert report["recommended"]["setting"]["markov"] in (1, 2)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--sweep", "alpha=1:3"], "give markov=… or order=…"),
        (["--sweep", "markov=a:b"], "values must be integers"),
        (["--excitation", "9"], "no excitation log '9'"),
        (["--cross", "--batch"], "--cross needs one model per excitation"),
    ],
)
def test_bad_arguments(tmp_path, args, message):
    excitation_logs(tmp_path, count=1)
    done = subprocess.run(
        [sys.executable, "-m", "agent", "analyze", str(tmp_path), "--axes", "lateral", *args],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
        env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
    )
    assert done.returncode == 2
    assert message in done.stderr


def test_sweep_parsing():
    assert an.parse_sweep("markov=1:4") == ("markov", [1, 2, 3, 4])
    assert an.parse_sweep("order=2:10:4") == ("order", [2, 6, 10])
    assert an.parse_sweep("markov=1,5") == ("markov", [1, 5])
    with pytest.raises(an.AnalyzeError, match="≥ 1"):
        an.parse_sweep("markov=0:2")
    # Bad input tried: a downward range (it used to run 5, 4, 3 and skip 2 and 1), a zero
    # step, a range pointing away from its end, a sweep of 1e5 settings.
    assert an.parse_sweep("markov=5:1:-1") == ("markov", [5, 4, 3, 2, 1])
    with pytest.raises(an.AnalyzeError, match="the step must not be 0"):
        an.parse_sweep("markov=1:5:0")
    with pytest.raises(an.AnalyzeError, match="names no value"):
        an.parse_sweep("markov=5:1")
    with pytest.raises(an.AnalyzeError, match="100000 values; at most 200"):
        an.parse_sweep("markov=1:100000")


def _cut_after_header(lines):
    return [line for line in lines if line.startswith("#") or line.startswith("time")]


def _empty_time_cell(lines):
    data = [k for k, line in enumerate(lines) if line[:1].isdigit() or line[:1] == "-"]
    lines[data[9]] = "," + lines[data[9]].split(",", 1)[1]
    return lines


def _repeated_time(lines):
    data = [k for k, line in enumerate(lines) if line[:1].isdigit() or line[:1] == "-"]
    lines.insert(data[20], lines[data[20]])
    return lines


def _comments_only(lines):
    return [line for line in lines if line.startswith("#")]


def _set_p(row: int, cell: str):
    """Data row `row` (from 0; file line row + 4 under two comments and the header) with its
    p cell (column 5) replaced by `cell`."""

    def damage(lines):
        cells = lines[3 + row].split(",")
        cells[4] = cell
        lines[3 + row] = ",".join(cells)
        return lines

    return damage


def _extra_field(lines):
    lines[3 + 14] += ",0.5"
    return lines


DAMAGED = [
    ("cut", _cut_after_header, "0 data row(s) after the header: the log was cut short"),
    ("empty-time", _empty_time_cell, "data row 10 has no time"),
    ("repeated-time", _repeated_time, "time does not increase at data row 22"),
    ("comments-only", _comments_only, "no header row, only comment lines"),
    ("extra-field", _extra_field, "line 18: 8 fields, the header has 7"),
    ("bad-cell", _set_p(30, "0.1x"), "line 34, column 5 ('p'): '0.1x' is not a number"),
    ("underscore", _set_p(30, "1_000"), "line 34, column 5 ('p'): '1_000' is not a number"),
]


@pytest.mark.parametrize(("name", "damage", "message"), DAMAGED, ids=[d[0] for d in DAMAGED])
@pytest.mark.parametrize("command", ["analyze", "report"])
def test_a_damaged_agent_log_is_a_clear_error(tmp_path, capsys, name, damage, message, command):
    """Bad input tried: an agent log cut right after its header (a power cut), one with an
    empty time cell, one with a row written twice: exit 2 with the reason, no traceback, and
    under --json one JSON object (the row-twice log used to be identified across the repeat,
    and the other two ended in an IndexError). Then a log of comment lines only ("list index
    out of range"), a row with a field too many ("inhomogeneous shape"), a cell 0.1x (no line
    named) and a cell 1_000 (read as 1000): each named by its line and column."""
    from agent.cli import main

    (path,) = excitation_logs(tmp_path, count=1)
    path.write_text("\n".join(damage(path.read_text().splitlines())) + "\n")
    extra = ["--out", str(tmp_path / "report")] if command == "report" else []
    assert main([command, str(path), "--axes", "lateral", *extra]) == 2
    err = capsys.readouterr().err
    assert message in err, err
    assert main([command, str(path), "--axes", "lateral", *extra, "--json"]) == 2
    error = json.loads(capsys.readouterr().out)["error"]
    assert message in error["message"]
    assert error["exit"] == 2


def test_an_unreachable_scheduler_is_a_clear_error(tmp_path):
    """Bad input tried: --scheduler with an address Dask cannot use: exit 1 with the reason,
    and under --json one JSON object. (A process of its own: Dask's client leaves its IO-loop
    thread behind.)"""
    excitation_logs(tmp_path, count=1)
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "agent",
            "analyze",
            str(tmp_path),
            "--axes",
            "lateral",
            "--scheduler",
            "nonsense",
            "--json",
        ],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
        env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "OPENBLAS_NUM_THREADS": "1"},
    )
    assert done.returncode == 1, done.stderr
    assert "cannot run the jobs: missing port number in address 'nonsense'" in done.stderr
    assert "missing port number" in json.loads(done.stdout)["error"]["message"]


def test_a_sweep_is_counted_before_its_values_are_listed(tmp_path):
    """Bad input tried: --sweep markov=1:100000000 (its 10⁸ values, 3.9 GB, used to be listed
    before "at most 200" was checked), in a process of its own with a memory limit."""
    excitation_logs(tmp_path, count=1)
    done = sysid(
        "analyze", str(tmp_path), "--axes", "lateral", "--sweep", "markov=1:100000000", cwd=tmp_path
    )
    assert done.returncode == 2, done.stderr
    assert "'markov=1:100000000': 100000000 values; at most 200" in done.stderr


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["analyze", "/dev/zero"], "/dev/zero: a line longer than 1048576 characters"),
        (["report", "/dev/zero", "--out", "report"], "/dev/zero: a line longer than 1048576"),
        (["analyze", "/dev/zero", "--excitation", "3"], "no excitation log '3' among 1 file"),
    ],
)
def test_a_log_without_line_ends_is_refused_at_its_bound(tmp_path, args, message):
    """Bad input tried: `analyze /dev/zero`, `report /dev/zero`, and `analyze /dev/zero
    --excitation 3` (which looks for the plan id in its header): each line used to be read
    whole, growing until the memory ran out. In a process of its own with a memory limit."""
    done = sysid(*args, "--axes", "lateral", cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert message in done.stderr


def test_an_agent_log_over_the_row_cap_is_refused(tmp_path, capsys, monkeypatch):
    """Bad input tried: an agent log over the rows one log may have (agent logs had no cap: a
    200 MB log took 1.3 GB). The cap lowered to 100 rows here, as for a 5-million-row log."""
    from agent.cli import main

    monkeypatch.setattr("agent.logs.MAX_ROWS", 100)
    (path,) = excitation_logs(tmp_path, count=1)
    assert main(["analyze", str(path), "--axes", "lateral"]) == 2
    assert "more than 100 data rows, the most one log may have" in capsys.readouterr().err


def test_an_agent_log_takes_the_memory_of_the_columns_used(tmp_path, capsys):
    """Bad input tried: a wide agent log, 14 MB of 40 columns of which the lateral axes use 7
    (the whole text, its lines and every cell as a Python float used to be held at once,
    about 7 times the file). Read a block at a time and only the columns used kept, the peak
    is well under the file's size."""
    import tracemalloc

    from agent.cli import main

    names = ["time", "aileron", "rudder", "beta", "p", "r", "phi"]
    names += [f"extra_{k}" for k in range(33)]
    data = np.random.default_rng(0).normal(size=(30_000, len(names)))
    data[:, 0] = np.arange(data.shape[0]) * 0.02
    path = tmp_path / "0001_lateral_single_20261122.csv"
    with path.open("w") as handle:
        handle.write("# suas-sysid lateral log, created 2026-11-22\n")
        handle.write(",".join(names) + "\n")
        np.savetxt(handle, data, delimiter=",", fmt="%.9g")
    # Read through to the time window, which is empty: the reading is all that is measured.
    args = ["analyze", str(path), "--axes", "lateral", "--start", "1e9"]
    assert main(args) == 2  # once to import what the command imports
    tracemalloc.start()
    try:
        assert main(args) == 2
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert "fewer than 3 samples between --start and --end" in capsys.readouterr().err
    assert peak < path.stat().st_size / 2, (peak, path.stat().st_size)


def test_a_foreign_record_with_a_gap_is_refused_by_name_not_cut_to_its_first_segment(
    tmp_path, capsys
):
    """Bad input tried: a foreign CSV record (not the agent's log) of two manoeuvres joined by
    a 30.08 s jump in time. A replay runs one uniform record: it says so and how to choose a
    segment (exit 2), rather than replay the first one alone in silence; the window that
    chooses one replays it."""
    from agent.cli import main

    parts = [reference.make_record(MODEL, seed=s, duration=10.0).columns() for s in (1, 2)]
    second = {**parts[1], "time": parts[1]["time"] + parts[0]["time"][-1] + 30.08}
    names = list(parts[0])
    data = np.column_stack([np.concatenate([parts[0][n], second[n]]) for n in names])
    path = tmp_path / "joined.csv"
    np.savetxt(path, data, delimiter=",", fmt="%.9g", header=",".join(names), comments="")
    lateral = ["--inputs", "aileron,rudder", "--outputs", "beta,p,r,phi"]
    assert main(["analyze", str(path), *lateral]) == 2
    err = capsys.readouterr().err
    assert "1 gap(s) in time (30.08 s at" in err, err
    assert "choose a segment with --start/--end" in err
    assert main(["analyze", str(path), *lateral, "--end", "10", "--json"]) == 0
