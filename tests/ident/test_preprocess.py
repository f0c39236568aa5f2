"""Band of interest, anti-alias decimation, smoothing — and what they do to identification."""

from __future__ import annotations

import numpy as np
import pytest

from agent.ident import Experiment, Settings, identify, reference
from agent.ident.errors import DataError, InsufficientDataError
from agent.ident.preprocess import RATE_FACTOR, decimation_factor, input_band, preprocess
from tests.conftest import DT, matched_relative_errors, true_eigenvalues

LAT = reference.LATERAL


def _record(noise: float = 0.0, seed: int = 0) -> Experiment:
    u = reference.thesis_multisine(LAT, DT)
    y = reference.simulate(LAT, u, DT)
    return Experiment(u, reference.with_output_noise(y, noise, seed))


def test_band_is_the_highest_excited_harmonic():
    # Rudder's highest harmonic is 20/20 s = 1 Hz; the aileron stops at 0.6 Hz.
    assert input_band([_record()], DT) == pytest.approx(1.0, abs=1 / 30)


def test_decimation_follows_the_25_times_band_rule_and_keeps_enough_samples():
    assert decimation_factor(0.01, 1.0, 10_000) == int(100 / (RATE_FACTOR * 1.0))
    assert decimation_factor(0.02, 1.0, 1500) == 2
    assert decimation_factor(0.02, 5.0, 1500) == 1  # 50 Hz is already below 25 × 5 Hz
    assert decimation_factor(0.01, 0.5, 300) < 8  # a short record limits the factor


def test_decimated_batch_keeps_the_input_output_relation():
    """Noise-free A.2 data at 50 Hz decimated 2× and 5×: the refined model is still right."""
    truth = true_eigenvalues(LAT)
    for factor, tolerance in [(2, 0.01), (5, 0.03)]:
        result = identify(_record(), DT, settings=Settings(decimation=factor, order=4))
        assert result.dt == pytest.approx(DT * factor)
        found = [m.eigenvalue for m in result.modes]
        found += [m.eigenvalue.conjugate() for m in result.modes if m.pair]
        assert matched_relative_errors(np.array(found), truth).max() < tolerance


def test_half_sample_shift_of_held_inputs_removes_the_decimation_bias():
    truth = true_eigenvalues(LAT)

    def worst(held: bool) -> float:
        settings = Settings(decimation=2, order=4, markov=1, held_inputs=held)
        result = identify(_record(), DT, settings=settings)
        found = [m.eigenvalue for m in result.modes]
        found += [m.eigenvalue.conjugate() for m in result.modes if m.pair]
        return matched_relative_errors(np.array(found), truth).max()

    assert worst(True) < 0.01 < worst(False)


def test_decimation_lowers_the_noise_by_the_filtered_bandwidth():
    exp = _record(0.2)
    out, info = preprocess([exp], DT, decimation=5)
    clean, _ = preprocess([_record(0.0)], DT, decimation=5)
    noise_before = np.std(exp.y - _record(0.0).y, axis=0)
    noise_after = np.std(out[0].y - clean[0].y, axis=0)
    # White noise through a low-pass at 0.8 of the new Nyquist keeps ~0.8/5 of its variance.
    assert np.all(noise_after < 0.5 * noise_before)
    assert info.factor == 5
    assert info.dropped_samples == 50
    assert out[0].length == (exp.length - 100 - 1) // 5 + 1


def test_savitzky_golay_smoothing_applies_to_inputs_and_outputs():
    out, info = preprocess([_record(0.2)], DT, decimation=1, smoothing_s=0.3)
    assert info.smoothing_s == 0.3
    raw = _record(0.2)
    assert np.std(np.diff(out[0].y, axis=0)) < 0.5 * np.std(np.diff(raw.y, axis=0))
    assert not np.allclose(out[0].u, raw.u)  # same filter on the inputs


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"decimation": 1, "smoothing_s": 0.05}, "longer than the polynomial order"),
        ({"decimation": 1, "smoothing_s": 100.0}, "fit in every record"),
        ({"decimation": 40}, "samples per record"),
    ],
)
def test_impossible_preprocessing_is_refused_with_the_reason(kwargs, message):
    """Bad input tried: a smoothing window of 3 samples or longer than the record; a
    decimation factor the record is too short for."""
    with pytest.raises(InsufficientDataError, match=message):
        preprocess([_record()], DT, **kwargs)


@pytest.mark.parametrize("factor", [0, 1001])
def test_a_decimation_beyond_the_bound_is_refused_before_its_filter_is_built(factor):
    """Bad input tried: decimation factors of 0 and MAX_DECIMATION + 1 (10⁷, whose filter of
    2 × 10⁸ taps used to be built before the record's length was checked, is tried through
    `sysid identify` in tests/test_cli_identify.py, under a memory limit). Each is refused
    from its value alone."""
    with pytest.raises(DataError, match=rf"decimation {factor} is outside 1…1000"):
        preprocess([_record()], DT, decimation=factor)


def test_a_short_record_is_refused_from_the_filter_length_before_it_is_built(monkeypatch):
    """Bad input tried: a factor within the bound on a record too short for it: refused from
    the filter's length, counted, without building it."""
    import agent.ident.preprocess as prep

    def never(factor):
        raise AssertionError(f"a filter of {factor} built for a record too short for it")

    monkeypatch.setattr(prep, "lowpass_taps", never)
    with pytest.raises(InsufficientDataError, match="decimating by 1000 needs at least 40000"):
        preprocess([_record()], DT, decimation=1000)
