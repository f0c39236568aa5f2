"""The onboard identification job measures the wind from the INS's channels in its window: a
JSBSim flight of the full preset in light turbulence (agent.sim.offline), handed to
`agent.ident.job.run` as the agent hands it a recorded window.

The same flight replayed offline, as a CSV record through `sysid identify` and as the agent's
excitation log through `sysid analyze`, is identified with the trim and the wind, as onboard.

Bad input tried: an INS dropout (NaN in v_N for a second), a window with no navigation
channel at all, and in a CSV record an empty v_E cell and a v_D cell that is not a number.
Each is identified without the wind, and the result says so; none fails.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from agent.analysis import analyze as an
from agent.analysis.identify import Request
from agent.cli import main
from agent.config import Channels, Config
from agent.excitation.plan import preset
from agent.ident import Settings
from agent.ident.document import ResultDocument
from agent.ident.job import Job, run
from agent.sim.offline import INS_CHANNELS, fly

CHANNELS = Channels()
INPUTS, OUTPUTS = CHANNELS.axis_set("full")
ROLES = ("airspeed", "alpha", "q", "theta", "beta", "p", "r", "phi")
CHANNELS_ROLES = tuple(CHANNELS.role_of(n) for n in INPUTS)


DT = 0.01


@pytest.fixture(scope="module")
def window() -> dict[str, np.ndarray]:
    record = fly(preset("full"), aircraft="pa28", speed_kts=90.0, turbulence=1.0, seed=4)
    values = dict(zip(INPUTS, record.u.T, strict=True))
    values.update(zip(OUTPUTS, record.y.T, strict=True))
    values.update(zip(CHANNELS.navigation(), record.ins.T, strict=True))
    assert tuple(INS_CHANNELS) == CHANNELS.navigation()  # the recorder's names, as onboard
    return values


def _job(values: dict[str, np.ndarray]) -> dict:
    job = Job(
        model_id="ful-1",
        axes="full",
        record_dt=0.01,
        inputs=INPUTS,
        outputs=OUTPUTS,
        roles=ROLES,
        experiments=(),
        settings=Settings(held_inputs=False),
        window=values,
        navigation=CHANNELS.navigation(),
    )
    outcome = run(job)
    assert outcome.ok, outcome.reason
    return outcome.result.aircraft


def test_the_job_measures_the_wind_from_the_ins_channels_in_its_window(window):
    report = _job(window)
    assert report.kinematics
    assert report.wind.measured
    # Light Dryden turbulence at 1000 ft (MIL-F-8785C's low-altitude model, W20 = 5 ft/s):
    # σ_u = 0.1 W20 / (0.177 + 0.000823 h)^0.4 = 0.15 m/s; the measured gust is the gust
    # without the sensors' noise (agent.ident.aircraft.noise).
    assert 0.1 < report.wind.gust_rms["airspeed"] < 0.3
    lateral = next(axis for axis in report.axes if axis.name == "lateral")
    assert "gust beta" in lateral.inputs


def test_an_ins_dropout_or_no_ins_channels_identify_without_the_wind(window):
    dropout = dict(window)
    dropout["vn"] = window["vn"].copy()
    dropout["vn"][3000:3100] = np.nan
    report = _job(dropout)
    assert not report.wind.measured
    assert report.kinematics  # the trim is still known
    without = {k: v for k, v in window.items() if k not in CHANNELS.navigation()}
    assert not _job(without).wind.measured


def test_a_lateral_job_uses_the_kinematics_of_the_airspeed_and_pitch_in_its_window(window):
    """A lateral run's job (outputs β, p, r, φ) whose window also holds the airspeed and θ, as
    the agent's recorder does: their kinematics are known (they were not: a lateral run
    fitted φ̇ freely); with θ gapped for a second (an INS dropout), not."""
    inputs, outputs = CHANNELS.axis_set("lateral")
    flight = tuple(
        (role, name) for role, name in zip(ROLES, OUTPUTS, strict=True) if name not in outputs
    )

    def lateral(values):
        job = Job(
            model_id="lat-1",
            axes="lateral",
            record_dt=DT,
            inputs=inputs,
            outputs=outputs,
            roles=ROLES[4:],
            experiments=(),
            settings=Settings(held_inputs=False),
            window=values,
            flight=flight,
        )
        outcome = run(job)
        assert outcome.ok, outcome.reason
        return outcome.result.aircraft

    assert lateral(window).kinematics
    gapped = {**window, "theta": window["theta"].copy()}
    gapped["theta"][3000:3100] = np.nan
    assert not lateral(gapped).kinematics


def _csv(path, values: dict[str, np.ndarray], header: str = "") -> None:
    names = list(values)
    table = np.column_stack([np.arange(len(values[names[0]])) * DT, *values.values()])
    rows = "\n".join(",".join(f"{v:.10g}" for v in row) for row in table)
    path.write_text(header + ",".join(["time", *names]) + "\n" + rows + "\n")


def _identify(capsys, path) -> dict:
    code = main(["identify", str(path), "--axes", "full", "--json"])
    out = capsys.readouterr().out
    assert code == 0, out
    return ResultDocument.model_validate(json.loads(out)).aircraft


def test_sysid_identify_on_a_csv_record_uses_the_trim_and_the_wind(tmp_path, capsys, window):
    _csv(tmp_path / "full.csv", window)
    report = _identify(capsys, tmp_path / "full.csv")
    onboard = _job(window)
    assert report.kinematics
    assert report.wind.measured
    assert report.wind.gust_rms == pytest.approx(onboard.wind.gust_rms, rel=1e-6)
    # Without the INS columns the same record is identified without the wind, not refused.
    _csv(
        tmp_path / "no_ins.csv", {k: v for k, v in window.items() if k not in CHANNELS.navigation()}
    )
    report = _identify(capsys, tmp_path / "no_ins.csv")
    assert report.kinematics
    assert not report.wind.measured


def test_a_damaged_ins_column_in_a_csv_record_leaves_out_the_wind(tmp_path, capsys, window):
    path = tmp_path / "damaged.csv"
    _csv(path, window)
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    for row, (name, cell) in ((500, ("ve", "")), (900, ("vd", "n/a"))):
        cells = lines[row].split(",")
        cells[header.index(name)] = cell
        lines[row] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    report = _identify(capsys, path)
    assert report.kinematics
    assert not report.wind.measured


def test_sysid_analyze_replays_an_agent_log_with_the_trim_and_the_wind(tmp_path, window):
    path = tmp_path / "0003_full_single_20261124.csv"
    _csv(
        path,
        window,
        header="# suas-sysid full log, created 2026-11-24\n"
        "# excitation plan full-1, finished, recorded at 100 Hz\n",
    )
    config = Config().identification
    request = Request((path,), INPUTS, OUTPUTS, navigation=config.channels.navigation())
    settings = Settings.from_config(config, sampled_inputs=True)  # the agent's own log
    cases, dt = an.build_cases(
        request, ROLES, settings, batch=False, sweep=None, input_roles=CHANNELS_ROLES
    )
    assert dt == pytest.approx(DT)
    (outcome,) = an.run_cases(cases)
    assert outcome.ok, outcome.reason
    report = outcome.result.aircraft
    assert report.kinematics
    assert report.wind.measured
    assert report.wind.gust_rms == pytest.approx(_job(window).wind.gust_rms, rel=1e-6)
