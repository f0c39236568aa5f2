"""Smoke test of benchmarks/bench_jsbsim.py (`make bench-jsbsim`), as far as it runs in seconds.

What it cannot do briefly: every row is judged against the aircraft's validated linear truth
(`agent.sim.truth.linear_truth`), whose linearisation of JSBSim alone takes about 15 s here,
and the smallest run (`--quick --aircraft J3Cub --turbulence 0 --excitation full --nav ins
--seeds 1`: the calibration runs that size the preset, then one flight) 27 s. The suite's
smoke tests share a budget of about a minute and a half with two real-time simulated flights
(test_bench_agent, test_bench_abort), so this one stops short of the flights: the script
starts with no aircraft, after its imports, its arguments, its `--without` terms and
`--open-loop-prediction` are applied (the terms reach into the aircraft method, whose options
have moved before), and prints its table's head. The
truth is checked in the suite by tests/sim/test_truth.py and an offline flight through the full
preset identified by tests/sim/test_wind_job.py; the whole benchmark runs by `make
bench-jsbsim`."""

from __future__ import annotations

import types

import numpy as np
import pytest

from tests.benchmarks.bench import SLACK_S, help_text, refused, run

TIMEOUT_S = 60


@pytest.mark.timeout(TIMEOUT_S + SLACK_S)
def test_starts_with_every_term_left_out():
    done = run(
        "bench_jsbsim.py",
        *("--aircraft", "--no-peers", "--bound", "--without", "alpha-products", "sideslip-drag"),
        "--open-loop-prediction",
        timeout_s=TIMEOUT_S,
    )
    assert done.stdout.startswith("cells: median / worst over seeds"), done.stdout
    assert "short period" in done.stdout


def test_help_and_arguments():
    text = help_text("bench_jsbsim.py")
    assert "--without" in text
    assert "--still" in text  # what the air alone does
    assert "--bound" in text  # the truth's Cramér–Rao bound on each row's records
    assert "--open-loop-prediction" in text  # the lateral refinement's open-loop measurement
    refused(
        "bench_jsbsim.py",
        "--without",
        "wings",
        saying="invalid choice: 'wings'",
        timeout_s=TIMEOUT_S,
    )


def _bench():
    import importlib.util
    import sys
    from pathlib import Path

    path = Path(__file__).parents[2] / "benchmarks" / "bench_jsbsim.py"
    spec = importlib.util.spec_from_file_location("bench_jsbsim", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules["bench_jsbsim"] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def test_a_mode_of_two_real_poles_is_judged_by_its_wn_and_zeta():
    """The J-3 Cub's overdamped short period (−9.745 and −6.367 1/s: ωn 7.877, ζ 1.023)
    against an identified −7.507 ± 1.855j (ωn 7.733, ζ 0.971): 34 % apart pole by pole, 5.1 %
    in ζ and 1.8 % in ωn. A complex pair on both sides is still judged pole by pole; a
    missing mode is a miss."""
    bench = _bench()
    truth = {"short period": [-9.745 + 0j, -6.367 + 0j], "phugoid": [-0.036 + 0.344j]}
    found = {"short period": [-7.507 + 1.855j], "phugoid": [-0.040 + 0.344j]}
    errors = dict(zip(bench.MODES, bench.mode_errors(found, truth), strict=True))
    assert errors["short period"] == pytest.approx(0.0508, abs=5e-4)
    assert errors["phugoid"] == pytest.approx(0.004 / abs(-0.036 + 0.344j), rel=1e-6)
    assert errors["Dutch roll"] == 0.0  # no truth of it given: nothing to miss
    assert bench.mode_errors({}, truth)[0] == float("inf")
    # Two real poles found for a complex truth: by ωn and ζ too.
    two = bench.mode_errors({"short period": [-9.0 + 0j, -7.0 + 0j]}, found)[0]
    wn, zeta = 7.733, 7.507 / 7.733
    assert two == pytest.approx(
        max(abs(np.sqrt(63) - wn) / wn, abs(8 / np.sqrt(63) - zeta) / zeta), rel=1e-3
    )


def test_a_pair_near_its_double_root_is_judged_by_its_wn_and_zeta():
    """Two identified models' short periods on the J-3 Cub (closed against open loop): ωn
    7.699 and 7.921 rad/s, ζ 0.912 and 0.997, 34 % apart pole by pole, within 10 % in ωn and ζ
    (8.6 % in ζ); a lightly damped pair is still judged pole by pole."""
    bench = _bench()
    open_loop = {"short period": [-7.898 + 0.598j]}
    closed = {"short period": [-7.019 + 3.164j]}
    error = bench.mode_errors(closed, open_loop)[0]
    assert abs(-7.019 + 3.164j - (-7.898 + 0.598j)) / abs(-7.898 + 0.598j) > 0.3
    wn, zeta = abs(-7.898 + 0.598j), 7.898 / abs(-7.898 + 0.598j)
    wn_c, zeta_c = abs(-7.019 + 3.164j), 7.019 / abs(-7.019 + 3.164j)
    assert error == pytest.approx(max(abs(wn_c - wn) / wn, abs(zeta_c - zeta) / zeta), rel=1e-6)
    assert error < 0.10
    light = {"phugoid": [-0.036 + 0.344j]}
    moved = {"phugoid": [-0.046 + 0.344j]}
    assert bench.mode_errors(moved, light)[1] == pytest.approx(0.010 / abs(-0.036 + 0.344j))


def test_each_modes_error_is_scored_in_its_reported_standard_errors():
    """mode_z: a pair's ωn and ζ errors over their reported σ, a real pole's real part's, a
    mode of two real poles by its second-order ωn and ζ; a mode without σ or without a truth
    is not scored."""
    bench = _bench()
    std = types.SimpleNamespace
    phugoid = std(
        name="phugoid",
        pair=True,
        frequency=0.35,
        damping=0.12,
        eigenvalue=-0.042 + 0.347j,
        uncertainty=std(frequency=0.005, damping=0.01, real=0.003),
    )
    roll = std(name="roll", pair=False, eigenvalue=-12.5 + 0j, uncertainty=std(real=0.25))
    dutch = std(name="Dutch roll", pair=True, eigenvalue=-0.6 + 2.2j, uncertainty=None)
    short = std(name="short period", pair=False, eigenvalue=-9.0 + 0j, uncertainty=None)
    order = std(
        name="short period", frequency=7.7, damping=1.0, frequency_std=0.1, damping_std=0.05
    )
    result = std(modes=[phugoid, roll, dutch, short, short], second_order=lambda: [order])
    truth = {
        "phugoid": [-0.036 + 0.344j],
        "roll": [-12.0 + 0j],
        "Dutch roll": [-0.66 + 2.24j],
        "short period": [-9.745 + 0j, -6.367 + 0j],
    }
    z = bench.mode_z(result, truth)
    wn, zeta = abs(-0.036 + 0.344j), 0.036 / abs(-0.036 + 0.344j)
    assert z["phugoid ωn"] == pytest.approx((0.35 - wn) / 0.005)
    assert z["phugoid ζ"] == pytest.approx((0.12 - zeta) / 0.01)
    assert z["roll"] == pytest.approx(-2.0)
    wn_sp = np.sqrt(9.745 * 6.367)
    assert z["short period ωn"] == pytest.approx((7.7 - wn_sp) / 0.1)
    assert z["short period ζ"] == pytest.approx((1.0 - 16.112 / (2 * wn_sp)) / 0.05)
    assert not any(k.startswith("Dutch roll") for k in z)  # no σ reported
    assert "spiral" not in z


def test_the_novanes_rows_identify_the_record_as_an_aircraft_without_vanes_would():
    """experiment(vanes=False): α and β replaced by those synthesised from the record's INS
    (the vanes' never read), the navigation kept, and the experiment marked as such, so the
    method takes only the airspeed's gust as measured."""
    from agent.sim.offline import Record
    from tests.ident.test_airangles import flight

    bench = _bench()
    (alpha, _), speed, theta, phi, navigation = flight(heading_span=2.0, seed=4)
    n = speed.size
    y = np.zeros((n, len(Record.outputs)))
    for name, values in (("Vt", speed), ("theta", theta), ("phi", phi)):
        y[:, Record.outputs.index(name)] = values
    y[:, Record.outputs.index("alpha")] = 1.0  # a vane reading the synthesis must not use
    record = Record(u=np.zeros((n, 4)), y=y, dt=0.02, ins=navigation)
    setup = types.SimpleNamespace(controls=bench.INPUT_CHANNELS)
    exp = bench.experiment(record, setup, wind=False, vanes=False)
    column = Record.outputs.index("alpha")
    synthesised = exp.y[:, column] + exp.operating_point[column]
    assert np.degrees(np.std(synthesised - alpha)) < 0.25
    assert exp.air_angles is not None
    assert exp.navigation is navigation
    assert bench.experiment(record, setup).air_angles is None


def test_each_rows_z_scores_are_split_into_scatter_and_bias(capsys):
    """_print_scatter: each mode's scatter about the seeds' mean over its σ (rms with n − 1
    degrees of freedom) and the mean's distance from the truth over the median σ; a mode seen
    on fewer than three seeds is left out. mode_estimates_of: the truth's values by the same
    names (ωn and ζ of a pair or of two real poles, the real part of one real pole)."""
    bench = _bench()
    truth = {"phugoid": [-0.03 + 0.4j], "roll": [-5.0 + 0j], "short period": [-9.0, -4.0]}
    true = bench.mode_estimates_of(truth)
    assert true["phugoid ωn"] == pytest.approx(abs(-0.03 + 0.4j))
    assert true["short period ωn"] == pytest.approx(6.0)
    assert true["short period ζ"] == pytest.approx(13 / 12)
    assert true["roll"] == -5.0
    seeds = [
        ([0.0] * 4, 0.1, 0.2, None, {}, {"roll": (-5.2, 0.1), "phugoid ζ": (0.1, 0.01)}),
        ([0.0] * 4, 0.1, 0.2, None, {}, {"roll": (-5.4, 0.1), "phugoid ζ": (0.1, 0.01)}),
        ([0.0] * 4, 0.1, 0.2, None, {}, {"roll": (-5.3, 0.1)}),
    ]
    bench._print_scatter("full", "ins", seeds, true)
    out = capsys.readouterr().out
    # roll: deviations +0.1, −0.1, 0 about the mean −5.3 over σ 0.1 → √(2/2) = 1; its mean
    # 0.3 from the truth, 3σ; the phugoid's ζ, on two seeds only, is left out.
    assert "scatter over σ (rms about the seeds' mean): roll 1.0;" in out
    assert "the mean's bias over σ: roll -3.0" in out
    assert "phugoid" not in out
