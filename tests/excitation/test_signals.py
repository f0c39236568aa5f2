"""Signal library: shapes, spectra, peak factors, sweep laws, harmonic allocation."""

from __future__ import annotations

import numpy as np
import pytest

from agent.excitation import signals

DT = 0.02


def _spectrum_bins(u: np.ndarray, period: float, dt: float) -> np.ndarray:
    """Power per harmonic of 1/period over the whole periods in u."""
    n = round(period / dt)
    whole = u[: (len(u) // n) * n]
    power = np.abs(np.fft.rfft(whole)) ** 2
    periods = len(whole) // n
    return power[::periods][: n // 2]


@pytest.mark.parametrize("surface", ["aileron", "rudder", "elevator"])
def test_multisine_power_only_at_assigned_harmonics(surface):
    k = signals.THESIS_HARMONICS[surface]
    u = signals.multisine(k, 20.0, DT, 40.0, 3.0, signals.low_peak_phases(k))
    bins = _spectrum_bins(u, 20.0, DT)
    assigned = np.zeros(bins.size, dtype=bool)
    assigned[list(k)] = True
    assert bins[~assigned].max() < 1e-20 * bins[assigned].min()
    # Equal amplitudes: the assigned harmonics carry equal power.
    assert np.ptp(bins[assigned]) < 1e-9 * bins[assigned].max()


def test_multisine_keeps_its_peak_amplitude():
    u = signals.multisine((3, 6, 9, 12), 20.0, DT, 40.0, 2.5)
    assert np.max(np.abs(u)) == pytest.approx(2.5)


def test_optimised_phases_beat_schroeder_and_reach_the_rpf_target():
    for k in signals.THESIS_HARMONICS.values():
        schroeder = signals.multisine(k, 20.0, DT, 20.0, 1.0)
        optimised = signals.multisine(k, 20.0, DT, 20.0, 1.0, signals.low_peak_phases(k))
        assert signals.relative_peak_factor(schroeder) == pytest.approx(1.19, abs=0.01)
        assert signals.relative_peak_factor(optimised) <= 1.05
        # Deterministic: the ground preview and the onboard player agree.
        assert np.array_equal(signals.low_peak_phases(k), signals.low_peak_phases(list(k)))


def test_low_peak_phases_refuses_bad_harmonics():
    # Bad input tried: repeated harmonic, zero harmonic, empty set.
    for bad in [(3, 3, 6), (0, 2), ()]:
        with pytest.raises(ValueError, match="distinct integers"):
            signals.low_peak_phases(bad)


def test_peak_factor_of_a_sine_is_root_two():
    t = np.arange(1000) * 0.001
    assert signals.peak_factor(np.sin(2 * np.pi * 5 * t)) == pytest.approx(np.sqrt(2), rel=1e-3)
    assert signals.relative_peak_factor(np.sin(2 * np.pi * 5 * t)) == pytest.approx(1, rel=1e-3)


def test_allocator_interleaves_disjoint_harmonics_over_the_band():
    alloc = signals.allocate_harmonics(["aileron", "rudder", "elevator"], 20.0, (0.1, 1.5))
    every = [k for ks in alloc.values() for k in ks]
    assert sorted(every) == list(range(2, 31))  # 0.1 Hz … 1.5 Hz of a 20 s period
    assert len(set(every)) == len(every)
    # Each surface spans the band, so each sees low and high frequencies.
    for ks in alloc.values():
        assert min(ks) <= 4
        assert max(ks) >= 28
    # Orthogonal over whole periods.
    dt, waves = 0.01, []
    for ks in alloc.values():
        waves.append(signals.multisine(ks, 20.0, dt, 40.0, 1.0, signals.low_peak_phases(ks)))
    for i in range(3):
        for j in range(i + 1, 3):
            corr = waves[i] @ waves[j] / np.linalg.norm(waves[i]) / np.linalg.norm(waves[j])
            assert abs(corr) < 1e-12


def test_allocator_says_what_to_change_when_the_band_is_too_narrow():
    # Bad input tried: a band holding two harmonics for three surfaces; an inverted band.
    with pytest.raises(ValueError, match="lengthen the period or widen the band"):
        signals.allocate_harmonics(["a", "b", "c"], 10.0, (0.1, 0.25))
    with pytest.raises(ValueError, match="low < high"):
        signals.allocate_harmonics(["a"], 10.0, (1.0, 0.5))


def test_doublet_shape():
    u = signals.doublet(0.1, 0.5, 2.0, lead=0.3, tail=0.2)
    expected = [0] * 3 + [2.0] * 5 + [-2.0] * 5 + [0] * 2
    assert np.array_equal(u, expected)


def test_3211_shape():
    u = signals.three_two_one_one(0.05, 0.3, 1.5)
    n = 6  # samples per unit pulse
    expected = [1.5] * 3 * n + [-1.5] * 2 * n + [1.5] * n + [-1.5] * n
    assert np.array_equal(u, expected)


def test_steps_hold_each_level():
    u = signals.steps(0.1, 0.5, 10.0, (1, 1, -1))
    assert np.array_equal(u, [10.0] * 10 + [-10.0] * 5)


def _zero_crossing_frequency(u: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(mid times, frequencies) from successive upward zero crossings, interpolated."""
    i = np.flatnonzero((u[:-1] < 0) & (u[1:] >= 0))
    crossings = (i + u[i] / (u[i] - u[i + 1])) * dt
    return (crossings[1:] + crossings[:-1]) / 2, 1 / np.diff(crossings)


@pytest.mark.parametrize("law", ["linear", "log"])
def test_sweep_follows_its_frequency_law(law):
    dt, f0, f1, duration = 0.0005, 0.5, 5.0, 20.0
    u = signals.sweep(dt, f0, f1, duration, 1.0, law=law)
    t, f = _zero_crossing_frequency(u, dt)
    expected = signals.sweep_frequency(t, f0, f1, duration, law)
    assert np.max(np.abs(f / expected - 1)) < 0.005
    # The two laws differ: half way, linear is at the mean, log at the geometric mean.
    middle = np.argmin(np.abs(t - duration / 2))
    target = (f0 + f1) / 2 if law == "linear" else np.sqrt(f0 * f1)
    assert f[middle] == pytest.approx(target, rel=0.01)


def test_sweep_dwell_and_fade():
    dt = 0.001
    u = signals.sweep(dt, 1.0, 4.0, 6.0, 2.0, law="log", fade=0.5, dwell_cycles=2)
    assert u.size == round(8.0 / dt)  # 2 cycles at 1 Hz, then 6 s of sweep
    assert abs(u[0]) < 1e-12
    assert abs(u[-1]) < 1e-3
    # During the dwell (after the fade) the signal is a 1 Hz sine of full amplitude.
    t = np.arange(u.size) * dt
    dwell = (t > 0.5) & (t < 2.0)
    assert np.allclose(u[dwell], 2.0 * np.sin(2 * np.pi * (t[dwell] - 2.0)), atol=1e-9)
    with pytest.raises(ValueError, match="law"):
        signals.sweep(dt, 1.0, 4.0, 6.0, 2.0, law="cubic")


def test_a_shape_interpolates_in_log_frequency_and_holds_beyond_its_ends():
    shape = ((0.1, 0.2), (1.0, 1.0))
    gain = signals.shaped(shape, np.array([0.01, 0.1, np.sqrt(0.1), 1.0, 5.0]))
    assert gain == pytest.approx([0.2, 0.2, 0.6, 1.0, 1.0])
    assert signals.shaped((), np.array([0.3, 3.0])) == pytest.approx([1.0, 1.0])


def test_a_shaped_multisine_plays_each_line_at_its_gain():
    k = (1, 3, 5, 7)
    gains = np.array([0.25, 0.5, 1.0, 0.75])
    phases = signals.low_peak_phases(k)
    flat = signals.multisine(k, 20.0, DT, 20.0, 3.0, phases)
    shaped = signals.multisine(k, 20.0, DT, 20.0, 3.0, phases, gains)
    line = np.abs(np.fft.rfft(shaped))[list(k)] / np.abs(np.fft.rfft(flat))[list(k)]
    assert line == pytest.approx(gains, rel=1e-9)


def test_a_shaped_sweep_plays_the_gain_of_its_instantaneous_frequency():
    shape = ((0.2, 0.25), (1.0, 1.0))
    flat = signals.sweep(DT, 0.1, 2.0, 40.0, 3.0, "log")
    shaped = signals.sweep(DT, 0.1, 2.0, 40.0, 3.0, "log", shape=shape)
    hz = signals.sweep_instants(DT, 0.1, 2.0, 40.0, "log")
    moving = np.abs(flat) > 0.5  # away from the zero crossings
    ratio = shaped[moving] / flat[moving]
    assert ratio == pytest.approx(signals.shaped(shape, hz[moving]), rel=1e-9)
    assert ratio.min() == pytest.approx(0.25)
    assert ratio.max() == pytest.approx(1.0)


def test_a_sweep_split_by_frequency_sums_to_itself_and_keeps_each_band_to_its_own():
    u = signals.sweep(DT, 0.1, 2.0, 40.0, 3.0, "log", fade=2.0, dwell_cycles=1)
    hz = signals.sweep_instants(DT, 0.1, 2.0, 40.0, "log", dwell_cycles=1)
    centres = np.geomspace(0.1, 2.0, 5)
    bands = signals.split_by_frequency(u, hz, centres)
    assert len(bands) == 5
    assert np.sum(bands, axis=0) == pytest.approx(u, abs=1e-12)
    for band, centre in zip(bands, centres, strict=True):
        playing = hz[np.abs(band) > 1e-9]
        # A band plays only between its neighbours' centres.
        assert playing.min() >= centre / (2.0 / 0.1) ** 0.25 * (1 - 1e-9)
        assert playing.max() <= centre * (2.0 / 0.1) ** 0.25 * (1 + 1e-9)


def test_a_shaped_multisine_still_starts_at_trim():
    """Lines turned down move the waveform's zero crossings: the start is found on the shaped
    waveform, so a whole period still starts and ends at trim."""
    k = (1, 3, 5, 7, 9, 11)
    gains = np.array([0.1, 0.2, 1.0, 1.0, 0.5, 1.0])
    flat_start = signals.zero_start(k, signals.low_peak_phases(k))
    assert abs(signals.multisine(k, 20.0, DT, 20.0, 3.0, flat_start, gains)[0]) > 0.01
    phases = signals.zero_start(k, signals.low_peak_phases(k), gains)
    u = signals.multisine(k, 20.0, DT, 20.0, 3.0, phases, gains)
    assert abs(u[0]) < 1e-9
