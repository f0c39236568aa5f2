"""The whole-aircraft method (agent.ident.aircraft through `identify`): decoupled axes with
every state measured, fitted in the frequency domain, on known linear aircraft."""

from __future__ import annotations

import numpy as np
import pytest

from agent.excitation.plan import preset, render
from agent.ident import Experiment, Settings, identify
from agent.ident.aircraft import COUPLED
from agent.ident.convert import discretize_foh
from agent.ident.errors import DataError
from agent.ident.fit import simulate
from agent.ident.reference import LATERAL, LONGITUDINAL

DT = 0.01
TAU = 0.4  # the throttle's two lags, s
INPUTS = ("throttle", "elevator", "aileron", "rudder")
OUTPUTS = ("airspeed", "alpha", "q", "theta", "beta", "p", "r", "phi")


def aircraft_with_engine_lag():
    """The thesis's A.2 longitudinal and lateral models side by side (inputs throttle,
    elevator, aileron, rudder), the throttle through two lags of TAU: 10 states."""
    A, B = np.zeros((10, 10)), np.zeros((10, 4))
    A[:4, :4], A[4:8, 4:8] = LONGITUDINAL.A, LATERAL.A
    B[:4, 1], B[4:8, 2:] = LONGITUDINAL.B[:, 1], LATERAL.B
    A[:4, 9] = [0.01, -0.001, 0.002, 0.0]  # thrust per µs of throttle, after the lags
    A[8, 8] = A[9, 9] = -1 / TAU
    A[9, 8] = 1 / TAU
    B[8, 0] = 1 / TAU
    C = np.hstack([np.eye(8), np.zeros((8, 2))])
    return A, B, C


def full_preset_record(A, B, C):
    timeline = render(preset("full"), 1 / DT)
    u = np.column_stack([timeline.values[c] for c in INPUTS])
    u[:, 0] *= 10.0  # percent → µs
    u = np.vstack([np.zeros((100, 4)), u, np.zeros((200, 4))])
    model = discretize_foh(A, B, C, np.zeros((8, 4)), DT)  # inputs sampled, linear between
    return Experiment(u, simulate(model, u))


def test_noise_free_aircraft_is_recovered_with_its_engine_lag_and_no_coupling():
    A, B, C = aircraft_with_engine_lag()
    record = full_preset_record(A, B, C)
    result = identify(record, DT, input_names=INPUTS, output_names=OUTPUTS,
                      output_roles=OUTPUTS, settings=Settings(held_inputs=False))  # fmt: skip
    assert result.method == "aircraft"  # chosen by "auto" for both axes' outputs
    report = result.aircraft
    assert report["model"] == "decoupled"
    assert report["engine_lag_s"]["longitudinal"]["throttle"] == pytest.approx(TAU, rel=1e-3)
    for axis in ("longitudinal", "lateral"):  # the last digits of a perfect fit: no coupling
        assert report["coupling"][axis]["by_inputs"] < COUPLED
        assert report["coupling"][axis]["by_states"] < COUPLED
    found = np.sort_complex(np.linalg.eigvals(result.continuous.A[:8, :8]))
    true = np.sort_complex(np.linalg.eigvals(A[:8, :8]))
    # The transforms of samples stand in for continuous ones: (ωΔt)²/12 ≈ 0.3 % at 3 Hz.
    assert np.max(np.abs(found - true) / np.abs(true)) < 5e-3
    assert result.fit.tic_avg < 0.01
    # Every mode carries its standard error; the named ones are the aircraft's.
    assert all(mode.uncertainty is not None for mode in result.modes)
    assert {"Dutch roll", "roll"} <= {mode.name for mode in result.modes}


def test_the_same_identification_in_one_bin_set_per_record_batches_records():
    A, B, C = aircraft_with_engine_lag()
    one = full_preset_record(A, B, C)
    half = one.u.shape[0] // 2
    # Two records of one flight (a cut anywhere: each has its own transient).
    batch = [Experiment(one.u[:half], one.y[:half]), Experiment(one.u[half:], one.y[half:])]
    result = identify(batch, DT, input_names=INPUTS, output_names=OUTPUTS,
                      output_roles=OUTPUTS, settings=Settings(held_inputs=False))  # fmt: skip
    found = np.sort_complex(np.linalg.eigvals(result.continuous.A[:8, :8]))
    true = np.sort_complex(np.linalg.eigvals(A[:8, :8]))
    # A cut mid-flight leaves each record a large jump between its ends; the rectangle rule
    # of the transforms errs by O(Δt) on that jump's share (measured: 1.0 %).
    assert np.max(np.abs(found - true) / np.abs(true)) < 0.02


def test_the_aircraft_method_without_an_axis_is_refused_clearly():
    # Bad input tried: method "aircraft" asked for outputs that are no axis's four states.
    A, B, C = aircraft_with_engine_lag()
    record = full_preset_record(A, B, C)
    names = tuple(f"y{i}" for i in range(8))
    with pytest.raises(DataError, match="four outputs of an axis"):
        identify(record, DT, input_names=INPUTS, output_names=names, output_roles=names,
                 settings=Settings(method="aircraft"))  # fmt: skip
