"""Frequency-domain OKID (thesis §4.3.1): period detection, averaged spectra, FRF, Markov
parameters by inverse FFT (broadband batch) and by the matrix-fraction observer fit (the
thesis's sparse multisines), leakage warnings."""

from __future__ import annotations

import numpy as np
import pytest

from agent.excitation.signals import multisine
from agent.ident import Experiment, Settings, identify, reference
from agent.ident.convert import discretize
from agent.ident.errors import InsufficientDataError
from agent.ident.frequency import (
    analyse,
    averaged_spectra,
    detect_period,
    frequency_response,
    inverse_fft_markov,
    observer_markov_from_frf,
)
from agent.ident.okid import system_markov
from tests.conftest import DT, matched_relative_errors, true_eigenvalues

LAT = reference.LATERAL


def _thesis_record(duration: float, noise: float = 0.0, seed: int = 0) -> Experiment:
    u = reference.thesis_multisine(LAT, DT, duration=duration)
    y = reference.simulate(LAT, u, DT)
    return Experiment(u, reference.with_output_noise(y, noise, seed))


def _true_frf(A, B, freqs_cycles_per_sample):
    Ad, Bd = discretize(A, B, DT)
    n = A.shape[0]
    return np.array(
        [
            np.linalg.solve(np.exp(2j * np.pi * f) * np.eye(n) - Ad, Bd)
            for f in freqs_cycles_per_sample
        ]
    )


def test_period_is_found_even_with_one_and_a_half_periods():
    assert detect_period(_thesis_record(30.0).u) == round(20.0 / DT)
    rng = np.random.default_rng(0)
    assert detect_period(rng.normal(size=(1500, 2))) is None


def test_frf_at_the_excited_harmonics_is_the_true_transfer_function_in_steady_state():
    exp = _thesis_record(200.0)  # 10 periods; the first (transient) is left out
    spectra = averaged_spectra([exp], round(20.0 / DT))
    assert spectra.periodic
    assert spectra.segments == 9
    frf = frequency_response(spectra)
    excited = np.flatnonzero(frf.known.any(axis=1))
    # Aileron on harmonics 3, 6, 9, 12 and rudder on 5, 10, 15, 20: one input per bin.
    assert set(excited) == {3, 5, 6, 9, 10, 12, 15, 20}
    truth = _true_frf(LAT.A, LAT.B, frf.freqs[excited])
    for k, f in enumerate(excited):
        j = int(np.flatnonzero(frf.known[f])[0])
        # The spiral's 10.6 s transient is e^(−20/10.6) ≈ 15 % after one period and decays
        # by that factor every period: averaged over nine periods it leaves under 1 %.
        assert np.allclose(frf.H[f][:, j], truth[k][:, j], rtol=0.02, atol=1e-4)


def test_observer_fit_to_the_sparse_frf_recovers_the_model():
    exp = _thesis_record(200.0)
    frf = frequency_response(averaged_spectra([exp], round(20.0 / DT)))
    omp = observer_markov_from_frf(frf, 1)
    result = identify(
        exp,
        DT,
        settings=Settings(method="frequency", markov=1, order=4, decimation=1, refine=False),
    )
    assert result.okid.markov == 1
    assert omp.Ybar1.shape == (1, 4, 2)
    found = [m.eigenvalue for m in result.modes]
    found += [m.eigenvalue.conjugate() for m in result.modes if m.pair]
    assert matched_relative_errors(np.array(found), true_eigenvalues(LAT)).max() < 0.01


def test_broadband_batch_gives_markov_parameters_by_inverse_fft():
    """Two records, each exciting one input on every harmonic: S_uu is full rank at every
    bin of the batch, so eq. 4.26 applies. A fast model keeps time aliasing negligible."""
    A = np.array([[-2.0, 3.0], [-3.0, -2.0]])
    B = np.array([[1.0, 0.0], [0.5, 1.0]])
    period, dt = 1024, DT
    batch = []
    for j in range(2):
        wave = multisine(range(1, period // 2), period * dt, dt, 4 * period * dt, 1.0)
        u = np.zeros((wave.size, 2))
        u[:, j] = wave
        Ad, Bd = discretize(A, B, dt)
        x, y = np.zeros(2), []
        for k in range(u.shape[0]):
            y.append(x.copy())
            x = Ad @ x + Bd @ u[k]
        batch.append(Experiment(u, np.array(y)))
    frf = frequency_response(averaged_spectra(batch, period))
    assert frf.broadband
    markov = inverse_fft_markov(frf, 30)
    Ad, Bd = discretize(A, B, dt)
    expected = np.array([np.linalg.matrix_power(Ad, k - 1) @ Bd for k in range(1, 30)])
    assert np.allclose(markov[1:], expected, atol=1e-6)
    assert np.allclose(markov[0], 0.0, atol=1e-6)
    result = identify(batch, dt, settings=Settings(method="frequency", decimation=1))
    found = [m.eigenvalue for m in result.modes]
    found += [m.eigenvalue.conjugate() for m in result.modes if m.pair]
    assert matched_relative_errors(np.array(found), np.linalg.eigvals(A)).max() < 1e-4


def test_frequency_method_with_refinement_on_the_thesis_record():
    truth = true_eigenvalues(LAT)
    result = identify(_thesis_record(30.0, 0.05), DT, settings=Settings(method="frequency"))
    found = [m.eigenvalue for m in result.modes]
    found += [m.eigenvalue.conjugate() for m in result.modes if m.pair]
    assert matched_relative_errors(np.array(found), truth).max() < 0.03
    assert any("one whole period" in w for w in result.warnings)


def test_leakage_is_measured_and_warned_about():
    """Bad input tried: a 'periodic' record whose second period is played 5 % louder, and a
    record with no period at all (random input)."""
    exp = _thesis_record(60.0)
    u = exp.u.copy()
    u[1000:2000] *= 1.05
    y = reference.simulate(LAT, u, DT)
    data = analyse([Experiment(u, y)], period=1000)
    assert data.spectra.leakage == pytest.approx(0.05, rel=0.2)
    assert any("leakage" in w for w in data.warnings)
    rng = np.random.default_rng(1)
    u = rng.normal(size=(1500, 2))
    data = analyse([Experiment(u, reference.simulate(LAT, u, DT))])
    assert data.period is None
    assert not data.spectra.periodic
    assert any("not periodic" in w for w in data.warnings)


def test_too_few_harmonics_for_p_is_refused_with_the_reason():
    """Bad input tried: p = 3 from eight excited harmonics (at most p = 1 is determined)."""
    frf = frequency_response(averaged_spectra([_thesis_record(60.0)], 1000))
    with pytest.raises(InsufficientDataError, match="at most p = 1"):
        observer_markov_from_frf(frf, 3)


def test_system_markov_of_the_frequency_observer_matches_the_truth():
    exp = _thesis_record(200.0)
    frf = frequency_response(averaged_spectra([exp], 1000))
    Y = system_markov(observer_markov_from_frf(frf, 1), 6)
    Ad, Bd = discretize(LAT.A, LAT.B, DT)
    assert np.allclose(Y[1], Bd, rtol=0.02, atol=1e-5)
    assert np.allclose(Y[3], Ad @ Ad @ Bd, rtol=0.02, atol=1e-5)
