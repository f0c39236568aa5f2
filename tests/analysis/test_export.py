"""`sysid export`: the agent's identified models to MATLAB .mat and JSON, and back.

The models come from the agent's own identification path (`Identification.identify` on the bundled
A.2 lateral record, the worker job run on a thread pool), its result log and its model store.

Bad input tried: a file with no identified model, a damaged store file, an unknown model id,
an output that is neither .mat nor .json, a failed `sysid identify --json`'s error object.
"""

from __future__ import annotations

import asyncio
import csv
import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from scipy.io import loadmat

from agent.analysis.export import ExportError, load_models, to_json, to_mat, variable_name
from agent.config import Config, IdentificationConfig, Recorder
from agent.excitation.scheduler import Window
from agent.link import messages
from agent.runtime import Agent
from tests.capped import sysid

ROOT = Path(__file__).resolve().parents[2]


SERIES = "5eed0001"
LAT1, LAT2 = f"lat-1-{SERIES}", f"lat-2-{SERIES}"


@pytest.fixture
def flight(tmp_path):
    """An agent that identified the A.2 record twice and accepted the first as nominal."""
    with (ROOT / "examples" / "a2_lateral.csv").open() as handle:
        table = list(csv.DictReader(handle))
    config = Config(
        recorder=Recorder(log_dir=str(tmp_path / "logs"), rate_hz=50.0),
        identification=IdentificationConfig(trim_seconds=0.5),
    )
    # The store's numbering in a known series, so the ids are known: LAT1, LAT2.
    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "numbering").write_text(json.dumps({"series": SERIES, "last": 0}))
    agent = Agent(config, base=tmp_path, worker=lambda: ThreadPoolExecutor(1))
    channels = agent.recorder.channels
    rows = np.full((len(table), 1 + 2 * len(channels)), np.nan)
    rows[:, 0] = [float(r["time"]) for r in table]
    for name in ("aileron", "rudder", "beta", "p", "r", "phi"):
        offset = {"phi": 0.02, "aileron": 1.5}.get(name, 0.0)  # a trim to recover
        rows[:, 1 + channels.index(name)] = [float(r[name]) + offset for r in table]

    async def fly():
        for k in range(2):
            window = Window(f"run{k}", "lateral", rows[0, 0], rows[-1, 0], "finished")
            await agent.identification.identify(window, rows)
            if k == 0:
                await agent.commands.handle(messages.Decision(model_id=LAT1, accept=True), 1)

    try:
        asyncio.run(fly())
    finally:
        agent.close()
    return tmp_path, agent


def test_mat_export_loads_back_with_the_same_matrices(flight, tmp_path):
    base, _ = flight
    log = next((base / "logs").glob("*_results_*.jsonl"))
    models = load_models(log)
    assert [m["id"] for m in models] == [LAT1, LAT2]
    to_mat(models, tmp_path / "flight.mat")
    mat = loadmat(tmp_path / "flight.mat", simplify_cells=True)
    assert list(mat["model_ids"]) == [LAT1, LAT2]
    record = json.loads(log.read_text().splitlines()[0])["result"]
    m = mat[variable_name(LAT1)]
    for key in ("A", "B", "C", "D"):
        np.testing.assert_array_equal(np.atleast_2d(m[key]), np.array(record[key]))
    np.testing.assert_array_equal(m["Ac"], np.array(record["continuous"]["A"]))
    assert list(m["inputs"]) == ["aileron", "rudder"]
    assert list(m["outputs"]) == ["beta", "p", "r", "phi"]
    assert m["u0"][0] == pytest.approx(1.5, abs=1e-9)  # the aileron trim removed
    assert m["y0"][3] == pytest.approx(0.02 + float(_first_phi()), abs=1e-3)
    lam = np.sort_complex(np.atleast_1d(m["eigenvalues"]))
    expected = np.sort_complex([complex(*x["eigenvalue"]) for x in record["modes"]])
    np.testing.assert_allclose(lam, expected)
    assert "Dutch roll" in list(m["mode_names"])
    assert m["dt"] == pytest.approx(record["dt"])


def _first_phi() -> float:
    with (ROOT / "examples" / "a2_lateral.csv").open() as handle:
        rows = list(csv.DictReader(handle))[:25]
    return float(np.mean([float(r["phi"]) for r in rows]))


def test_the_nominal_store_exports_its_data_set(flight, tmp_path):
    base, _ = flight
    models = load_models(base / "models" / "lateral_nominal.json")
    to_mat(models, tmp_path / "nominal.mat")
    m = loadmat(tmp_path / "nominal.mat", simplify_cells=True)[variable_name(LAT1)]
    u, y = np.atleast_2d(m["u"]), np.atleast_2d(m["y"])
    assert u.shape[1] == 2
    assert y.shape[1] == 4
    assert abs(u[:25].mean()) < 1e-9  # deviations from the trim


def test_json_and_the_command_line(flight, tmp_path):
    base, _ = flight
    log = next((base / "logs").glob("*_results_*.jsonl"))
    data = json.loads(to_json(load_models(log)))
    assert data[1]["id"] == LAT2
    assert len(data[1]["eigenvalues"][0]) == 2  # [re, im]
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    run = lambda *a: subprocess.run(  # noqa: E731
        [sys.executable, "-m", "agent", "export", *a],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=60,
        env=env,
    )
    done = run(str(log), "--out", "one.mat", "--model", LAT2)
    assert done.returncode == 0, done.stderr
    assert (
        list(loadmat(tmp_path / "one.mat", simplify_cells=True)["model_ids"]) == [LAT2]
        or loadmat(tmp_path / "one.mat", simplify_cells=True)["model_ids"] == LAT2
    )
    assert "no model lat-9" in run(str(log), "--out", "x.mat", "--model", "lat-9").stderr
    assert "give a .mat, .json or .csv" in run(str(log), "--out", "x.txt").stderr
    # The derivatives with their standard errors: one line per model, equation and variable.
    done = run(str(log), "--out", "derivatives.csv")
    assert done.returncode == 0, done.stderr
    with (tmp_path / "derivatives.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert {r["model"] for r in rows} == {LAT1, LAT2}
    assert len(rows) == 2 * 4 * 6  # β̇, ṗ, ṙ, φ̇ over β, p, r, φ, aileron, rudder
    model = load_models(log)[0]
    lp = next(
        r for r in rows if r["model"] == LAT1 and r["equation"] == "dp/dt" and r["variable"] == "p"
    )
    p = model["outputs"].index("p")
    assert float(lp["value"]) == pytest.approx(model["Ac"][p, p], rel=1e-5)
    assert float(lp["std"]) == pytest.approx(model["Ac_std"][p, p], rel=1e-2)


def test_derivatives_need_a_model_in_output_coordinates(tmp_path):
    # Bad input tried: a ground log, whose results carry the discrete model only.
    from agent.analysis.export import to_csv
    from agent.link import messages
    from tests.ground.aircraft import result

    log = tmp_path / "0001_ground_20261122.jsonl"
    log.write_text(
        json.dumps({"dir": "rx", "seq": 4, "message": messages.to_dict(result("lat-7"))})
    )
    with pytest.raises(ExportError, match="no model in output coordinates"):
        to_csv(load_models(log))


@pytest.mark.parametrize("bad", ["no models", "damaged store"])
def test_sources_without_models_are_refused(tmp_path, bad):
    path = tmp_path / ("x.jsonl" if bad == "no models" else "lateral_nominal.json")
    path.write_text('{"level": "INFO"}\n' if bad == "no models" else '{"model_id": "a"')
    with pytest.raises(ExportError, match=path.name.replace(".", r"\.")):
        load_models(path)


def test_a_store_file_of_the_earlier_layout_exports_with_its_trim(tmp_path):
    """Input: a model store file as written before the result had typed parts (Markov
    parameters and singular values at the top level, the OKID/ERA fit in the refinement, the
    trim under "extra"): it is read, its trim and data set exported as from a store of now."""
    from agent.ident import Experiment, Settings, identify, reference

    model, dt = reference.LATERAL, 0.02
    record = reference.make_record(model, dt=dt, duration=10.0)
    u, y = record.inputs, record.outputs
    found = identify(
        Experiment(u, y),
        dt,
        input_names=model.inputs,
        output_names=model.outputs,
        settings=Settings(markov=2, method="time"),
    )
    now = found.document().model_dump(mode="json")
    earlier = {k: v for k, v in now.items() if k not in ("okid", "aircraft")}
    okid = now["okid"]
    earlier |= {k: okid[k] for k in ("markov", "markov_auto", "singular_values", "frequency")}
    earlier["refinement"] = now["refinement"] | {"okid_tic_avg": okid["tic_avg"]}
    trim = {"inputs": {"aileron": 1.5, "rudder": 0.0}, "outputs": dict.fromkeys(model.outputs, 0.1)}
    store = tmp_path / "lateral_nominal.json"
    store.write_text(
        json.dumps(
            {
                "model_id": "lat-1",
                "axes": "lateral",
                "record_dt": dt,
                "result": earlier,
                "tic_nn": now["tic_avg"],
                "count": 1,
                "extra": {"trim": trim, "record_s": 10.0},
            }
        )
    )
    np.savez(store.with_suffix(".npz"), u0=u, y0=y)
    (exported,) = load_models(store)
    np.testing.assert_array_equal(exported["A"], np.array(now["A"]))
    np.testing.assert_array_equal(exported["Ac_std"], np.array(now["refinement"]["Ac_std"]))
    assert list(exported["u0"]) == [1.5, 0.0]
    np.testing.assert_array_equal(exported["u"][0], u)


def test_matlab_names():
    assert variable_name("lat-3") == "lat_3"
    assert variable_name("periodic@1234") == "periodic_1234"
    assert variable_name("3x") == "m_3x"


def test_results_heard_by_the_ground_console_export_too(tmp_path):
    from agent.link import messages
    from tests.ground.aircraft import result

    message = messages.to_dict(result("lat-7"))
    log = tmp_path / "0001_ground_20261122.jsonl"
    log.write_text(
        json.dumps({"dir": "rx", "seq": 4, "message": message})
        + "\n"
        + json.dumps({"dir": "note", "message": {"text": "x"}})
        + "\n"
    )
    (model,) = load_models(log)
    assert model["id"] == "lat-7"
    np.testing.assert_array_equal(model["A"], result("lat-7").A)
    assert model["Ac"].size == 0  # the radio carries the discrete model only
    assert list(model["tic"]) == [0.02, 0.03, 0.02, 0.04]
    assert model["mode_names"] == ["Dutch roll", "roll", "spiral"]


def test_damaged_sources_are_clear_errors_and_nothing_is_dropped_silently(flight, tmp_path):
    """Bad input tried: a result log with a Latin-1 byte (a traceback before), a model store
    whose .npz data set is damaged (a traceback before), a result log with a line of garbage
    in the middle (silently dropped before), and two models whose ids give one MATLAB name
    (lat-1 and lat_1: the second overwrote the first in the .mat)."""
    base, _ = flight
    log = next((base / "logs").glob("*_results_*.jsonl"))
    latin = tmp_path / "latin.jsonl"
    latin.write_bytes(log.read_bytes() + "\xb0\n".encode("latin-1"))
    with pytest.raises(ExportError, match="not a UTF-8 text file"):
        load_models(latin)
    store = base / "models" / "lateral_nominal.json"
    npz = store.with_suffix(".npz")
    npz.write_bytes(npz.read_bytes()[: npz.stat().st_size // 2])
    with pytest.raises(ExportError, match="data set is damaged"):
        load_models(store)
    lines = log.read_text().splitlines()
    torn = tmp_path / "torn.jsonl"
    torn.write_text("\n".join([lines[0], '{"model_id": "lat-', lines[1]]) + "\n")
    models = load_models(torn)
    assert [m["id"] for m in models] == [LAT1, LAT2]
    assert models.skipped == (2,)
    done = subprocess.run(
        [sys.executable, "-m", "agent", "export", str(torn), "--out", str(tmp_path / "t.mat")],
        capture_output=True,
        text=True,
        timeout=60,
        env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
    )
    assert done.returncode == 0, done.stderr
    assert "1 line(s) not JSON and not exported (line 2)" in done.stderr
    twins = load_models(log)
    name = variable_name(LAT1)  # lat_1_5eed0001: the second id spelled as the first's name
    twins[1]["id"] = name
    to_mat(twins, tmp_path / "twins.mat")
    mat = loadmat(tmp_path / "twins.mat", simplify_cells=True)
    assert list(mat["model_variables"]) == [name, f"{name}_2"]
    assert mat[name]["id"] == LAT1
    assert mat[f"{name}_2"]["id"] == name


def test_an_out_that_is_the_source_is_refused_and_the_store_kept(flight, tmp_path, capsys):
    """Bad input tried: `export nom.json --out nom.json` (the model store file used to be
    overwritten by the export) and --out naming a hard link to it: exit 2 naming both, the
    store's bytes unchanged."""
    from agent.cli import main

    base, _ = flight
    record = json.loads(next((base / "logs").glob("*_results_*.jsonl")).read_text().split("\n")[0])
    store = tmp_path / "nom.json"  # a model store file: the id, the axes and the result
    store.write_text(json.dumps({k: record[k] for k in ("model_id", "axes", "result")}))
    before = store.read_bytes()
    assert len(load_models(store)) == 1  # a source export takes
    (tmp_path / "again.json").hardlink_to(store)
    for out in (store, tmp_path / "again.json"):
        assert main(["export", str(store), "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert f"--out {out}: that is {store}, the file being exported" in err, err
        assert store.read_bytes() == before


def test_a_source_without_line_ends_is_refused_at_its_bound(tmp_path):
    """Bad input tried: `export /dev/zero --out x.mat` (read whole before: it grew until the
    memory ran out), in a process of its own with a memory limit."""
    done = sysid("export", "/dev/zero", "--out", "x.mat", cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert "/dev/zero: line 1 is longer than 16777216 bytes" in done.stderr
    assert not (tmp_path / "x.mat").exists()


def test_what_sysid_identify_printed_exports_as_it_is(tmp_path, capsys):
    """What a user just identified (`sysid identify --json > model.json`) exports to MATLAB
    (it was refused: "not a model store file"): its matrices, modes and its one record's
    trim. Bad input tried: the `--json` error object of a failed identify, refused by name."""
    from agent.cli import main

    record = ROOT / "examples" / "a2_lateral.csv"
    lateral = ["--inputs", "aileron,rudder", "--outputs", "beta,p,r,phi"]
    assert main(["identify", str(record), *lateral, "--json"]) == 0
    identified = tmp_path / "model.json"
    identified.write_text(capsys.readouterr().out)
    done = sysid("export", str(identified), "--out", str(tmp_path / "model.mat"), cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    doc = json.loads(identified.read_text())
    m = loadmat(tmp_path / "model.mat", simplify_cells=True)["model"]
    for key in ("A", "B", "C", "D"):
        np.testing.assert_array_equal(np.atleast_2d(m[key]), np.array(doc[key]))
    lam = np.sort_complex(np.atleast_1d(m["eigenvalues"]))
    expected = np.sort_complex([complex(*x["eigenvalue"]) for x in doc["modes"]])
    np.testing.assert_allclose(lam, expected)
    assert m["u0"][0] == pytest.approx(doc["trim"][0]["aileron"])
    assert m["y0"][3] == pytest.approx(doc["trim"][0]["phi"])
    assert main(["identify", str(tmp_path / "absent.csv"), *lateral, "--json"]) == 2
    failed = tmp_path / "failed.json"
    failed.write_text(capsys.readouterr().out)
    done = sysid("export", str(failed), "--out", str(tmp_path / "failed.mat"), cwd=tmp_path)
    assert done.returncode == 2
    assert "not a model store file nor a `sysid identify --json` result" in done.stderr
