"""The result document's honesty about what a model lacks: a pole at z = 0 left out of the
modes (never a mode of NaNs), the expected modes not identified with why, both kept through
JSON and the text summary, and documents written before either existed still read.

Bad input tried: a record whose aileron reaches the plant one sample late (ERA realises the
delay as a pole at z ≈ 0), NaN and ∞ in a mode, a stored mode whose eigenvalue is NaN or
null, a model of too low an order to hold the lateral modes.
"""

from __future__ import annotations

import dataclasses
import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError

from agent.ident import Experiment, Settings, identify, reference
from agent.ident.document import ModeDocument, ResultDocument
from agent.ident.modal import EigenvalueStd
from agent.ident.summary import format_text
from tests.conftest import DT, detrimmed

LATERAL = reference.LATERAL


def delayed_aileron() -> tuple[np.ndarray, np.ndarray]:
    """The thesis's lateral plant, its aileron acting one sample after it is recorded."""
    u = np.vstack(
        [np.zeros((50, 2)), reference.multisine_inputs(LATERAL.inputs, DT, 30.0, 1, (0.05, 2.0))]
    )
    late = u.copy()
    late[1:, 0], late[0, 0] = u[:-1, 0], 0.0
    return u, reference.simulate(LATERAL, late, DT)


def delayed_identified(u: np.ndarray, y: np.ndarray, settings: Settings):
    """`delayed_aileron`'s record identified at order 5 (a pole at z = 0 among its poles)."""
    return identify(
        Experiment(u, y),
        DT,
        input_names=LATERAL.inputs,
        output_names=LATERAL.outputs,
        output_roles=LATERAL.outputs,
        settings=settings,
    )


@pytest.mark.parametrize(
    "settings", [Settings(order=5, method="time"), Settings(order=5, method="time", refine=False)]
)
def test_a_pole_at_z_0_is_left_out_with_a_note_and_never_a_null_eigenvalue(settings):
    u, y = delayed_aileron()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # "divide by zero encountered in log" was one
        found = delayed_identified(u, y, settings)
        doc = found.document()
    text = json.dumps(doc.model_dump(mode="json"), allow_nan=False)  # no NaN, no ∞ anywhere
    again = json.loads(text)
    assert all(None not in m["eigenvalue"] for m in again["modes"])
    assert {m["name"] for m in again["modes"]} == {"Dutch roll", "roll", "spiral"}
    dutch = next(m for m in again["modes"] if m["name"] == "Dutch roll")
    assert dutch["eigenvalue"] == pytest.approx([-3.692, 3.182], rel=1e-3)
    (note,) = again["poles_left_out"]
    assert "a pole at z ≈ 0" in note
    assert "pure sample delay" in note
    assert again["missing_modes"] == []
    assert ResultDocument.model_validate_json(text) == doc
    assert "left out: a pole at z ≈ 0" in format_text(found, 1, u.shape[0])


def test_a_mode_document_refuses_nan_and_infinity():
    """A regression that lets a non-finite number into a mode fails where it is made; a
    standard error that is not finite (a singular covariance) is unknown, None."""
    fields = {
        "name": "roll",
        "eigenvalue": (-9.0, 0.0),
        "frequency_rad_s": 9.0,
        "damping": 1.0,
        "time_constant_s": 0.11,
        "msv": 100.0,
        "mci": 100.0,
        "moi": 100.0,
        "emac": None,
        "mpc": 100.0,
        "cmi": None,
    }
    ModeDocument(**fields)
    for key, bad in [
        ("eigenvalue", (float("-inf"), float("nan"))),
        ("frequency_rad_s", float("inf")),
        ("damping", float("nan")),
        ("msv", float("nan")),
    ]:
        with pytest.raises(ValidationError, match="finite number"):
            ModeDocument(**(fields | {key: bad}))
    record = detrimmed(reference.make_record(LATERAL))
    found = identify(record, DT, output_roles=LATERAL.outputs, settings=Settings(method="time"))
    mode = found.modes[0]
    nan = EigenvalueStd(real=float("nan"), imag=0.0, frequency=float("inf"), damping=0.01)
    doc = ModeDocument.of(dataclasses.replace(mode, uncertainty=nan))
    assert doc.eigenvalue_std is None
    assert doc.frequency_std_rad_s is None
    assert doc.damping_std == 0.01


def test_the_expected_modes_not_identified_are_in_the_document_with_why():
    """A second-order model of a lateral record cannot hold its three modes: each is named as
    not identified, with the rule's reason, through JSON and the text summary."""
    record = detrimmed(reference.make_record(LATERAL))
    found = identify(
        record,
        DT,
        input_names=LATERAL.inputs,
        output_names=LATERAL.outputs,
        output_roles=LATERAL.outputs,
        settings=Settings(order=2, method="time"),
    )
    doc = ResultDocument.model_validate_json(found.document().model_dump_json())
    missing = {m.name: m.reason for m in doc.missing_modes}
    assert list(missing) == ["Dutch roll", "roll", "spiral"]
    assert missing["Dutch roll"].startswith("no named mode: no lateral pair damped below")
    assert "resolves time constants up to" in missing["spiral"]
    text = format_text(found, 1, record.length)
    assert "not identified: roll: no named mode: no fast stable real lateral mode" in text


def test_a_document_of_before_reads_with_empty_lists_and_its_nan_mode_left_out():
    """A model store file written before these fields existed reads with both lists empty; one
    written before poles at z = 0 were left out holds a mode of NaNs (the store's JSON) or of
    nulls (`--json`): it reads, the mode left out with a note, the other modes kept."""
    record = detrimmed(reference.make_record(LATERAL))
    found = identify(record, DT, output_roles=LATERAL.outputs, settings=Settings(method="time"))
    now = found.document().model_dump(mode="json")
    before = {k: v for k, v in now.items() if k not in ("missing_modes", "poles_left_out")}
    read = ResultDocument.model_validate(json.loads(json.dumps(before)))
    assert read.missing_modes == []
    assert read.poles_left_out == []
    assert read.modes == found.document().modes
    for nothing in (float("nan"), None):
        bad = dict(now["modes"][0], eigenvalue=[nothing, nothing], name=None)
        bad["frequency_rad_s"] = float("inf") if nothing is not None else None
        stored = json.dumps(before | {"modes": [*now["modes"], bad]})  # NaN as the store wrote
        read = ResultDocument.model_validate(json.loads(stored))
        assert len(read.modes) == len(now["modes"])
        (note,) = read.poles_left_out
        assert "no finite eigenvalue" in note
    # A mode with no eigenvalue at all is damage, not an earlier layout: refused.
    broken = dict(now["modes"][0])
    del broken["eigenvalue"]
    with pytest.raises(ValidationError):
        ResultDocument.model_validate(before | {"modes": [broken]})


def test_a_mode_of_two_real_poles_is_also_given_as_one_by_its_wn_and_zeta():
    """An overdamped short period (the J-3 Cub's −9.745 and −6.367 1/s) is listed as its two
    real poles and, below the table and in --json's `second_order`, as the one mode it is:
    ωn 7.877 rad/s, ζ 1.023 — the
    handling-qualities parameters, well determined near ζ = 1 where the poles are not. A
    complex pair, or a name with one pole, gets no such line."""
    from tests.ident.test_modal import _mode

    u, y = delayed_aileron()
    found = delayed_identified(u, y, Settings(order=5, method="time", refine=False))
    short = [_mode(s, [0.1, 1, 0.9, 0.2]) for s in (-9.745 + 0j, -6.367 + 0j)]
    modes = [*(dataclasses.replace(m, name="short period") for m in short), *found.modes]
    result = dataclasses.replace(found, modes=tuple(modes))
    text = format_text(result, 1, u.shape[0])
    assert "short period as one mode (its two real poles): ωn 7.877 rad/s, ζ 1.023" in text
    doc = ResultDocument.model_validate_json(result.document().model_dump_json())
    (one,) = doc.second_order
    assert one.name == "short period"
    assert one.frequency_rad_s == pytest.approx(np.sqrt(9.745 * 6.367), rel=1e-9)
    assert one.damping == pytest.approx((9.745 + 6.367) / (2 * np.sqrt(9.745 * 6.367)), rel=1e-9)
    assert found.document().second_order == []  # its own modes: pairs and single poles
    assert "Dutch roll as one mode" not in text  # a complex pair: its own line says it
    assert "roll as one mode" not in text


def test_the_tables_show_what_the_method_has_not_eras_dashes(capsys):
    """The whole-aircraft method realises no ERA model: its `sysid identify` table has no EMAC
    or CMI column of dashes, and `sysid sim`'s table shows each mode's Cramér–Rao σ(ωn) where
    the EMAC column was empty; OKID/ERA keeps both columns."""
    from agent.cli import main
    from agent.sim.flight import format_report

    record = Path(__file__).resolve().parents[2] / "examples" / "a2_lateral.csv"
    lateral = ["--inputs", "aileron,rudder", "--outputs", "beta,p,r,phi"]
    assert main(["identify", str(record), *lateral]) == 0
    aircraft = capsys.readouterr().out
    assert "EMAC" not in aircraft
    assert "CMI" not in aircraft
    assert "—  100" not in aircraft
    assert main(["identify", str(record), *lateral, "--method", "time"]) == 0
    era = capsys.readouterr().out
    assert "EMAC" in era
    assert "CMI" in era
    row = {"name": "roll", "eigenvalue": [-1.5, 0.0], "truth": [-1.55, 0.0], "error": 0.032}
    report = {
        "aircraft": "J3Cub",
        "preset": "lateral",
        "runs": 1,
        "history": [],
        "failure": None,
        "modes": [{**row, "emac": None, "sigma_pct": 1.234}],
        "suggestion": {"update": True, "steps": []},
        "tic_avg": 0.1,
        "decision": "accepted",
        "notices": [],
    }
    text = format_report(report)
    assert "σ(ωn) %" in text
    assert "1.23" in text
    assert "EMAC" not in text
    report["modes"] = [{**row, "emac": 97.0, "sigma_pct": None}]
    assert "EMAC %" in format_report(report)
