"""`sysid sim` end to end: the simulated aircraft, emulated ArduPlane, sensor ptys and radios,
the real agent (worker-process identification, model store), and the scripted operator.

Three lateral excitations, each sized by the aircraft before it is armed (agent/sizing.py):
the first is the build-up (a quarter of the preset, its model not made nominal), the second
is sized by the first's model and its result becomes the nominal by the operator's accept, the
third is sized by the nominal and compared with it by the thesis's TIC procedure (TIC_jN,
TIC_NN, TIC_Nj).
"""

from __future__ import annotations

import pytest

from agent.sim.flight import SimOptions, fly

pytestmark = pytest.mark.usefixtures("no_leaked_tasks")


@pytest.mark.timeout(300)
async def test_three_sized_lateral_runs_end_to_end(tmp_path):
    report = await fly(SimOptions(preset="lateral", runs=3, sizing=True, directory=tmp_path))
    assert report["events"] == ["started", "finished"]  # the excitation played
    assert report["sensor_gaps"] == {"vn200": 0, "airdata": 0, "surfaces": 0}  # 100 Hz, no loss
    assert report["recorder"]["frames"] > 30 * 100
    assert report["worker_identifications"] == 3  # each ran in the worker process
    assert report["air_angles"] == "vanes"  # the µADC's; `--no-vanes`: "synthesised"
    # Commanded and measured surfaces agree in sign end to end (plan, direction, ArduPlane,
    # servo linkage, pots): the aircraft told the operator of no surface moving against or
    # not following its command.
    assert not [n for n in report["notices"] if "command" in n], report["notices"]
    # The result crossed the radio link; the named modes the record resolves are within 15 %.
    modes = {m["name"]: m for m in report["modes"] if m["name"]}
    for name in ("Dutch roll", "roll"):
        assert modes[name]["error"] < 0.15, (name, modes[name])
    assert report["truth_check"]["validated"], report["truth_check"]  # errors against a truth
    # The build-up flew a quarter of the preset and calibrated the second run, whose sizing
    # came from its model, within the targets; the operator's accept made the second model
    # nominal, and the third, sized by it, got the TIC comparison.
    build_up, first, second = report["history"]
    assert build_up["sizing"]["build_up"]
    assert build_up["decision"] == "reject"
    assert all(c["factor"] == 0.25 for c in build_up["sizing"]["controls"])
    sized = first["sizing"]
    assert build_up["model_id"] in sized["source"]
    assert not sized["build_up"]
    assert sized["predicted"]["bank_deg"] <= 15.0 * 1.01
    grown = {c["control"]: c["amplitude"] for c in sized["controls"]}
    assert all(grown[c["control"]] > c["amplitude"] for c in build_up["sizing"]["controls"])
    assert first["decision"] == "accept"
    assert second["sizing"]["source"] == f"nominal model {first['model_id']}"
    assert second["model_id"] != first["model_id"]
    suggestion = report["suggestion"]
    assert suggestion["tic_nn"] is not None
    assert suggestion["tic_jn"] is not None
    assert suggestion["tic_nj"] is not None
    assert any(step.startswith("4–5 TIC_jN") for step in suggestion["steps"])
    assert report["decision"] in ("accept", "reject")
    assert (tmp_path / "models" / "lateral_nominal.json").exists()  # persisted
    logs = [p.name.split("_", 1)[1] for p in (tmp_path / "logs").iterdir()]
    for kind in ("flight_", "exec_", "results_", "lateral_single_"):  # thesis 2.2.1 logs
        assert any(n.startswith(kind) for n in logs), kind
    post_flight(tmp_path, report)


# How far a converged replay's TIC_avg may be from the aircraft's own (see post_flight).
REPLAY_TIC_REL = 1e-6


def post_flight(directory, report) -> None:
    """The post-flight commands on the logs this very flight produced: analyze, export,
    import, report."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    from scipy.io import loadmat

    root = Path(__file__).resolve().parents[2]
    env = {"PYTHONPATH": str(root), "PATH": "/usr/bin:/bin"}
    if "OPENBLAS_NUM_THREADS" in os.environ:  # BLAS threads as the onboard worker had them
        env["OPENBLAS_NUM_THREADS"] = os.environ["OPENBLAS_NUM_THREADS"]

    def sysid(*args):
        done = subprocess.run(
            [sys.executable, "-m", "agent", *map(str, args)],
            cwd=directory,
            capture_output=True,
            text=True,
            timeout=120,
            env=env,
        )
        assert done.returncode == 0, (args, done.stderr)
        return done.stdout

    logs = directory / "logs"
    analysed = json.loads(sysid("analyze", logs, "--axes", "lateral", "--cross", "--json"))
    runs = len(report["history"])
    assert len(analysed["cases"]) == runs  # one per lateral excitation log
    truth = complex(*report["truth_modes"]["Dutch roll"])
    for case in analysed["cases"]:
        modes = case["result"]["modes"]
        dutch = [complex(*m["eigenvalue"]) for m in modes if m["name"] == "Dutch roll"]
        assert abs(dutch[0] - truth) / abs(truth) < 0.15, case
    assert all(v < 0.3 for row in analysed["cross_tic"] for v in row)
    results = next(logs.glob("*_results_*.jsonl"))
    # The replay runs the aircraft's own job on the very numbers it had (the excitation log
    # holds them to 17 digits, and the recorder's rate): the same p and order, the flown modes
    # under the same names. Where the flight's refinement converged, the same numbers too.
    # Where it stopped at its iteration limit (an over-parameterised model sliding along a
    # long valley of the cost), where it stopped depends on the last bits of arithmetic that
    # differ between processes (memory alignment in BLAS kernels), so the numbers may differ:
    # both then carry the warning that says so.
    onboard = [json.loads(line)["result"] for line in results.read_text().splitlines()]
    for case, flown in zip(analysed["cases"], onboard, strict=True):
        replay = case["result"]
        assert replay["method"] == flown["method"]
        p = [(doc["okid"] or {}).get("markov") for doc in (replay, flown)]  # None: aircraft
        assert p[0] == p[1]
        assert replay["order"] == flown["order"]
        replayed = {m["name"] for m in replay["modes"] if m["name"]}
        original = {m["name"] for m in flown["modes"] if m["name"]}
        assert {"Dutch roll", "roll"} <= replayed & original, (replayed, original)
        warnings = replay["warnings"]
        if flown["refinement"]["converged"]:
            assert replay["refinement"]["converged"], warnings
            assert replay["tic_avg"] == pytest.approx(flown["tic_avg"], rel=REPLAY_TIC_REL)
        else:
            assert any("iteration limit" in w for w in flown["warnings"]), flown["warnings"]
            assert replay["refinement"]["converged"] is False, warnings
            assert any("iteration limit" in w for w in warnings), warnings
    sysid("export", results, "--out", directory / "flight.mat")
    mat = loadmat(directory / "flight.mat", simplify_cells=True)
    assert len(mat["model_ids"]) == runs
    sysid("import", directory / "ardupilot.bin", "--out", directory / "ardupilot.csv")
    header = (directory / "ardupilot.csv").read_text().split("\n")
    columns = next(line for line in header if line.startswith("time,")).split(",")
    # The EKF's velocities with the heading: the navigation the wind is measured with; the
    # AHRS's sideslip estimate named apart from a vane's.
    assert {"phi", "p", "r", "Vt", "aileron", "rudder", "psi", "vn", "ve", "vd"} <= set(columns)
    assert "ssa_ahrs" in columns
    assert "beta" not in columns
    sysid(
        "report",
        logs,
        "--axes",
        "lateral",
        "--out",
        directory / "report",
        "--nominal",
        directory / "models" / "lateral_nominal.json",
    )
    page = (directory / "report" / "index.html").read_text()
    assert page.count('<svg class="splane"') == runs + 1  # every excitation's, then one each
    assert page.count('<g class="mode nominal"') >= 3  # the nominal's modes on each plane
    assert (directory / "report" / "excitation_2_bode.png").stat().st_size > 10_000
    # ArduPlane gains from each lateral model: the roll loop's Bode and step drawn, the pitch
    # refused by name (the trim airspeed from the record's flight states).
    assert page.count("<h3>ArduPlane gains from this model</h3><p>As ") == runs
    assert "RLL_RATE_FF" in page
    assert "pitch: the model has no elevator input" in page
    assert (directory / "report" / "excitation_2_gains.png").stat().st_size > 10_000
    # The nominal lateral model tuned for ArduPlane with the linkage and lag the aircraft
    # measured on its runs (the execution log): the roll axis designed, the pitch axis refused
    # by name (a lateral model has no elevator).
    tuned = json.loads(
        sysid(
            "tune",
            directory / "models" / "lateral_nominal.json",
            "--exec-log",
            next(logs.glob("*_exec_*.jsonl")),
            "--scaling-speed",
            "31",
            "--json",
        )
    )
    assert {"aileron", "rudder"} <= set(tuned["measured_linkage"])
    assert [axis["axis"] for axis in tuned["axes"]] == ["roll"]
    assert tuned["axes"][0]["whole_loop"]["phase_margin_deg"] >= 45
    assert any("elevator" in why for why in tuned["refused"])
