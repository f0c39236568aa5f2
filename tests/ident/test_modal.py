"""Modes and their indicators: known values, and independence from the state coordinates."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

from agent.ident import identify, reference
from agent.ident.convert import StateSpace, continuous_eigenvalues, discretize
from agent.ident.errors import ContinuousConversionError, IdentificationFailed
from agent.ident.modal import (
    HankelFactors,
    Mode,
    left_out,
    modal_analysis,
    modal_phase_collinearity,
)
from agent.ident.naming import expected_modes, missing_modes, name_modes
from tests.conftest import DT, detrimmed


@pytest.fixture(scope="module")
def lateral():
    return identify(detrimmed(reference.make_record(reference.LATERAL)), DT)


def _indicators(modes):
    return np.array(
        [[m.frequency, m.damping, m.msv, m.mci, m.moi, m.emac, m.mpc, m.cmi] for m in modes]
    )


def test_noise_free_well_excited_modes_have_full_emac(lateral):
    for mode in lateral.modes:
        assert mode.emac == pytest.approx(100.0, abs=1e-6)
        assert 0 < mode.msv <= 100
        assert 0 < mode.mci <= 100
        assert 0 < mode.moi <= 100
    assert max(m.msv for m in lateral.modes) == pytest.approx(100.0)


def test_real_modes_have_full_mpc_and_cmi_equals_emac_times_mpc(lateral):
    real = [m for m in lateral.modes if not m.pair]
    assert len(real) == 2
    for mode in real:
        assert mode.mpc == pytest.approx(100.0, abs=1e-9)
    for mode in lateral.modes:
        assert mode.cmi == pytest.approx(mode.emac * mode.mpc / 100)


def test_mpc_of_known_shapes():
    assert modal_phase_collinearity(np.array([1.0, 2.0, -3.0], dtype=complex)) == pytest.approx(1.0)
    assert modal_phase_collinearity(
        np.array([1, 2, -3], dtype=complex) * np.exp(0.7j)
    ) == pytest.approx(1.0)
    assert modal_phase_collinearity(np.array([1.0, 1.0j])) == pytest.approx(
        0.0, abs=1e-12
    )  # circular


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_eigenvalues_and_indicators_do_not_depend_on_state_coordinates(lateral, seed):
    rng = np.random.default_rng(seed)
    era = lateral.okid.era
    model = StateSpace(era.A, era.B, era.C, era.D)
    factors = HankelFactors(era.observability, era.controllability)
    T = rng.normal(size=(4, 4)) + 4 * np.eye(4)
    moved, moved_factors = model.transformed(T), factors.transformed(T)
    scales = {"input_scale": np.array([2.0, 3.0]), "output_scale": np.array([0.05, 0.1, 0.1, 0.05])}
    before = modal_analysis(model.A, model.B, model.C, DT, factors=factors, **scales)
    after = modal_analysis(moved.A, moved.B, moved.C, DT, factors=moved_factors, **scales)
    assert np.allclose([m.eigenvalue for m in before], [m.eigenvalue for m in after], rtol=1e-9)
    assert np.allclose(_indicators(before), _indicators(after), rtol=1e-6, atol=1e-6)


def test_indicators_without_hankel_factors_leave_emac_unset(lateral):
    model = lateral.discrete
    modes = modal_analysis(model.A, model.B, model.C, DT)
    assert all(m.emac is None and m.cmi is None for m in modes)
    assert all(0 < m.msv <= 100 for m in modes)


def test_inconsistent_mode_has_low_emac():
    """A mode that the data's Hankel factor does not continue as λ^k predicts loses EMAC."""
    Ac = np.diag([-1.0, -3.0])
    A, B = discretize(Ac, np.array([[1.0], [1.0]]), DT)
    C = np.eye(2)
    alpha = beta = 20
    obs = np.vstack([C @ np.linalg.matrix_power(A, k) for k in range(alpha)])
    ctrl = np.hstack([np.linalg.matrix_power(A, k) @ B for k in range(beta)])
    good = modal_analysis(A, B, C, DT, factors=HankelFactors(obs, ctrl))
    obs_bad = obs.copy()
    obs_bad[-2:, 1] *= -1  # the last block flips phase for state 2 only
    bad = modal_analysis(A, B, C, DT, factors=HankelFactors(obs_bad, ctrl))
    assert [m.emac for m in good] == pytest.approx([100.0, 100.0])
    assert min(m.emac for m in bad) < 10.0


def _mode(eigenvalue: complex, shape, msv=50.0, emac=100.0) -> Mode:
    return Mode(
        eigenvalue=eigenvalue,
        discrete=np.exp(eigenvalue * DT),
        pair=abs(eigenvalue.imag) > 0,
        frequency=abs(eigenvalue),
        damping=-eigenvalue.real / abs(eigenvalue),
        time_constant=None if eigenvalue.imag else -1 / eigenvalue.real,
        msv=msv,
        mci=50.0,
        moi=50.0,
        emac=emac,
        mpc=100.0,
        cmi=emac,
        shape=np.asarray(shape, dtype=complex),
    )


def test_longitudinal_names_from_frequency_and_shape():
    roles = ("airspeed", "alpha", "q", "theta")
    phugoid = _mode(-0.05 + 0.4j, [1, 0.01, 0.05, 0.8])
    short = _mode(-4 + 3j, [0.05, 1, 0.9, 0.2])
    named = name_modes([phugoid, short], roles)
    assert [m.name for m in named] == ["phugoid", "short period"]
    only_short = name_modes([short], roles)
    assert only_short[0].name == "short period"
    only_phugoid = name_modes([phugoid], roles)
    assert only_phugoid[0].name == "phugoid"


def test_a_pair_is_named_by_its_shape_not_by_being_the_fastest_or_slowest():
    """Bad input tried: the modes of a glider identified without vanes in turbulence — a slow
    pair that α and q dominate (the synthesised α drifting with the wind estimate) below the
    phugoid, and one fast real pole of an overdamped short period. Named by order, the
    phugoid was the "short period" (94 % off, z 268 over ten seeds)."""
    roles = ("airspeed", "alpha", "q", "theta")
    drift = _mode(-0.065 + 0.061j, [0.1, 1, 0.3, 0.2])
    phugoid = _mode(-0.036 + 0.286j, [1, 0.1, 0.2, 0.9])
    fast = _mode(-3.7 + 0j, [0.05, 1, 0.6, 0.1])
    named = name_modes([drift, phugoid, fast], roles)
    assert [m.name for m in named] == [None, "phugoid", None]
    assert [name for name, _ in missing_modes(named, roles)] == ["short period"]
    # With a short-period pair beside them, it is named as before; a V–θ pair faster than
    # an α–q pair does not make that α–q pair a short period.
    short = _mode(-4 + 3j, [0.05, 1, 0.9, 0.2])
    named = name_modes([drift, phugoid, short], roles)
    assert [m.name for m in named] == [None, "phugoid", "short period"]
    slow_short = _mode(-0.1 + 0.15j, [0.05, 1, 0.9, 0.2])
    assert [m.name for m in name_modes([slow_short, phugoid], roles)] == [None, "phugoid"]


def test_unclear_modes_stay_unnamed():
    roles = ("airspeed", "alpha", "q", "theta")
    reals = [_mode(-0.5 + 0j, [1, 0.1, 0.1, 1]), _mode(-6 + 0j, [0.1, 1, 1, 0.1])]
    assert [m.name for m in name_modes(reals, roles)] == [None, None]  # relaxed stability
    noise = _mode(-30 + 120j, [0.1, 0.2, 1, 0.1])  # far above rigid-body frequencies
    inconsistent = _mode(-4 + 3j, [0.05, 1, 0.9, 0.2], emac=5.0)
    assert [m.name for m in name_modes([noise, inconsistent], roles)] == [None, None]
    lat_roles = ("beta", "p", "r", "phi")
    middle = _mode(-0.6 + 0j, [0.1, 1, 0.2, 1])  # τ = 1.7 s: neither clearly roll nor spiral
    assert name_modes([middle], lat_roles)[0].name is None
    mixed = _mode(-2 + 2j, [1, 1, 1, 1, 1, 1, 1, 1])  # equal energy in both axes
    full_roles = ("airspeed", "alpha", "q", "theta", "beta", "p", "r", "phi")
    assert name_modes([mixed], full_roles)[0].name is None


def test_no_roles_no_names(lateral):
    named = name_modes(lateral.modes, [None, None, None, None])
    assert all(m.name is None for m in named)
    assert [dataclasses.replace(m, name=None) for m in named] == list(named)


def test_a_nearly_real_pair_is_not_the_dutch_roll_but_a_split_real_pole():
    # Seen in the simulator: noise split the roll pole into a pair with ζ = 0.999 that carried
    # more of the response than the real Dutch roll; the oscillatory pair must get the name,
    # and the split pair is the roll (τ = 0.08 s), not the extra real pole beside it.
    roles = ("beta", "p", "r", "phi")
    split_roll = _mode(-12.2 + 0.6j, [0.05, 1, 0.1, 0.3], msv=80.0)
    dutch = _mode(-0.65 + 2.2j, [1, 0.5, 0.9, 0.2], msv=30.0)
    named = name_modes([split_roll, dutch], roles)
    assert [m.name for m in named] == ["roll", "Dutch roll"]
    spiral = _mode(0.04 + 0j, [0.3, 0.1, 0.5, 1], msv=30.0)
    extra = _mode(-0.65 + 0j, [0.2, 0.5, 0.3, 1], msv=3.0)
    named = name_modes([spiral, extra, dutch, split_roll], roles)
    assert [m.name for m in named] == ["spiral", None, "Dutch roll", "roll"]


def test_a_real_lateral_mode_that_does_not_subside_is_not_the_roll():
    # Bad input tried: the record of JSBSim's glider in light turbulence that did not resolve
    # the roll mode left two real poles near zero, +0.149 and −0.119 1/s: the faster, being
    # unstable, is not the roll subsidence (its damping is negative on every aircraft), and
    # the roll is missing with the reason, not a pole named roll 104 % off. A stable real pole
    # slower than a spiral can be (τ 4.2 s) is not it either; a single unstable one neither.
    roles = ("beta", "p", "r", "phi")
    dutch = _mode(-0.96 + 2.0j, [1, 0.5, 0.9, 0.2], msv=30.0)
    spiral = _mode(-0.119 + 0j, [0.3, 0.1, 0.5, 1], msv=30.0)
    for faster in (0.149, -0.236):
        other = _mode(faster + 0j, [0.05, 1, 0.1, 0.3], msv=40.0)
        named = name_modes([dutch, other, spiral], roles)
        assert [m.name for m in named] == ["Dutch roll", None, "spiral"]
        ((name, reason),) = missing_modes(named, roles)
        assert name == "roll"
        assert "stable" in reason
    roll = _mode(-3.4 + 0j, [0.05, 1, 0.1, 0.3], msv=40.0)
    named = name_modes([dutch, roll, spiral], roles)
    assert [m.name for m in named] == ["Dutch roll", "roll", "spiral"]
    unstable = _mode(3.4 + 0j, [0.05, 1, 0.1, 0.3], msv=40.0)
    assert [m.name for m in name_modes([dutch, unstable], roles)] == ["Dutch roll", None]


def test_a_lightly_damped_pair_is_preferred_for_the_dutch_roll():
    # Seen in the simulator: the roll pole split into a pair at ζ = 0.92 that carried more of
    # the response than the real Dutch roll (ζ = 0.29), and took its name.
    roles = ("beta", "p", "r", "phi")
    split_roll = _mode(-13.4 + 5.8j, [0.05, 1, 0.1, 0.3], msv=80.0)
    dutch = _mode(-0.65 + 2.2j, [1, 0.5, 0.9, 0.2], msv=30.0)
    assert [m.name for m in name_modes([split_roll, dutch], roles)] == [None, "Dutch roll"]
    # A heavily damped Dutch roll (the thesis's A.2 model: ζ = 0.76) is still one, and with no
    # lightly damped pair at all the most energetic pair below ζ = 0.95 keeps the name.
    heavy = _mode(-3.69 + 3.18j, [1, 0.5, 0.9, 0.2], msv=30.0)
    assert [m.name for m in name_modes([split_roll, heavy], roles)] == [None, "Dutch roll"]
    assert name_modes([split_roll], roles)[0].name == "Dutch roll"


def test_an_overdamped_short_period_and_phugoid_are_named_from_their_real_poles():
    """Bad input tried: real longitudinal poles only (no pair at all), a short-period pair with
    two slow real poles, and slow real poles that α and q dominate, or that are not slower
    than the short period: only the first two are named."""
    roles = ("airspeed", "alpha", "q", "theta")
    short = [_mode(-10.1 + 0j, [0.1, 1, 0.9, 0.2]), _mode(-6.4 + 0j, [0.1, 0.8, 1, 0.3])]
    slow = [_mode(-0.05 + 0j, [1, 0.05, 0.02, 0.9]), _mode(-0.3 + 0j, [0.9, 0.1, 0.05, 1])]
    named = name_modes([*slow, *short], roles)
    assert [m.name for m in named] == ["phugoid", "phugoid", "short period", "short period"]
    pair = _mode(-4 + 3j, [0.05, 1, 0.9, 0.2])
    named = name_modes([*slow, pair], roles)
    assert [m.name for m in named] == ["phugoid", "phugoid", "short period"]
    alpha_q = [_mode(-0.05 + 0j, [0.1, 1, 0.5, 0.1]), _mode(-0.3 + 0j, [0.9, 0.1, 0.05, 1])]
    assert [m.name for m in name_modes([*alpha_q, pair], roles)] == [None, None, "short period"]
    fast = [_mode(-6 + 0j, [1, 0.05, 0.02, 0.9]), _mode(-7 + 0j, [0.9, 0.1, 0.05, 1])]
    assert [m.name for m in name_modes([*fast, pair], roles)] == [None, None, "short period"]
    # A phugoid pair keeps its name; the slow real poles beside it stay unnamed.
    phugoid = _mode(-0.05 + 0.4j, [1, 0.01, 0.05, 0.8])
    named = name_modes([*slow, phugoid, pair], roles)
    assert [m.name for m in named] == [None, None, "phugoid", "short period"]


def test_the_missing_expected_modes_are_listed_with_why():
    """Bad input tried: a full record's modes with no phugoid, no spiral and a Dutch roll whose
    EMAC is too low, and a record of unknown roles (nothing is expected, nothing missing)."""
    roles = ("airspeed", "alpha", "q", "theta", "beta", "p", "r", "phi")
    lon, lat = [1, 1, 1, 1, 0, 0, 0, 0], [0, 0, 0, 0, 1, 1, 1, 1]
    short = _mode(-4 + 3j, [0.05, 1, 0.9, 0.2, 0, 0, 0, 0])
    roll = _mode(-9 + 0j, [0, 0, 0, 0, 0.05, 1, 0.1, 0.3])
    weak_dutch = _mode(-0.7 + 2.2j, lat, emac=20.0)
    slow = _mode(-0.6 + 0j, lon)  # one real pole: no overdamped phugoid
    modes = name_modes([slow, weak_dutch, short, roll], roles)
    missing = dict(missing_modes(modes, roles, span_s=20.0))
    assert list(missing) == ["phugoid", "Dutch roll", "spiral"]
    assert missing["phugoid"].startswith(
        "no named mode: no longitudinal pair, nor two real modes slower than the short period, "
        "dominated by airspeed and θ; unnamed: -0.6 1/s; a 20 s record resolves time "
        "constants up to 10 s and frequencies down to 0.31 rad/s"
    )
    assert "set aside: -0.7 ± 2.2j 1/s (EMAC 20 % < 50 %)" in missing["Dutch roll"]
    assert "no slow real lateral mode" in missing["spiral"]
    assert expected_modes(roles) == ("short period", "phugoid", "Dutch roll", "roll", "spiral")
    assert missing_modes(modes, [None] * 8) == []


def test_a_pole_at_z_0_is_left_out_of_the_modes_without_a_warning():
    """Bad input tried: a discrete model with an eigenvalue of exactly 0 (a one-sample delay)
    and one at 1e-12 (numerically 0): ln(0) used to give −∞ + NaN j, a mode of NaNs and
    "divide by zero in log". Both are left out, the note says so, and no warning is raised."""
    for zero in (0.0, 1e-12):
        A = np.diag([zero, 0.9, 0.5])
        B, C = np.ones((3, 1)), np.eye(3)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            modes = modal_analysis(A, B, C, DT)
            notes = left_out(A, DT)
        assert sorted(m.discrete.real for m in modes) == pytest.approx([0.5, 0.9])
        assert all(np.isfinite(m.eigenvalue) and np.isfinite(m.damping) for m in modes)
        assert len(notes) == 1
        assert "a pole at z ≈ 0" in notes[0]
        assert "pure sample delay" in notes[0]
        assert "left out of the modes" in notes[0]
    assert modal_analysis(np.zeros((1, 1)), np.ones((1, 1)), np.eye(1), DT) == []
    with pytest.raises(ContinuousConversionError, match="no continuous-time eigenvalue"):
        continuous_eigenvalues(np.array([0.0]), DT)


def test_a_pole_whose_response_overflows_the_analysis_is_a_clear_failure():
    # Bad input tried: a fitted model with a pole of +4000 1/s (a diverged fit; JSBSim's glider
    # in turbulence gave one): its powers overflow the Hankel horizon. A clear failure naming
    # the pole, not numpy's "SVD did not converge".
    dt = 0.01
    A = np.diag(np.exp(np.array([-1.0, -3.0, 4000.0]) * dt))
    B, C = np.ones((3, 1)), np.ones((2, 3))
    with pytest.raises(IdentificationFailed, match=r"a pole of 4e\+03 1/s .* the fit diverged"):
        modal_analysis(A, B, C, dt)
    # A fast but ordinary unstable pole (+5 1/s) is analysed as before.
    A[2, 2] = np.exp(5.0 * dt)
    assert len(modal_analysis(A, B, C, dt)) == 3


def test_a_mode_whose_shape_mixes_the_axes_takes_the_axis_the_models_structure_gives():
    # Two modes of the two axes at nearly one eigenvalue (the Cub's roll at −12.1 1/s beside
    # a short-period pole at −11.6) mix their eigenvectors through a weak coupling: neither
    # shape lies 70 % in one axis, and without the model's word the roll went unnamed. The
    # structure's axis is taken only where the shape says nothing: a clear shape keeps its own.
    roles = ("airspeed", "alpha", "q", "theta", "beta", "p", "r", "phi")
    fast_lon = _mode(-5.4 + 0j, [0.1, 1, 0.9, 0.1, 0, 0, 0, 0])
    near_lon = _mode(-11.6 + 0j, [0.05, 0.8, 1, 0.1, 0.1, 0.9, 0.1, 0.1])
    roll = _mode(-12.1 + 0j, [0.05, 0.7, 0.8, 0.1, 0.1, 1, 0.1, 0.1])
    spiral = _mode(-0.01 + 0j, [0, 0, 0, 0, 0.1, 0.01, 0.1, 1])
    modes = [fast_lon, near_lon, roll, spiral]
    assert [m.name for m in name_modes(modes, roles, min_msv=0.0)] == [None, None, None, "spiral"]
    axes = ["lon", "lon", "lat", "lon"]  # the spiral's wrong word is not taken over its shape
    named = name_modes(modes, roles, min_msv=0.0, axes=axes)
    assert [m.name for m in named] == ["short period", "short period", "roll", "spiral"]


def test_two_modes_of_two_axes_at_one_eigenvalue_take_the_structures_axes():
    # Bad input tried: an overdamped short period's fast pole beside the roll mode (JSBSim's
    # J-3 Cub, −12.1 and −12.2 1/s), whose eigenvectors mix through the weak coupling so that
    # both look 80 % longitudinal: by the shapes alone the longitudinal axis has one mode more
    # than its states give and the roll mode is lost. The structure (each eigenvalue matched
    # to an axis's own) gives each axis its count, and its axes stand.
    roles = ("airspeed", "alpha", "q", "theta", "beta", "p", "r", "phi")
    modes = [
        _mode(-0.04 + 0.35j, [1, 0.05, 0.05, 0.8, 0, 0, 0, 0]),
        _mode(-5.2 + 0j, [0.05, 1, 0.9, 0.2, 0.02, 0.02, 0, 0]),
        _mode(-12.08 + 0j, [0.05, 1, 0.9, 0.2, 0.2, 0.45, 0.1, 0.1]),
        _mode(-12.17 + 0j, [0.05, 1, 0.9, 0.2, 0.2, 0.45, 0.1, 0.1]),
        _mode(-0.67 + 2.25j, [0, 0, 0, 0, 1, 0.8, 0.8, 0.4]),
        _mode(-0.01 + 0j, [0, 0, 0, 0, 0.1, 0.05, 0.2, 1]),
    ]
    structure = ["lon", "lon", "lat", "lon", "lat", "lat"]
    by_shape = [m.name for m in name_modes(modes, roles, min_msv=0.0)]
    assert "roll" not in by_shape
    named = [m.name for m in name_modes(modes, roles, min_msv=0.0, axes=structure)]
    assert named == ["phugoid", "short period", "roll", "short period", "Dutch roll", "spiral"]
    # Where the shapes' count is the structure's they keep deciding.
    agreeing = ["lon", "lon", "lat", "lon", "lon", "lat"]
    assert [m.name for m in name_modes(modes, roles, min_msv=0.0, axes=agreeing)] == by_shape
