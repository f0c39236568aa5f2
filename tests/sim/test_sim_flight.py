"""`sysid sim` end to end: the simulated aircraft, emulated ArduPlane, sensor ptys and radios,
the real agent (worker-process identification, model store), and the scripted operator.

Two lateral excitations: the first result becomes the nominal model by the operator's accept,
the second is compared with it by the thesis's TIC procedure (TIC_jN, TIC_NN, TIC_Nj).
"""

from __future__ import annotations

import pytest

from agent.sim.flight import SimOptions, fly

pytestmark = pytest.mark.usefixtures("no_leaked_tasks")


@pytest.mark.timeout(240)
async def test_two_lateral_runs_end_to_end(tmp_path):
    report = await fly(SimOptions(preset="lateral", runs=2, directory=tmp_path))
    assert report["events"] == ["started", "finished"]  # the excitation played
    assert report["sensor_gaps"] == {"vn200": 0, "airdata": 0, "surfaces": 0}  # 100 Hz, no loss
    assert report["recorder"]["frames"] > 30 * 100
    assert report["worker_identifications"] == 2  # both ran in the worker process
    # The result crossed the radio link; the named modes the record resolves are within 15 %.
    modes = {m["name"]: m for m in report["modes"] if m["name"]}
    for name in ("Dutch roll", "roll"):
        assert modes[name]["error"] < 0.15, (name, modes[name])
    # The operator's accept made the first model nominal; the second got the TIC comparison.
    first, second = report["history"]
    assert first["decision"] == "accept"
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
