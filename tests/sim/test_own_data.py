"""A flight-test engineer's own record, end to end: a JSBSim flight of the PA-28 through the
full preset (agent.sim.offline, sensor noise on), written as another system writes its CSV —
its own column names, mapped in a config file; knots, degrees and deg/s declared in the header,
the time in ms; two stretches joined by a 30.08 s jump in time, the second starting in the
middle of the manoeuvre (not trimmed) — through `sysid identify --validate`.

Bad input tried: the same file with its units left out of the header (refused as degrees),
and a column given as an input that no role carries (refused by name).
"""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from agent.cli import main
from agent.excitation.plan import preset
from agent.sim.offline import fly

NAMES = {  # the system's names for the roles, and the unit each is written in
    "throttle": ("THR", None),
    "elevator": ("DE", None),
    "aileron": ("DA", None),
    "rudder": ("DR", None),
    "Vt": ("TAS", "kt"),
    "alpha": ("AOA", "deg"),
    "q": ("Q", "deg/s"),
    "theta": ("THETA", "deg"),
    "beta": ("AOS", "deg"),
    "p": ("P", "deg/s"),
    "r": ("R", "deg/s"),
    "phi": ("PHI", "deg"),
}
ROLES = {"Vt": "airspeed"}
KT = 1852 / 3600


@pytest.fixture(scope="module")
def record():
    return fly(preset("full"), aircraft="pa28", speed_kts=90.0, seed=3)


def _write(path, record, *, units: bool = True):
    values = dict(zip(record.inputs, record.u.T, strict=True))
    values |= dict(zip(record.outputs, record.y.T, strict=True))
    time = np.arange(record.u.shape[0]) * record.dt
    split = int(0.55 * time.size)  # the second stretch starts mid-manoeuvre
    time[split:] += 30.08
    header, columns = ["time [ms]" if units else "time"], [time * 1000 if units else time]
    for name, (column, unit) in NAMES.items():
        v = values[name]
        if unit == "kt":
            v = v / KT
        elif unit is not None:
            v = np.degrees(v)
        header.append(f"{column} [{unit}]" if units and unit else column)
        columns.append(v)
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        writer.writerows(zip(*(np.round(c, 6) for c in columns), strict=True))
    return split


def _config(path):
    lines = ["[identification.channels]"]
    lines += [f'{ROLES.get(role, role)} = "{column}"' for role, (column, _) in NAMES.items()]
    path.write_text("\n".join(lines) + "\n")


def test_a_foreign_csv_of_a_jsbsim_flight_is_identified_as_its_user_would_have_it(
    record, tmp_path, capsys
):
    data, config = tmp_path / "flight.csv", tmp_path / "mine.toml"
    _write(data, record)
    _config(config)
    args = ["identify", str(data), "--config", str(config), "--axes", "full", "--json"]
    assert main([*args, "--validate", str(data)]) == 0
    doc = json.loads(capsys.readouterr().out)
    notes = "\n".join(doc["warnings"])
    assert "TAS in kt, converted to m/s" in notes
    assert "AOS in deg, converted to rad" in notes
    assert "flight.csv: 1 gap(s) in time" in notes
    assert "2 uniform segment(s) of the batch" in notes
    assert "inputs taken as sampled positions" in notes  # the potentiometers' noise
    assert doc["aircraft"]["kinematics"]
    named = {m["name"] for m in doc["modes"]}
    assert {"short period", "phugoid", "Dutch roll", "roll"} <= named
    # The second stretch does not start trimmed: from the trim it is punished for it.
    assert sum(doc["tic_validation"].values()) < sum(doc["tic"].values())
    assert doc["validation"]["tic_avg"] <= doc["validation"]["tic_from_trim_avg"]
    assert math.isfinite(doc["validation"]["tic_avg"])


def test_the_same_csv_without_its_units_or_with_an_unknown_input_is_refused_by_name(
    record, tmp_path, capsys
):
    data, config = tmp_path / "plain.csv", tmp_path / "mine.toml"
    _write(data, record, units=False)
    _config(config)
    code = main(["identify", str(data), "--config", str(config), "--axes", "full", "--json"])
    assert code == 2
    message = json.loads(capsys.readouterr().out)["error"]["message"]
    assert "these look like degrees" in message
    _write(data, record)
    lateral = ["--inputs", "DA,DR,THR", "--outputs", "AOS,P,R,PHI"]
    assert main(["identify", str(data), "--config", str(config), *lateral, "--json"]) == 2
    message = json.loads(capsys.readouterr().out)["error"]["message"]
    assert "input 'THR' (throttle) moves the longitudinal axis" in message
