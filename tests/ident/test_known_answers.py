"""Known answers: noise-free records of the thesis's appendix A models (A.2, A.3, A.4).

Each record is the model discretised at 50 Hz (zero-order hold), a 1 s trimmed lead-in, then
30 s of orthogonal multisines on every input, in absolute units; trim is removed as the
command line does. The identified continuous model, in output coordinates, must give the true
eigenvalues to 1e-6 relative — and A, B themselves.
"""

from __future__ import annotations

import numpy as np
import pytest

from agent.ident import Settings, identify, reference
from tests.conftest import DT, detrimmed, matched_relative_errors, true_eigenvalues

ROLES = {
    "lateral": ("beta", "p", "r", "phi"),
    "longitudinal": ("airspeed", "alpha", "q", "theta"),
    "full": ("airspeed", "alpha", "q", "theta", "beta", "p", "r", "phi"),
}


@pytest.mark.parametrize("key", ["lateral", "longitudinal", "full"])
def test_noise_free_record_gives_true_eigenvalues_and_matrices(key):
    model = reference.MODELS[key]
    exp = detrimmed(reference.make_record(model))
    result = identify(exp, DT, output_roles=ROLES[key])

    assert result.order == model.A.shape[0]
    assert result.coordinates == "outputs"
    found = np.array(
        [m.eigenvalue for m in result.modes]
        + [m.eigenvalue.conjugate() for m in result.modes if m.pair]
    )
    assert matched_relative_errors(found, true_eigenvalues(model)).max() < 1e-6
    cont = result.continuous
    assert cont is not None
    assert np.abs(cont.A - model.A).max() / np.abs(model.A).max() < 1e-6
    assert np.abs(cont.B - model.B).max() / np.abs(model.B).max() < 1e-6
    assert np.allclose(cont.C, np.eye(model.A.shape[0]))
    assert np.all(cont.D == 0)
    assert result.fit.tic_avg < 1e-6


@pytest.mark.parametrize("p", [2, 5])
def test_given_markov_count_above_deadbeat_order_is_still_exact(p):
    model = reference.LATERAL
    exp = detrimmed(reference.make_record(model))
    result = identify(exp, DT, settings=Settings(markov=p))
    found = [m.eigenvalue for m in result.modes]
    found += [m.eigenvalue.conjugate() for m in result.modes if m.pair]
    assert result.okid.markov == p
    assert matched_relative_errors(np.array(found), true_eigenvalues(model)).max() < 1e-6


def test_lateral_modes_are_named_and_classified():
    exp = detrimmed(reference.make_record(reference.LATERAL))
    result = identify(exp, DT, output_roles=ROLES["lateral"])
    by_name = {m.name: m for m in result.modes}
    assert set(by_name) == {"Dutch roll", "roll", "spiral"}
    assert by_name["Dutch roll"].pair
    assert by_name["Dutch roll"].time_constant is None
    assert by_name["roll"].time_constant == pytest.approx(1 / 1.54923291, rel=1e-6)
    assert by_name["spiral"].time_constant == pytest.approx(1 / 0.09438903, rel=1e-6)
    dutch = by_name["Dutch roll"]
    assert dutch.frequency == pytest.approx(4.87400878, rel=1e-6)
    assert dutch.damping == pytest.approx(3.69210903 / 4.87400878, rel=1e-6)


def test_unstable_phugoid_is_reported_unstable_with_finite_indicators():
    exp = detrimmed(reference.make_record(reference.LONGITUDINAL))
    result = identify(exp, DT, output_roles=ROLES["longitudinal"])
    names = {m.name: m for m in result.modes}
    assert set(names) == {"phugoid", "short period"}
    assert not names["phugoid"].stable
    assert not result.stable
    assert 0 < names["phugoid"].msv <= 100  # defined for an unstable mode (finite sum)
    assert any("unstable" in w for w in result.warnings)


def test_estimated_feedthrough_is_recovered():
    model = reference.LATERAL
    D = np.array([[0.0, 0.001], [0.002, 0.0], [0.0, -0.003], [0.0, 0.0]])
    exp = detrimmed(reference.make_record(model))
    exp = type(exp)(u=exp.u, y=exp.y + exp.u @ D.T)
    result = identify(exp, DT, settings=Settings(estimate_d=True, markov=2))
    assert np.abs(result.discrete.D - D).max() < 1e-9
    without = identify(exp, DT, settings=Settings(estimate_d=False, markov=2))
    assert np.all(without.discrete.D == 0)
    assert without.fit.tic_avg > 1e3 * result.fit.tic_avg


def test_observer_gain_is_deadbeat_for_noise_free_full_state_data():
    exp = detrimmed(reference.make_record(reference.LATERAL))
    result = identify(exp, DT, settings=Settings(markov=1))
    model = result.discrete
    observer = model.A + result.okid.observer_gain @ model.C
    assert np.abs(np.linalg.eigvals(observer)).max() < 1e-6


def test_tikhonov_regularization_damps_but_keeps_dominant_dynamics():
    exp = detrimmed(reference.make_record(reference.LATERAL))
    plain = identify(exp, DT, settings=Settings(markov=10, order=4, refine=False))
    ridge = identify(
        exp, DT, settings=Settings(markov=10, order=4, regularization=1e-3, refine=False)
    )
    truth = true_eigenvalues(reference.LATERAL)

    def err(result):
        found = [m.eigenvalue for m in result.modes]
        found += [m.eigenvalue.conjugate() for m in result.modes if m.pair]
        return matched_relative_errors(np.array(found), truth)

    assert err(plain).max() < 1e-6
    assert err(ridge).max() > err(plain).max()  # regularization biases a noise-free fit...
    assert err(ridge).max() < 0.2  # ...but not away from the dominant modes
