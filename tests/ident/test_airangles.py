"""α and β without vanes (agent.ident.aircraft.airangles): synthesised from the INS's velocity,
the attitude and an estimated wind, checked against the α and β a known flight had.

The flight: a known air-relative motion (airspeed, α, β, attitude, a turn through the
heading) in a known steady wind that drifts; the INS reads the air velocity turned into
north, east, down plus the wind, the pitot the airspeed, each with its noise.

Bad input tried: arrays of different lengths, a non-finite sample, a record without the INS's
velocities (in the functions and through `sysid identify`), onboard windows with missing edge
rows."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from agent.ident import job as jobs
from agent.ident.aircraft.airangles import Sources, fill, synthesise
from tests.ident.test_aircraft import (
    DT,
    INPUTS,
    RECORDED,
    _body_to_ned,
    gusty_record,
    window_job,
)
from tests.test_cli_identify import run_json, write

RATE = 50.0
NAV = ("psi", "vn", "ve", "vd")


def flight(heading_span: float, seed: int = 0, wind=(4.0, -6.0), drift=(1.0, 0.5)):
    """(truth, speed, theta, phi, navigation) of a 60 s flight: α, β oscillating by about 2°
    and 1.5°, bank up to 20°, the heading swept over `heading_span` rad, in a wind `wind`
    (north, east, m/s) that changes by `drift` over the record; pitot noise 0.1 m/s, INS
    0.05 m/s and 0.1°."""
    rng = np.random.default_rng(seed)
    t = np.arange(0, 60, 1 / RATE)
    s = t / t[-1] - 0.5
    speed = 25.0 + 1.5 * np.sin(0.21 * t)
    alpha = 0.06 + 0.035 * np.sin(1.3 * t) + 0.01 * np.sin(3.1 * t)
    beta = 0.01 + 0.026 * np.sin(1.9 * t + 0.4)
    theta = 0.05 + 0.04 * np.sin(0.33 * t)
    phi = 0.35 * np.sin(0.11 * t)
    psi = 1.0 + heading_span * (0.5 - 0.5 * np.cos(np.pi * t / t[-1]))
    body = np.column_stack(
        [
            speed * np.cos(alpha) * np.cos(beta),
            speed * np.sin(beta),
            speed * np.sin(alpha) * np.cos(beta),
        ]
    )
    ned = np.array(
        [_body_to_ned(f, th, p) @ b for f, th, p, b in zip(phi, theta, psi, body, strict=True)]
    )
    ned[:, 0] += wind[0] + drift[0] * s
    ned[:, 1] += wind[1] + drift[1] * s
    navigation = np.column_stack(
        [psi + rng.normal(0, np.radians(0.1), t.size), ned + rng.normal(0, 0.05, ned.shape)]
    )
    measured = speed + rng.normal(0, 0.1, t.size)
    return (alpha, beta), measured, theta, phi, navigation


def test_a_turning_flight_gives_back_its_wind_and_its_air_angles():
    (alpha, beta), speed, theta, phi, navigation = flight(heading_span=np.pi)
    made = synthesise(speed, theta, phi, navigation)
    assert made.wind == pytest.approx((4.0, -6.0), abs=0.15)
    assert made.drift == pytest.approx((1.0, 0.5), abs=0.3)
    assert made.sideslip == pytest.approx(np.mean(beta), abs=0.005)
    assert made.airspeed_rms == pytest.approx(0.1, rel=0.3)
    assert np.degrees(made.heading_span) == pytest.approx(180.0, abs=1.0)
    # Within the INS's noise (0.1° of heading, 0.05 m/s: about 0.15° rms on β) and the wind
    # estimate's error (0.1 m/s is 0.23° here).
    for found, true in ((made.alpha, alpha), (made.beta, beta)):
        assert np.degrees(np.sqrt(np.mean((found - true) ** 2))) < 0.25
    assert "wind of 7.2 m/s from 124°" in made.note()


def test_on_one_heading_the_angles_motion_is_right_though_the_cross_wind_is_not_known():
    # Flown on one heading, the wind across the track and the mean sideslip cannot be told
    # apart; the identification removes the trim, so what matters is each angle's motion.
    (alpha, beta), speed, theta, phi, navigation = flight(heading_span=0.0, seed=1)
    made = synthesise(speed, theta, phi, navigation)
    for found, true in ((made.alpha, alpha), (made.beta, beta)):
        error = (found - found.mean()) - (true - true.mean())
        assert np.degrees(np.std(error)) < 0.25  # the INS noise: about 0.15°
        assert np.corrcoef(found, true)[0, 1] > 0.98


def test_the_vanes_are_kept_where_the_record_has_them_and_synthesised_where_not():
    (alpha, beta), speed, theta, phi, navigation = flight(heading_span=1.0, seed=2)
    columns = {"Vt": speed, "theta": theta, "phi": phi}
    columns |= dict(zip(("psi", "vn", "ve", "vd"), navigation.T, strict=True))
    vanes = {**columns, "alpha": alpha + 0.01, "beta": beta}
    out, made = fill(vanes, ["Vt", "alpha", "beta"], Sources())
    assert made is None
    assert out["alpha"] is vanes["alpha"]
    out, made = fill(vanes, ["Vt", "alpha"], Sources(mode="synthesised"))
    assert made is not None
    assert np.degrees(np.std(out["alpha"] - alpha)) < 0.25
    out, made = fill(columns, ["p", "r"], Sources())  # neither angle wanted
    assert made is None
    assert "alpha" not in out
    out, made = fill(columns, ["beta", "p"], Sources(mode="vanes"))
    assert made is None
    assert "beta" not in out
    # An onboard window: edge rows without the INS yet, and a vane channel of NaN only.
    window = {**columns, "alpha": np.full(speed.size, np.nan)}
    window["vn"] = window["vn"].copy()
    window["vn"][:10] = np.nan
    out, made = fill(window, ["alpha", "q"], Sources())
    assert made is not None
    assert np.isnan(out["alpha"][:10]).all()
    assert np.isfinite(out["alpha"][10:]).all()
    assert np.degrees(np.std(out["alpha"][10:] - alpha[10:])) < 0.25


def test_what_a_synthesis_needs_is_named_when_it_is_missing():
    # Bad input tried: no INS velocities, a non-finite sample, lengths that disagree.
    (_alpha, _), speed, theta, phi, navigation = flight(heading_span=1.0, seed=3)
    columns = {"Vt": speed, "theta": theta, "phi": phi, "psi": navigation[:, 0]}
    with pytest.raises(ValueError, match=r"has no alpha .*missing: vn, ve, vd"):
        fill(columns, ["alpha", "q"], Sources())
    bad = speed.copy()
    bad[5] = np.nan
    with pytest.raises(ValueError, match="finite"):
        synthesise(bad, theta, phi, navigation)
    with pytest.raises(ValueError, match="one row per sample"):
        synthesise(speed[1:], theta, phi, navigation)


def test_sysid_identify_synthesises_what_a_record_without_vanes_lacks(capsys, tmp_path):
    # A CSV with the airspeed, the attitude and the INS but no alpha or beta column (a small
    # aircraft's log): `--axes full` identifies it with α and β synthesised and says so;
    # `--air-angles vanes` refuses it naming the missing column. Bad input tried: the same
    # record without the INS's velocities (nothing to synthesise from).
    u, air, op, navigation, _ = gusty_record(seed=5, scale=0.015)
    navigation[:, 1] += 5.0
    x = air + op
    columns = {"time": np.arange(len(u)) * DT}
    columns |= dict(zip(INPUTS, u.T, strict=True))
    for name, k in (("Vt", 0), ("q", 2), ("theta", 3), ("p", 5), ("r", 6), ("phi", 7)):
        columns[name] = x[:, k]
    record = write(tmp_path / "vaneless.csv", columns | dict(zip(NAV, navigation.T, strict=True)))
    code, doc = run_json(capsys, str(record), "--axes", "full")
    assert code == 0
    assert doc["aircraft"]["wind"]["air_angles"] == "synthesised"
    assert doc["aircraft"]["wind"]["synthesised"][0]["wind_mps"] == pytest.approx(
        [5.0, 0.0], abs=0.3
    )
    assert any("alpha and beta synthesised (no vanes)" in w for w in doc["warnings"])
    assert {m["name"] for m in doc["modes"]} >= {"short period", "phugoid", "Dutch roll", "roll"}
    code, doc = run_json(capsys, str(record), "--axes", "full", "--air-angles", "vanes")
    assert code == 2
    assert "alpha" in doc["error"]["message"]
    blind = write(tmp_path / "blind.csv", columns | {"psi": navigation[:, 0]})
    code, doc = run_json(capsys, str(blind), "--axes", "full")
    assert code == 2
    assert "missing: vn, ve, vd" in doc["error"]["message"]


def test_an_onboard_window_without_vanes_is_identified_with_synthesised_angles():
    # The agent's job on a window whose α and β columns hold nothing (an airspeed-only probe:
    # `[sensors.airdata] vanes = false` records them missing), edge rows without the INS:
    # the job synthesises them and its result says so.
    u, air, op, navigation, _ = gusty_record(seed=6, scale=0.015)
    x = air + op
    window = dict(zip(INPUTS, u.T, strict=True)) | dict(zip(RECORDED, x.T, strict=True))
    window["alpha"] = np.full(len(u), np.nan)
    window["beta"] = np.full(len(u), np.nan)
    window |= dict(zip(NAV, navigation.T, strict=True))
    window["vn"] = window["vn"].copy()
    window["vn"][:5] = np.nan
    job = window_job(window, navigation=NAV, air_angles=Sources())
    outcome = jobs.run(job)
    assert outcome.ok, outcome.reason
    assert outcome.result.aircraft.wind.air_angles == "synthesised"
    assert any("synthesised (no vanes)" in w for w in outcome.result.warnings)
    # Bad input tried: the same window without the INS's velocities: a failure saying why.
    blind = {k: v for k, v in window.items() if k not in ("vn", "ve", "vd")}
    outcome = jobs.run(dataclasses.replace(job, window=blind))
    assert not outcome.ok
    assert "missing: vn, ve, vd" in outcome.reason
