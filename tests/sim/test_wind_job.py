"""The onboard identification job measures the wind from the INS's channels in its window: a
JSBSim flight of the full preset in light turbulence (agent.sim.offline), handed to
`agent.ident.job.run` as the agent hands it a recorded window.

Bad input tried: an INS dropout (NaN in v_N for a second) and a window with no navigation
channel at all. Each is identified without the wind, and the result says so; neither fails the
job.
"""

from __future__ import annotations

import numpy as np
import pytest

from agent.config import Channels
from agent.excitation.plan import preset
from agent.ident import Settings
from agent.ident.job import Job, run
from agent.sim.offline import INS_CHANNELS, fly

CHANNELS = Channels()
INPUTS, OUTPUTS = CHANNELS.axis_set("full")
ROLES = ("airspeed", "alpha", "q", "theta", "beta", "p", "r", "phi")


@pytest.fixture(scope="module")
def window() -> dict[str, np.ndarray]:
    record = fly(preset("full"), aircraft="pa28", speed_kts=90.0, turbulence=1.0, seed=4)
    values = dict(zip(INPUTS, record.u.T, strict=True))
    values.update(zip(OUTPUTS, record.y.T, strict=True))
    values.update(zip(CHANNELS.navigation(), record.ins.T, strict=True))
    assert tuple(INS_CHANNELS) == CHANNELS.navigation()  # the recorder's names, as onboard
    return values


def _job(values: dict[str, np.ndarray]) -> dict:
    job = Job("ful-1", "full", 0.01, INPUTS, OUTPUTS, ROLES, (), Settings(held_inputs=False),
              window=values, navigation=CHANNELS.navigation())  # fmt: skip
    outcome = run(job)
    assert outcome["ok"], outcome.get("reason")
    return outcome["result"]["aircraft"]


def test_the_job_measures_the_wind_from_the_ins_channels_in_its_window(window):
    report = _job(window)
    assert report["kinematics"]
    assert report["wind"]["measured"]
    # Light Dryden turbulence at 1000 ft: gusts of a fraction of a metre per second.
    assert 0.2 < report["wind"]["gust_rms"]["airspeed"] < 2.0
    lateral = next(axis for axis in report["axes"] if axis["name"] == "lateral")
    assert "gust beta" in lateral["inputs"]


def test_an_ins_dropout_or_no_ins_channels_identify_without_the_wind(window):
    dropout = dict(window)
    dropout["vn"] = window["vn"].copy()
    dropout["vn"][3000:3100] = np.nan
    report = _job(dropout)
    assert not report["wind"]["measured"]
    assert report["kinematics"]  # the trim is still known
    without = {k: v for k, v in window.items() if k not in CHANNELS.navigation()}
    assert not _job(without)["wind"]["measured"]
