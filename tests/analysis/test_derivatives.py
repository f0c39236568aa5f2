"""The derivative table (agent/analysis/derivatives.py): its rows and columns, fixed and
unknown standard errors, and its CSV and HTML forms. Bad input tried: a model not in output
coordinates (no table), a model without standard errors (none made up)."""

from __future__ import annotations

import csv
import io

import numpy as np

from agent.analysis.derivatives import POOR, from_matrices, from_result, to_csv, to_html
from agent.ident.document import RefinementDocument, ResultDocument
from tests.documents import INPUTS, OUTPUTS, lateral_document


def lateral(n: int = 4):
    rng = np.random.default_rng(0)
    Ac, Bc = rng.normal(size=(n, n)), rng.normal(size=(n, 2))
    Ac_std, Bc_std = 0.01 * np.abs(Ac), 0.01 * np.abs(Bc)
    Ac_std[3] = 0.0  # the bank angle's row: kinematics, fixed
    Bc_std[0, 0] = 2 * POOR * abs(Bc[0, 0])  # poorly determined
    return Ac, Bc, Ac_std, Bc_std


def test_rows_are_the_outputs_rates_and_columns_the_states_then_the_inputs():
    Ac, Bc, Ac_std, Bc_std = lateral(n=6)  # two more states: the engine's lags
    d = from_matrices(OUTPUTS, INPUTS, Ac, Bc, Ac_std, Bc_std)
    assert d.equations == OUTPUTS
    assert d.variables == (*OUTPUTS, "x5", "x6", *INPUTS)
    assert d.value.shape == d.std.shape == (4, 8)
    np.testing.assert_array_equal(d.value[:, :6], Ac[:4])
    np.testing.assert_array_equal(d.value[:, 6:], Bc[:4])


def test_the_csv_and_html_say_what_is_fixed_unknown_and_poor():
    Ac, Bc, Ac_std, Bc_std = lateral()
    d = from_matrices(OUTPUTS, INPUTS, Ac, Bc, Ac_std, Bc_std)
    rows = list(csv.DictReader(io.StringIO(to_csv([("lat-1", d)]))))
    assert len(rows) == 4 * 6
    phi_p = next(r for r in rows if r["equation"] == "dphi/dt" and r["variable"] == "p")
    assert float(phi_p["std"]) == 0.0  # fixed, and said so by 0
    lp = next(r for r in rows if r["equation"] == "dp/dt" and r["variable"] == "p")
    assert float(lp["value"]) == float(f"{Ac[1, 1]:.6g}")
    assert float(lp["std_percent"]) == float(f"{100 * Ac_std[1, 1] / abs(Ac[1, 1]):.3g}")
    page = to_html(d)
    assert page.count('class="fixed"') == 4  # the bank angle's row over the states
    assert page.count('class="poor"') == 1
    unknown = from_matrices(OUTPUTS, INPUTS, Ac, Bc)  # not refined: no standard errors
    assert np.isnan(unknown.std).all()
    assert {r["std"] for r in csv.DictReader(io.StringIO(to_csv([("x", unknown)])))} == {""}
    assert "±" not in to_html(unknown)


def document(Ac=None, Bc=None, refinement=None) -> ResultDocument:
    """An identification's document with the continuous model (Ac, Bc) given, if any."""
    return lateral_document(
        Ac=None if Ac is None else Ac.tolist(),
        Bc=None if Bc is None else Bc.tolist(),
        coordinates="era" if Ac is None else "outputs",
        refinement=refinement,
    )


def test_a_model_not_in_output_coordinates_has_no_table():
    Ac, Bc, Ac_std, Bc_std = lateral()
    assert from_result(document()) is None
    unrefined = from_result(document(Ac, Bc))
    assert unrefined.value.shape == (4, 6)
    assert np.isnan(unrefined.std).all()
    refinement = RefinementDocument(
        criterion="output error",
        hold="zoh",
        iterations=3,
        converged=True,
        noise_std=dict.fromkeys(OUTPUTS, 0.001),
        Ac_std=Ac_std.tolist(),
        Bc_std=Bc_std.tolist(),
    )
    refined = from_result(document(Ac, Bc, refinement))
    np.testing.assert_array_equal(refined.std, np.hstack([Ac_std, Bc_std]))
