"""The whole-aircraft method (agent.ident.aircraft through `identify`): decoupled axes with
every state measured, fitted in the frequency domain, on known linear aircraft."""

from __future__ import annotations

import dataclasses
import re
import types

import numpy as np
import pytest
import scipy.linalg

from agent.excitation.plan import Doublet, Plan, Segment, ThreeTwoOneOne, preset, render
from agent.ident import Experiment, Identification, Settings, identify
from agent.ident import job as jobs
from agent.ident.aircraft import fit, predictor
from agent.ident.aircraft.airangles import synthesise
from agent.ident.aircraft.fit import (
    COUPLED,
    SMOOTH_BINS,
    SMOOTH_FLOOR,
    bin_sigma,
    consistent,
    normal_inverse,
    smooth_bins,
)
from agent.ident.aircraft.kinematics import GRAVITY, kinematic_jacobian, kinematic_remainder
from agent.ident.aircraft.model import _mode_axes
from agent.ident.aircraft.noise import FALSE_ALARM, conditional_mean, detected
from agent.ident.aircraft.prepare import DENSITY_GRADIENT, prepare
from agent.ident.aircraft.transforms import Transforms, excited
from agent.ident.convert import discretize_foh
from agent.ident.errors import DataError, IdentificationFailed
from agent.ident.fit import simulate, theil
from agent.ident.reference import LATERAL, LONGITUDINAL
from agent.ident.summary import format_text
from agent.models import TIC_LIMIT, Candidate, excited_tic, suggest

DT = 0.01
TAU = 0.4  # the throttle's two lags, s
INPUTS = ("throttle", "elevator", "aileron", "rudder")
OUTPUTS = ("airspeed", "alpha", "q", "theta", "beta", "p", "r", "phi")
# OUTPUTS as the recorder names them
RECORDED = ("Vt", "alpha", "q", "theta", "beta", "p", "r", "phi")


def window_job(window: dict, **extra) -> jobs.Job:
    """The agent's whole-aircraft job on one recorded window (columns by name: the inputs,
    RECORDED, and any the `extra` fields name, e.g. the INS's)."""
    return jobs.Job(
        model_id="1",
        axes="full",
        record_dt=DT,
        inputs=INPUTS,
        outputs=RECORDED,
        roles=OUTPUTS,
        experiments=(),
        settings=Settings(held_inputs=False),
        window=window,
        **extra,
    )


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


def aircraft_identify(record, inputs=INPUTS, **options) -> Identification:
    """The whole record identified as the agent does for `--axes full`: every channel named
    by its role, the inputs sampled (not held); `options`: other settings."""
    return identify(
        record,
        DT,
        input_names=inputs,
        output_names=OUTPUTS,
        output_roles=OUTPUTS,
        settings=Settings(held_inputs=False, **options),
    )


def test_noise_free_aircraft_is_recovered_with_its_engine_lag_and_no_coupling():
    A, B, C = aircraft_with_engine_lag()
    record = full_preset_record(A, B, C)
    result = aircraft_identify(record)
    assert result.method == "aircraft"  # chosen by "auto" for both axes' outputs
    report = result.aircraft
    assert report.model == "decoupled"
    # The lag shows only in the throttle's band (< 0.12 Hz, ωτ < 0.3), and the per-band weights
    # of a noise-free fit are set by the transforms' own small errors: 2.0 % measured.
    assert report.engine_lag_s["longitudinal"]["throttle"] == pytest.approx(TAU, rel=3e-2)
    for axis in ("longitudinal", "lateral"):  # the last digits of a perfect fit: no coupling
        assert report.coupling[axis].response_by_inputs < COUPLED
        assert report.coupling[axis].response_by_states < COUPLED
    found = np.sort_complex(np.linalg.eigvals(result.continuous.A[:8, :8]))
    true = np.sort_complex(np.linalg.eigvals(A[:8, :8]))
    # The transforms of samples stand in for continuous ones: (ωΔt)²/12 ≈ 0.3 % at 3 Hz.
    assert np.max(np.abs(found - true) / np.abs(true)) < 5e-3
    assert result.fit.tic_avg < 0.01
    # The simulation starts where the outputs start, the engine's lag states at rest (estimated
    # by least squares they took values of ±1000 on a JSBSim record).
    x0 = result.fit.initial_states[0]
    assert np.all(x0[8:] == 0)
    assert np.allclose(x0[:8], record.y[:5].mean(axis=0))
    # Every mode carries its standard error; the named ones are the aircraft's.
    assert all(mode.uncertainty is not None for mode in result.modes)
    assert {"Dutch roll", "roll"} <= {mode.name for mode in result.modes}


def aircraft_with_engine_order(order: int):
    """`aircraft_with_engine_lag` with the throttle through `order` lags of TAU (0: the
    thrust follows at once)."""
    A, B, C = aircraft_with_engine_lag()
    n = 8 + order
    A2, B2 = A[:n, :n].copy(), B[:n].copy()
    if order == 0:
        B2[:4, 0] = A[:4, 9]
    elif order == 1:
        A2[:4, 8] = A[:4, 9]
        B2[8, 0] = 1 / TAU
    return A2, B2, C[:, :n]


@pytest.mark.parametrize("order", [0, 1, 2])
def test_the_engines_number_of_lags_is_the_datas(order):
    # A turbine's spool (one lag), a piston's manifold and speed (two), a thrust that follows
    # at once (none): the record says which, the Akaike criterion picks it, and the result and
    # its summary report it. 1 % sensor noise: the choice must not hang on the last digits.
    A, B, C = aircraft_with_engine_order(order)
    record = full_preset_record(A, B, C)
    noise = 0.01 * record.y.std(axis=0)
    y = record.y + noise * np.random.default_rng(order).standard_normal(record.y.shape)
    result = aircraft_identify(Experiment(record.u, y))
    (engine,) = result.aircraft.engine
    assert (engine.input, engine.lags, engine.measured) == ("throttle", order, False)
    assert engine.criterion[order] == 0.0
    assert all(v > 0 for k, v in engine.criterion.items() if k != order)
    assert set(engine.criterion) == {0, 1, 2}
    assert result.order == 8 + order  # the model carries the lags it chose, no more
    if order:
        assert engine.time_constant_s == pytest.approx(TAU, rel=0.05)
        assert result.aircraft.engine_lag_s["longitudinal"]["throttle"] == engine.time_constant_s
    else:
        assert engine.time_constant_s is None
        assert "longitudinal" not in result.aircraft.engine_lag_s
    found = np.sort_complex(np.linalg.eigvals(result.continuous.A[:8, :8]))
    true = np.sort_complex(np.linalg.eigvals(A[:8, :8]))
    assert np.max(np.abs(found - true) / np.abs(true)) < 0.02
    text = format_text(result, 1, len(y))
    assert f"engine: throttle {'at once' if not order else 'through'}" in text
    assert "lags 0/1/2: AIC" in text


def test_a_measured_rpm_is_the_engines_input_at_once_and_the_throttle_is_set_aside():
    # The record carries the engine's speed (here the last lag state × 2): it is the
    # longitudinal axis's known input without lags, and the throttle command beside it would
    # be the same path twice, so it is set aside with a note — not dropped silently.
    A, B, C = aircraft_with_engine_lag()
    record = full_preset_record(A, B, C)
    C2 = np.vstack([C, 2.0 * np.eye(10)[9:]])
    y = simulate(discretize_foh(A, B, C2, np.zeros((9, 4)), DT), record.u)
    u = np.column_stack([record.u, y[:, 8]])
    result = aircraft_identify(Experiment(u, y[:, :8]), inputs=(*INPUTS, "rpm"))
    assert any("throttle set aside: the measured rpm" in w for w in result.warnings)
    (engine,) = result.aircraft.engine
    assert (engine.input, engine.lags, engine.measured) == ("rpm", 0, True)
    longitudinal = next(a for a in result.aircraft.axes if a.name == "longitudinal")
    assert longitudinal.inputs == ["elevator", "rpm"]
    assert result.order == 8  # no lag states: the engine's speed is measured
    # The rpm's gains within 3 % of the largest (measured: 2.1 %, on V̇'s; 1.0 % by output
    # error: the noise-free record's residual, the transforms' own errors, is coloured, so the
    # longitudinal axis takes the filter-error method, agent.ident.aircraft.process).
    gains = result.continuous.B[:4, 4] * 2.0
    assert np.max(np.abs(gains - A[:4, 9])) < 0.03 * np.max(np.abs(A[:4, 9]))
    assert np.all(result.continuous.B[:, 0] == 0)  # the throttle's column: not used
    found = np.sort_complex(np.linalg.eigvals(result.continuous.A[:8, :8]))
    true = np.sort_complex(np.linalg.eigvals(A[:8, :8]))
    assert np.max(np.abs(found - true) / np.abs(true)) < 0.01
    assert "engine: rpm measured, at once" in format_text(result, 1, len(u))
    # Bad input tried: a measured rpm column of zeros (a log's empty thrust channel) is refused
    # by name, not fitted as an input with no effect.
    u[:, 4] = 0.0
    with pytest.raises(DataError, match="input 'rpm' is constant"):
        aircraft_identify(Experiment(u, y[:, :8]), inputs=(*INPUTS, "rpm"))


def test_a_mode_the_record_resolves_poorly_is_said_so_by_name_with_why():
    # Bad input tried: sensor noise as large as each output's own motion. The spiral (0.07 rad/s,
    # below most of the preset's lines) comes out with σ(ωn) above 20 % of ωn, the
    # suggestion's own limit: the result says so by name, with the share of the lateral
    # controls' power near it; the modes the record does resolve are not flagged.
    A, B, C = aircraft_with_engine_lag()
    record = full_preset_record(A, B, C)
    noise = record.y.std(axis=0) * np.random.default_rng(0).standard_normal(record.y.shape)
    result = aircraft_identify(Experiment(record.u, record.y + noise))
    flagged = [w for w in result.warnings if "poorly resolved" in w]
    spread = {m.name: m.uncertainty.frequency / m.frequency for m in result.modes if m.name}
    assert {w.split(" poorly")[0] for w in flagged} == {n for n, v in spread.items() if v > 0.2}
    assert [w.split(" poorly")[0] for w in flagged] == ["spiral"]
    assert re.search(
        r"σ\(ωn\) \d+% of its 0.0\d+ rad/s; the lateral controls put [\d.]+% ", flagged[0]
    )
    assert spread.get("short period", 1.0) < 0.2


def record_at_rest(controls: tuple[str, ...], noise_deg: float = 0.05, seed: int = 0):
    """The full preset on the thesis's aircraft with `controls` left at trim: their columns
    are their position sensors' noise alone (`noise_deg` rms), the outputs' noise 1 % of
    their motion and 10⁻⁴ (SI) where they do not move."""
    A, B, C = aircraft_with_engine_lag()
    timeline = render(preset("full"), 1 / DT)
    u = np.column_stack([timeline.values[c] for c in INPUTS])
    u[:, 0] *= 10.0
    u = np.vstack([np.zeros((100, 4)), u, np.zeros((200, 4))])
    rest = [INPUTS.index(c) for c in controls]
    u[:, rest] = 0.0
    y = simulate(discretize_foh(A, B, C, np.zeros((8, 4)), DT), u)
    rng = np.random.default_rng(seed)
    u[:, rest] += noise_deg * rng.standard_normal((u.shape[0], len(rest)))
    y += (0.01 * y.std(axis=0) + 1e-4) * rng.standard_normal(y.shape)
    return Experiment(u, y), A


def test_an_axis_the_record_did_not_move_is_left_out_and_its_modes_named_missing():
    # Bad input tried: a whole-aircraft record (all four controls' and all eight states'
    # columns) whose lateral controls stayed at trim, their potentiometers' noise alone, as a
    # single-axis manoeuvre leaves them. The lateral modes are not identifiable from it: they
    # are missing by name, with why, and the lateral channels left out; the longitudinal
    # modes come out as from a longitudinal record.
    record, A = record_at_rest(("aileron", "rudder"))
    result = aircraft_identify(record)
    assert result.input_names == ("throttle", "elevator")
    assert result.output_names == OUTPUTS[:4]
    why = dict(result.missing)
    assert set(why) == {"Dutch roll", "roll", "spiral"}
    assert all(
        re.match(
            r"not identifiable from this record: the lateral controls \(aileron, rudder\) "
            r"moved no more than their sensors' noise \(at most [\d.]+×",
            w,
        )
        for w in why.values()
    ), why
    assert any(w.startswith("lateral axis left out") for w in result.warnings)
    named = {m.name: m.eigenvalue for m in result.modes if m.name}
    assert set(named) == {"short period", "phugoid"}
    true = np.linalg.eigvals(A[:4, :4])
    for s in named.values():
        assert np.min(np.abs(true - s) / np.abs(true)) < 0.01
    assert "not identified: roll: not identifiable from this record" in format_text(
        result, 1, len(record.u)
    )


def test_a_control_the_record_did_not_move_is_left_out_by_name_and_its_axis_identified():
    # Bad input tried: the rudder at trim (its sensor's noise) while the aileron played: the
    # rudder is no input of the model (fitted, it would be gains on noise), said so; the
    # lateral modes still come out.
    record, _ = record_at_rest(("rudder",))
    result = aircraft_identify(record)
    assert result.input_names == ("throttle", "elevator", "aileron")
    assert any(
        re.match(r"rudder not moved by this record \(at most [\d.]+× its noise floor", w)
        for w in result.warnings
    ), result.warnings
    assert {m.name for m in result.modes if m.name} >= {"Dutch roll", "roll", "short period"}


def test_a_record_that_moved_no_control_is_refused_clearly():
    # Bad input tried: every control at trim (a record of straight and level flight).
    record, _ = record_at_rest(INPUTS)
    with pytest.raises(DataError, match="no control moved above its sensor's noise"):
        aircraft_identify(record)


def test_the_same_identification_in_one_bin_set_per_record_batches_records():
    A, B, C = aircraft_with_engine_lag()
    one = full_preset_record(A, B, C)
    half = one.u.shape[0] // 2
    # Two records of one flight (a cut anywhere: each has its own transient).
    batch = [Experiment(one.u[:half], one.y[:half]), Experiment(one.u[half:], one.y[half:])]
    result = aircraft_identify(batch)
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
        identify(
            record,
            DT,
            input_names=INPUTS,
            output_names=names,
            output_roles=names,
            settings=Settings(method="aircraft"),
        )


TRIM = {"airspeed": 30.0, "alpha": 0.06, "theta": 0.06}  # the operating point, SI
TRIM_SAMPLES = 50  # the method's trim: the record's first 0.5 s (agent.ident.aircraft.model)
GUSTS = (0, 1, 4)  # the states a gust moves: airspeed, alpha, beta
ATTITUDE = (3, 7)  # θ and φ: kinematics alone
ATTITUDE_ROWS = np.isin(np.arange(8), ATTITUDE)


def gusty_record(
    seed: int,
    tau_q: float = 0.0,
    drag: float = 0.0,
    scale: float = 0.0015,
    roll_ab: float = 0.0,
    tau_r: float = 0.0,
    gust: float = 1.0,
    roll_gust: float = 0.0,
    roll_corner: float = 0.5,
    roll_loop: tuple[float, float] | None = None,
    plan: Plan | None = None,
    curve: float = 0.0,
    climb: float = 0.0,
):
    """The aircraft flown through a gust g (V, α, β; low-passed white noise, 0.03 m/s and
    0.03° rms), the controls at 0.15 % of the full preset (A.2's responses are large): the
    forces see the air-relative state, ẋ_i = A(x_i − g) + B u, the vanes and the
    pitot read x_i − g, and the INS reads the inertial velocity, turned into north, east, down
    by the attitude. Returns the record with its operating point and navigation. With
    `tau_q` (s), the forces also see Dryden's pitch-rate gust q_g = s α_g / (1 + τ s): they
    depend on q − q_g (α̇ = q + … and θ̇ = q keep the inertial q). With `drag` (m/s² per
    rad²), V̇ also loses drag · β² (sideslip drag, β the air-relative sideslip from trim);
    with `tau_r` (s), they see Dryden's yaw-rate gust r_g = s β_g / (1 + τ s), as they see
    q_g (β̇'s kinematic −r and φ̇ keep the inertial r);
    `scale`: the controls' share of the full preset; `gust`: the gust's (0: calm air). With
    `roll_ab` (1/s² per rad²), ṗ also gains roll_ab · α β (the rolling moment's change with
    α, α and β air-relative from trim). With `roll_gust` (rad/s² rms), ṗ also takes a
    rolling gust nothing measures (the gust's gradient along the span: white noise low-passed
    at `roll_corner` rad/s). With `roll_loop` (k_φ, k_p), the ailerons fly a roll loop too,
    as FBWA's does: −k_φ φ − k_p p of the sensed state added to the plan's, so that they
    answer the gusts (the record's aileron is what they did). `plan`: flown in place of the
    full preset. With `curve`, the engine's lags are driven by δ + curve · δ² / max |δ| of the
    throttle's δ (a throttle→thrust curve bent about the trim: a piston engine near full
    throttle gains less than it loses). With `climb` (m/s), the trim climbs (descends, below
    nought) at that rate, θ below α by the flight path's angle, and the lift at the trim
    changes with the air's density along it: α̇ gains −(1/ρ dρ/dh) g cos γ / V per metre
    climbed from the trim's middle (a glider's steady glide).

    A.2's models came from flight data and do not keep θ̇ = q: their θ and φ rows and
    columns are replaced by the kinematics at the operating point, as a real aircraft has
    them (the method fixes those entries)."""
    A, B, C = aircraft_with_engine_lag()
    op = np.array([TRIM.get(name, 0.0) for name in OUTPUTS])
    gamma = np.arcsin(climb / TRIM["airspeed"])
    op[OUTPUTS.index("theta")] += gamma
    J = kinematic_jacobian(op)
    for k in ATTITUDE:
        A[:8, k], A[k, :8], B[k] = J[:, k], J[k], 0.0
    timeline = render(plan or preset("full"), 1 / DT)
    u = np.column_stack([timeline.values.get(c, np.zeros(timeline.count)) for c in INPUTS])
    u[:, 0] *= 10.0
    u = scale * np.vstack([np.zeros((100, 4)), u, np.zeros((200, 4))])
    rng = np.random.default_rng(seed)
    white = rng.normal(size=(u.shape[0], 3))
    g = np.zeros_like(white)
    pole = np.exp(-0.5 * DT)  # Dryden-like: a corner at 0.5 rad/s
    for k in range(1, len(g)):
        g[k] = pole * g[k - 1] + np.sqrt(1 - pole**2) * white[k]
    g *= gust * np.array([0.03, 0.0005, 0.0005])
    rolling = np.zeros(len(g))
    if roll_gust:
        white, corner = rng.normal(size=len(g)), np.exp(-roll_corner * DT)
        for k in range(1, len(g)):
            rolling[k] = corner * rolling[k - 1] + np.sqrt(1 - corner**2) * white[k]
        rolling *= roll_gust
    E = np.zeros((A.shape[0], 4))
    E[:, :3] = -A[:, GUSTS]
    if tau_q > 0:
        q_gust = _rate_gust(g[:, 1], tau_q)
        E[:, 3] = -A[:, 2]
        E[1, 3] += 1.0  # α̇ = q + …: the kinematic part sees the inertial q
        E[3, 3] = 0.0  # θ̇ = q
    else:
        q_gust = np.zeros(len(g))
    E = np.hstack([E, np.zeros((A.shape[0], 1))])
    if tau_r > 0:
        r_gust = _rate_gust(g[:, 2], tau_r)
        E[:, 4] = -A[:, 6]
        E[4, 4] -= 1.0  # β̇ = … − r: the kinematic part sees the inertial r
        E[7, 4] = 0.0  # φ̇ = p + …
    else:
        r_gust = np.zeros(len(g))
    model = discretize_foh(A, np.hstack([B, E]), C, np.zeros((8, 9)), DT)
    # The attitude's kinematics beyond their linear part (what A holds) act too, as they do
    # on a real aircraft (Euler steps: they are second order in the motion). The other rows
    # stay linear: their kinematic nonlinearities share factors with the aerodynamic force's,
    # which this linear aircraft does not have (agent.ident.aircraft's docstring).
    w = np.hstack([u, g, q_gust[:, None], r_gust[:, None]])
    if curve:
        w[:, 0] += curve * u[:, 0] ** 2 / np.max(np.abs(u[:, 0]))
    state = np.zeros(A.shape[0])
    inertial = np.empty((len(u), 8))
    for k in range(len(u)):
        if roll_loop is not None:
            sensed = model.C @ state
            w[k, 2] += -roll_loop[0] * sensed[7] - roll_loop[1] * sensed[5]
            u[k, 2] = w[k, 2]
        inertial[k] = model.C @ state + model.D @ w[k]
        remainder = kinematic_remainder((inertial[k] + op)[None], op)[0] * ATTITUDE_ROWS
        remainder[0] -= drag * (inertial[k, 4] - g[k, 2]) ** 2
        remainder[5] += roll_ab * (inertial[k, 1] - g[k, 1]) * (inertial[k, 4] - g[k, 2])
        remainder[5] += rolling[k]
        height = climb * (k - (TRIM_SAMPLES - 1) / 2) * DT
        remainder[1] += -DENSITY_GRADIENT * GRAVITY * np.cos(gamma) / op[0] * height
        state = model.A @ state + model.B @ w[k] + DT * np.concatenate([remainder, [0, 0]])
    air = inertial.copy()
    air[:, GUSTS] -= g
    x = inertial + op  # absolute, OUTPUTS order: V, α, q, θ, β, p, r, φ
    V, alpha, theta, beta, phi = x[:, 0], x[:, 1], x[:, 3], x[:, 4], x[:, 7]
    body = np.column_stack(
        [V * np.cos(alpha) * np.cos(beta), V * np.sin(beta), V * np.sin(alpha) * np.cos(beta)]
    )
    psi = np.full(len(V), 0.3)
    ned = np.empty_like(body)
    for k in range(len(V)):
        ned[k] = _body_to_ned(phi[k], theta[k], psi[k]) @ body[k]
    return u, air, op, np.column_stack([psi, ned]), A


def _rate_gust(gust: np.ndarray, tau: float) -> np.ndarray:
    """Dryden's rate gust of a gust angle: s g / (1 + τ s) = (g − lowpass(g)) / τ."""
    lowpass = np.zeros(len(gust))
    for k in range(1, len(gust)):
        lowpass[k] = lowpass[k - 1] + DT / tau * (gust[k - 1] - lowpass[k - 1])
    return (gust - lowpass) / tau


def _body_to_ned(phi: float, theta: float, psi: float) -> np.ndarray:
    cf, sf, ct, st, cp, sp = (
        np.cos(phi),
        np.sin(phi),
        np.cos(theta),
        np.sin(theta),
        np.cos(psi),
        np.sin(psi),
    )
    return np.array(
        [
            [ct * cp, sf * st * cp - cf * sp, cf * st * cp + sf * sp],
            [ct * sp, sf * st * sp + cf * cp, cf * st * sp - sf * cp],
            [-st, sf * ct, cf * ct],
        ]
    )


def test_the_measured_wind_turns_the_gust_from_bias_into_excitation():
    # The vanes and the pitot read the gust: without the INS's velocities it is an input the
    # fit does not know, and it biases the modes; with them the wind is measured and the
    # same record gives the aircraft back (measured: worst eigenvalue 0.25 off blind, 0.99 by
    # output error before the filter-error method modelled the unmeasured gust as process
    # noise; 0.0002 with the wind).
    u, air, op, navigation, A = gusty_record(seed=5)
    true = np.linalg.eigvals(A[:8, :8])

    def worst(result):  # relative error; absolute (1/s) for the pole at the origin
        found = np.linalg.eigvals(result.continuous.A[:8, :8])
        return max(np.min(np.abs(found - t)) / max(abs(t), 1.0) for t in true)

    blind = aircraft_identify(Experiment(u, air))
    measured = aircraft_identify(Experiment(u, air, operating_point=op, navigation=navigation))
    report = measured.aircraft
    assert report.wind.measured
    assert report.kinematics
    assert report.wind.gust_rms["airspeed"] == pytest.approx(0.03, rel=0.3)
    assert not blind.aircraft.wind.measured
    assert worst(blind) > 0.1
    assert worst(measured) < 0.01
    # The model's inputs are the controls; the gusts drove the fit only.
    assert measured.continuous.B.shape[1] == len(INPUTS)
    assert any("gust alpha" in axis.inputs for axis in report.axes)


def test_the_time_domain_fit_is_driven_by_the_measured_wind_too():
    """The gusty aircraft (pitch- and yaw-rate gusts too): the result's simulated outputs
    are driven by what the record measured and the model was fitted with, the gusts and
    their rates through their fitted gains and lags, and they are on the recorded channels
    (the vanes' α and β, the pitot's airspeed). Driven by the controls alone, the gusts'
    share of the response is left unexplained (measured: TIC 0.013 with the wind, 0.51
    without)."""
    u, air, op, navigation, _ = gusty_record(seed=5, tau_q=0.4, tau_r=1.5)
    result = aircraft_identify(Experiment(u, air, operating_point=op, navigation=navigation))
    assert result.fit.tic_avg < 0.03
    predicted = result.fit.predictions[0]
    assert np.sqrt(np.mean((predicted - air) ** 2)) < 0.02 * np.sqrt(np.mean(air**2))
    controls_only = simulate(result.discrete, u, result.fit.initial_states[0])
    assert np.mean(theil(controls_only, air)) > 10 * result.fit.tic_avg


def test_the_pitch_rate_gust_is_modelled_from_the_alpha_gusts_rate():
    """The same aircraft, its forces seeing Dryden's pitch-rate gust too (τ = 0.4 s): the
    α gust's rate, through one fitted lag, is a known input of the longitudinal axis, and the
    aircraft comes back (measured: worst eigenvalue 0.3 % off with the rate; without it,
    GUST_RATES emptied, 32 % off and a lateral coupling that is not there)."""
    u, air, op, navigation, A = gusty_record(seed=5, tau_q=0.4)
    true = np.linalg.eigvals(A[:8, :8])
    result = aircraft_identify(Experiment(u, air, operating_point=op, navigation=navigation))
    found = np.linalg.eigvals(result.continuous.A[:8, :8])
    worst = max(np.min(np.abs(found - t)) / max(abs(t), 1.0) for t in true)
    longitudinal = next(a for a in result.aircraft.axes if a.name == "longitudinal")
    assert "gust alpha rate" in longitudinal.inputs
    assert worst < 0.01
    assert result.continuous.A.shape == (10, 10)  # the gust rate's lag is no state of the model


def test_the_yaw_rate_gust_is_modelled_from_the_beta_gusts_rate():
    """The same aircraft, its forces seeing Dryden's yaw-rate gust (τ = 1.5 s, a glider's
    span against its speed): the β gust's rate, through one fitted lag, is a known input of
    the lateral axis, and the lateral modes come back (measured: worst eigenvalue 0.65 % off);
    without it (GUST_RATES without β) the yaw-rate gust, correlated with the measured β gust,
    biases them (11.6 %)."""
    u, air, op, navigation, A = gusty_record(seed=5, tau_r=1.5)
    true = np.linalg.eigvals(A[4:8, 4:8])
    record = Experiment(u, air, operating_point=op, navigation=navigation)

    def worst(result):
        found = np.linalg.eigvals(result.continuous.A[4:8, 4:8])
        return max(np.min(np.abs(found - t)) / max(abs(t), 1.0) for t in true)

    result = aircraft_identify(record)
    lateral = next(a for a in result.aircraft.axes if a.name == "lateral")
    assert "gust beta rate" in lateral.inputs
    assert worst(result) < 0.01
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr("agent.ident.aircraft.prepare.GUST_RATES", ("alpha",))
        without = aircraft_identify(record)
    assert worst(without) > 0.05


def test_sideslip_drag_is_a_known_input_of_the_airspeeds_equation():
    """The aircraft's V̇ loses 10 m/s² per rad² of β² (sideslip drag), the lateral controls at
    100 times the longitudinal share (β to 3°): the β² input of V̇'s equation gives the gain
    back and the modes with it (measured: worst eigenvalue 0.08 % off with the term, 0.87 %
    without it). Without drag the gain is nought within its standard error."""
    scale = np.array([0.0015, 0.0015, 0.15, 0.15])

    def worst(drag: float, **options):
        u, air, op, navigation, A = gusty_record(seed=5, drag=drag, scale=scale)
        record = Experiment(u, air, operating_point=op, navigation=navigation)
        result = aircraft_identify(record, **options)
        found = np.linalg.eigvals(result.continuous.A[:8, :8])
        true = np.linalg.eigvals(A[:8, :8])
        error = max(np.min(np.abs(found - t)) / max(abs(t), 1.0) for t in true)
        return error, result.aircraft

    error, report = worst(10.0)
    assert error < 0.002
    assert report.sideslip_drag.gain == pytest.approx(-10.0, rel=0.02)
    longitudinal, lateral = report.axes
    assert "beta²" in longitudinal.inputs
    assert "beta²" not in lateral.inputs
    _, still = worst(0.0)
    assert abs(still.sideslip_drag.gain) < 3 * still.sideslip_drag.std
    blind, report = worst(10.0, sideslip_drag=False)
    assert report.sideslip_drag is None
    assert blind > 4 * error


def classic_card() -> Plan:
    """A 3-2-1-1 on the elevator, a throttle doublet of 5 s steps, then elevator, aileron and
    rudder doublets, each followed by free flight (plan units: degrees, throttle percent)."""
    segments = [
        Segment(signals={"elevator": ThreeTwoOneOne(pulse_s=0.5, amplitude=3.0)}, free_s=4.0),
        Segment(signals={"throttle": Doublet(pulse_s=5.0, amplitude=10.0)}, free_s=15.0),
    ]
    for control in ("elevator", "aileron", "rudder"):
        segments.append(Segment(signals={control: Doublet(pulse_s=1.0, amplitude=4.0)}, free_s=6.0))
    return Plan(id="card", axes="full", segments=tuple(segments))


def _card_phugoid(curve: float, gust: float = 0.0, **options):
    """A linear aircraft flown through the classic card (its throttle's thrust bent by
    `curve`, in `gust`) and identified: the phugoid's error and the aircraft report."""
    u, air, op, navigation, A = gusty_record(
        seed=5, gust=gust, scale=0.03, plan=classic_card(), curve=curve
    )
    record = Experiment(u, air, operating_point=op, navigation=navigation)
    result = aircraft_identify(record, **options)
    true = np.linalg.eigvals(A[:4, :4])  # the longitudinal axis (A.2 holds no coupling)
    phugoid = min((t for t in true if t.imag > 0), key=abs)
    found = np.linalg.eigvals(result.continuous.A[:8, :8])
    return np.min(np.abs(found - phugoid)) / abs(phugoid), result.aircraft


def test_the_throttles_curvature_is_a_known_input_of_the_longitudinal_axis():
    """Bad input tried: a throttle whose thrust bends about the trim (+0.7 of its linear
    gain at the doublet's top, -1.3 at its bottom: JSBSim's Cessna 310 near full throttle
    gained 93 lb and lost 172 lb at +-10 %), flown in 5 s steps: on a linear model the bend
    biased the phugoid (benchmarks/README.md, the C310's card). The throttle's square about
    the trim, a known input of V̇, takes it."""
    error, report = _card_phugoid(-0.3)
    blind, blind_report = _card_phugoid(-0.3, throttle_curve=False)
    gain = report.throttle_curve["throttle²"]["airspeed"]
    assert set(report.throttle_curve["throttle²"]) == {"airspeed"}  # V̇ alone
    # V̇'s other one-equation input, sideslip drag (none on this aircraft), is its own, and
    # its standard error says the record cannot tell it (a record without sideslip, fitted
    # by the filter error: its whitened normal equations' condition 4e15, whose
    # pseudo-inverse had the drag at 0.68 ± 4e-7).
    drag = report.sideslip_drag
    assert drag.gain != gain.gain
    assert abs(drag.gain) < 3 * drag.std
    assert gain.gain < 0
    assert abs(gain.gain) > 3 * gain.std
    longitudinal, lateral = report.axes
    assert "throttle²" in longitudinal.inputs
    assert "throttle²" not in lateral.inputs
    assert blind_report.throttle_curve == {}
    # Measured: 0.20 % off with the square (a gain on V̇ alone, where this aircraft's bend
    # drives the engine's lags and through them α̇ and q̇ too), 1.1 % without.
    assert error < 0.004
    assert blind > 3 * error
    # Bad input tried: the throttle recorded as its absolute setting (0.7 of full at the
    # trim), not as a deviation: its square is still taken about the trim, the same gain.
    u, air, op, navigation, _ = gusty_record(
        seed=5, scale=0.03, plan=classic_card(), curve=-0.3, gust=0.0
    )
    u[:, 0] += 0.7
    absolute = aircraft_identify(Experiment(u, air, operating_point=op, navigation=navigation))
    same = absolute.aircraft.throttle_curve["throttle²"]["airspeed"]
    # The same to the fit's arithmetic (2e-6 of it apart, 2e-5 of its standard error); about
    # absolute nought instead, the square would hold 1.4 times the throttle's deviation.
    assert same.gain == pytest.approx(gain.gain, rel=1e-5)


def _glide_phugoid(climb: float, **options) -> tuple[float, Identification]:
    """The phugoid's error of the linear aircraft flown at `climb` (m/s) through the classic
    card, and the identification."""
    u, air, op, navigation, A = gusty_record(
        seed=5, gust=0.0, scale=0.03, plan=classic_card(), climb=climb
    )
    result = aircraft_identify(
        Experiment(u, air, operating_point=op, navigation=navigation), **options
    )
    true = np.linalg.eigvals(A[:4, :4])
    phugoid = min((t for t in true if t.imag > 0), key=abs)
    found = np.linalg.eigvals(result.continuous.A[:8, :8])
    return float(np.min(np.abs(found - phugoid)) / abs(phugoid)), result


def test_a_descending_trims_density_is_a_known_forcing_of_the_angle_of_attack():
    """Bad input tried: a trim that is no equilibrium of the air, a glide at 1.2 m/s down
        (the SGS 1-26's at 50 kt): over the card's two minutes it sinks into denser air and its
        lift at the trim's α grows, a slow drift in the lowest bins, the phugoid's. The INS's
        climb rate over the trim gives that drift, a known forcing with no free gain; without it
        the phugoid comes out several per cent off (JSBSim's glider: 11.5 and 13.1 % on two calm
        seeds of ten, benchmarks/README.md). In level flight the forcing is nought: nothing
        changes: a trim that climbs or descends through less than LEVEL_M over the record is level
    (the J-3 Cub's in light turbulence, ±0.05 m/s of v_D over its trim's half second)."""
    error, forced = _glide_phugoid(-1.2)
    blind, _ = _glide_phugoid(-1.2, density=False)
    # The result says which climb it forced: the INS's over the trim.
    (climb,) = forced.aircraft.density_climb_mps
    assert climb == pytest.approx(-1.2, abs=0.01)
    # Measured: 0.014 % with the forcing, 0.27 % without (this record's phugoid is well
    # determined; the drift's share grows with the record's length and the sink rate).
    assert error < 0.0005
    assert blind > 5 * error
    level, with_term = _glide_phugoid(0.0)
    same, without_term = _glide_phugoid(0.0, density=False)
    assert with_term.aircraft.density_climb_mps == []
    assert level == same
    np.testing.assert_array_equal(with_term.continuous.A, without_term.continuous.A)


def test_a_straight_throttle_has_no_curvature_and_turbulence_leaves_it_out():
    """Without the bend the square's gain is nought within its standard error; in measured
    turbulence the square is no input (its slow content is the gusts' band)."""
    _, straight = _card_phugoid(0.0)
    still = straight.throttle_curve["throttle²"]["airspeed"]
    assert abs(still.gain) < 3 * still.std
    _, gusty = _card_phugoid(-0.3, gust=1.0)
    assert gusty.throttle_curve == {}
    assert "throttle²" not in gusty.axes[0].inputs


def test_the_rolling_moments_change_with_alpha_is_a_known_input_of_the_lateral_axis():
    """ṗ gains −50 α β (C_lβ changing with α, as JSBSim's Cub tabulates it), every control at
    3 % of the full preset (α and β to about 1°): the α·β input of the lateral axis gives the
    gain back (measured: −50.8 ± 0.5); without the term every product's gain is nought within
    three standard errors. The longitudinal axis has no such input, and with the longitudinal
    controls left out (α barely moves) neither has the lateral one."""
    scale = np.full(4, 0.03)

    def identified(roll_ab: float, inputs=INPUTS):
        u, air, op, navigation, _ = gusty_record(seed=5, scale=scale, roll_ab=roll_ab)
        columns = [INPUTS.index(name) for name in inputs]
        record = Experiment(u[:, columns], air, operating_point=op, navigation=navigation)
        return aircraft_identify(record, inputs).aircraft

    report = identified(-50.0)
    products = report.alpha_products
    assert set(products) == {"alpha·beta", "alpha·p", "alpha·r"}
    assert set(products["alpha·beta"]) == {"beta", "p", "r"}  # φ̇ is kinematics
    assert products["alpha·beta"]["p"].gain == pytest.approx(-50.0, rel=0.04)
    longitudinal, lateral = report.axes
    assert "alpha·beta" in lateral.inputs
    assert not any(name.startswith("alpha·") for name in longitudinal.inputs)
    still = identified(0.0).alpha_products
    for rows in still.values():
        for gain in rows.values():
            assert abs(gain.gain) < 3 * gain.std
    alone = identified(-50.0, ("aileron", "rudder"))
    assert [axis.name for axis in alone.axes] == ["lateral"]
    assert alone.alpha_products == {}
    assert not any(name.startswith("alpha·") for name in alone.axes[0].inputs)


def test_the_alpha_products_are_of_the_air_relative_states_about_their_mean():
    """The α·β, α·p, α·r inputs are built from what the vanes read (α and β air-relative,
    the moments' arguments) less their mean over the record. About the trim (the record's
    first half second, which in turbulence carries that moment's gust) a constant part of α
    times p would be p itself, and the roll damping would trade against the product's gain.
    The record: the gusty aircraft, whose inertial and air-relative states differ by the
    gust."""
    u, air, op, navigation, _ = gusty_record(seed=5, scale=0.03)
    record = Experiment(u, air, operating_point=op, navigation=navigation)
    ready = prepare([record], OUTPUTS, trim_samples=50, dt=DT)
    names = [ready.extra_names[j - u.shape[1]] for j in ready.bilinear]
    assert names == ["alpha·beta", "alpha·p", "alpha·r"]
    deviation = air - air.mean(axis=0)
    alpha = deviation[:, OUTPUTS.index("alpha")]
    columns = ready.batch[0].u[:, list(ready.bilinear)]
    for k, role in enumerate(("beta", "p", "r")):
        expected = alpha * deviation[:, OUTPUTS.index(role)]
        np.testing.assert_allclose(columns[:, k], expected, rtol=1e-9, atol=1e-15)
    # The inertial α (what the model's states are) is not the moments' argument here.
    inertial = ready.batch[0].y[:, OUTPUTS.index("alpha")]
    assert np.ptp(inertial - air[:, OUTPUTS.index("alpha")]) > 0


def test_a_dead_alpha_vane_is_a_clear_failure_naming_it():
    """Bad input tried: the α vane dead, its channel sensor noise alone (10⁻⁷ rad), no INS.
    Its noise is no response, and the other equations fitted it with gains of 10¹⁰ and a pole
    of 9·10⁶ 1/s, whose sampling overflowed: an "array must not contain infs or NaNs" from
    deep in the modal analysis. Now a failure that names α, and through the worker's job (what
    the agent runs) a failed outcome with that reason, so the ground is told and flying goes
    on."""
    from agent.ident.job import Job, run

    u, air, op, _, _ = gusty_record(seed=5, scale=np.full(4, 0.03))
    air[:, 1] = 1e-7 * np.random.default_rng(1).normal(size=len(air))
    with pytest.raises(IdentificationFailed, match="on alpha: an output with no response"):
        aircraft_identify(Experiment(u, air, operating_point=op))
    job = Job(
        model_id="ful-1",
        axes="full",
        record_dt=DT,
        inputs=INPUTS,
        outputs=OUTPUTS,
        roles=OUTPUTS,
        experiments=((u, air),),
        settings=Settings(held_inputs=False),
        contexts=((op, None),),
        input_roles=INPUTS,
    )
    outcome = run(job)
    assert not outcome.ok
    assert "check alpha's signal" in outcome.reason


def test_navigation_of_the_wrong_shape_is_refused_clearly():
    # Bad input tried: navigation with a row missing, and an operating point one value short.
    u, air, op, navigation, _ = gusty_record(seed=1)
    with pytest.raises(DataError, match="navigation needs"):
        identify(
            Experiment(u, air, operating_point=op, navigation=navigation[1:]),
            DT,
            input_names=INPUTS,
            output_names=OUTPUTS,
            output_roles=OUTPUTS,
        )
    with pytest.raises(DataError, match="operating point needs 8"):
        identify(
            Experiment(u, air, operating_point=op[:7]),
            DT,
            input_names=INPUTS,
            output_names=OUTPUTS,
            output_roles=OUTPUTS,
        )


def test_a_propellers_gyroscopic_coupling_is_found_as_a_coupling_block_of_a():
    # q̇ = … − 0.5 r (JSBSim's Cub has −0.52): the lateral states join the longitudinal axis
    # as inputs, their gains fill A's block, and the coupled aircraft's modes come back.
    A, B, C = aircraft_with_engine_lag()
    A[2, 6] = -0.5
    record = full_preset_record(A, B, C)
    result = aircraft_identify(record)
    report = result.aircraft
    assert "longitudinal" in report.model
    assert "coupled" in report.model
    assert report.coupling["longitudinal"].response_by_states > COUPLED
    assert result.continuous.A[2, 6] == pytest.approx(-0.5, rel=0.02)
    found = np.sort_complex(np.linalg.eigvals(result.continuous.A[:8, :8]))
    true = np.sort_complex(np.linalg.eigvals(A[:8, :8]))
    assert np.max(np.abs(found - true) / np.abs(true)) < 5e-3


def test_the_throttle_and_the_longitudinal_states_join_the_lateral_axis_each_on_its_own_test():
    """The propeller's torque (the thrust state → roll and yaw) couples the throttle into the
    lateral axis; the longitudinal states explain part of it too (at the throttle's lines they
    are its response). Each joins on its own test: the throttle (through the engine's lags, as
    it reaches the longitudinal axis; without them the modes were 19 % off) and the states,
    but not the elevator, which has no path to the lateral forces but through the states. The
    aircraft's modes come back (measured: 0.13 % off at worst; with the controls alone, the
    former rule, 0.24 %)."""
    A, B, C = aircraft_with_engine_lag()
    A[5:7, 9] = [0.04, -0.02]  # thrust state → ṗ, ṙ
    record = full_preset_record(A, B, C)
    result = aircraft_identify(record)
    report = result.aircraft
    coupling = report.coupling["lateral"]
    assert coupling.response_by_inputs > COUPLED
    assert coupling.response_by_states > COUPLED  # both qualify, both join
    lateral = next(a for a in report.axes if a.name == "lateral")
    assert "throttle" in lateral.inputs
    assert "elevator" not in lateral.inputs
    assert all(name in lateral.inputs for name in ("airspeed", "alpha", "q"))
    assert "lateral coupled by the throttle and the other axis's states" in report.model
    assert "throttle" in report.engine_lag_s["lateral"]
    found = np.sort_complex(np.linalg.eigvals(result.continuous.A[:8, :8]))
    true = np.sort_complex(np.linalg.eigvals(A[:8, :8]))
    assert np.max(np.abs(found - true) / np.abs(true)) < 3e-3


def _transforms(U: np.ndarray, record: np.ndarray, Y: np.ndarray | None = None) -> Transforms:
    counts = [int(np.sum(record == e)) for e in np.unique(record)]
    s = 2j * np.pi * np.concatenate([np.arange(1, c + 1) / 10.0 for c in counts])
    Y = np.zeros((s.size, 1), dtype=complex) if Y is None else Y
    return Transforms(s=s, Y=Y, U=U.astype(complex), record=record, band_hz=(0.1, 1.0))


def test_excited_keeps_each_records_bins_where_a_chosen_control_has_power():
    """Per record and per control, a bin counts when that control puts EXCITED_LEVEL of its
    own largest bin's power there: a weak control's lines count as fully as a strong one's,
    a line below the level does not, and the other controls' lines are left out."""
    record = np.repeat([0, 1], 12)
    U = np.zeros((24, 3))
    U[[2, 8], 0] = [1.0, 0.2]  # control 0: its second line at 4 % of its power
    U[5, 1], U[7, 1] = 1e-3, 0.5e-4  # control 1: weak, and a line at 0.25 % of its power
    U[3, 2] = 5.0  # control 2: not chosen
    U[12 + 4, 0] = 0.01  # record 1: control 0's only line, far below record 0's
    U[12 + 6, 1] = 2.0
    kept = excited(_transforms(U, record), [0, 1])
    harmonics = np.round(kept.s.imag / (2 * np.pi) * 10).astype(int)
    assert list(zip(kept.record.tolist(), harmonics.tolist(), strict=True)) == [
        (0, 3),
        (0, 6),
        (0, 9),
        (1, 5),
        (1, 7),
    ]
    assert kept.Y.shape == (5, 1)
    assert kept.U.shape == (5, 3)


def test_each_bins_weight_follows_its_neighbourhoods_residual_level():
    """bin_sigma: the residual's rms over the SMOOTH_BINS nearest bins, so a band 10 times
    noisier gets a σ 3 times larger (a single σ per output would weight both alike); a band
    fitted exactly is held at SMOOTH_FLOOR of the output's rms, not at zero. (The floor also
    caps the contrast: a band 10 times quieter than the rest would sit on it.)"""
    rng = np.random.default_rng(3)
    F = 400
    s = 2j * np.pi * np.arange(1, F + 1) / 80.0
    level = np.where(np.arange(F) < F // 2, 3.0, 1.0)
    noise = level * (rng.standard_normal(F) + 1j * rng.standard_normal(F)) / np.sqrt(2)
    exact = np.where(np.arange(F) < F // 2, noise, 0.0)
    sigma = bin_sigma(np.column_stack([noise, exact]), s)
    margin = 4 * SMOOTH_BINS  # away from the step between the bands
    deep = slice(margin, F // 2 - margin), slice(F // 2 + margin, F - margin)
    ratio = np.median(sigma[deep[0], 0]) / np.median(sigma[deep[1], 0])
    assert 2.5 < ratio < 3.5
    rms = np.sqrt(np.mean(np.abs(exact) ** 2))
    assert np.allclose(sigma[deep[1], 1], SMOOTH_FLOOR * rms)
    assert np.all(sigma[deep[0], 1] > 2 * SMOOTH_FLOOR * rms)


def test_a_noisy_regressors_conditional_mean_gives_its_gain_unbiased():
    """conditional_mean on a Dryden-like gust (a first-order low-pass at 1 rad/s) read with white
    noise as strong as the gust: a response 2 × gust regressed on the raw reading gives a gain
    near 1 (errors in variables); on conditional_mean's, 2. Of pure noise (calm air) about 3 % of
    the power is left (the smoothed periodogram's own scatter above the floor)."""
    rng = np.random.default_rng(11)
    n = 8000
    white = rng.standard_normal(n)
    gust = np.zeros(n)
    pole = np.exp(-1.0 * DT)
    for k in range(1, n):
        gust[k] = pole * gust[k - 1] + np.sqrt(1 - pole**2) * white[k]
    raw = gust + rng.standard_normal(n)
    response = 2.0 * gust

    def gain(regressor):
        r = regressor - regressor.mean()
        return float(r @ (response - response.mean()) / (r @ r))

    assert gain(raw) < 1.2
    assert gain(conditional_mean(raw)) == pytest.approx(2.0, rel=0.05)
    assert np.std(conditional_mean(raw) - gust) < 0.4 * np.std(raw - gust)
    calm = rng.standard_normal(n)
    assert np.std(conditional_mean(calm)) < 0.2


def test_a_gust_is_detected_where_it_stands_above_its_sensors_noise_and_white_noise_is_not():
    """`detected` on white noise alone (calm air read by noisy sensors) passes at about its
    false-alarm rate; on a Dryden-like gust (a low-pass at 1 rad/s) 0.3 of the noise's rms,
    read with that noise, it passes every time (its power sits in the few low bins)."""
    rng = np.random.default_rng(3)
    n, records = 6000, 300
    alarms = sum(detected(rng.standard_normal(n)) for _ in range(records))
    assert alarms <= 3  # expected 0.3 at FALSE_ALARM
    assert FALSE_ALARM * records < 1
    pole = np.exp(-1.0 * DT)
    for _ in range(20):
        white = rng.standard_normal(n)
        gust = np.zeros(n)
        for k in range(1, n):
            gust[k] = pole * gust[k - 1] + np.sqrt(1 - pole**2) * white[k]
        assert detected(0.3 * gust + rng.standard_normal(n))
    assert not detected(np.zeros(n))


def test_each_mode_takes_its_axis_by_continuity_from_the_axes_own_models():
    """_mode_axes: with the coupling blocks zeroed, each axis's eigenvalues are its own; the
    coupled model's are matched to them one to one, so a roll pole and a short-period pole
    0.5 1/s apart and coupled strongly enough to mix their eigenvectors each keep their axis."""
    lon = np.array([[-0.02, 0.3, 0, -9.8], [-0.3, -5.4, 1, 0], [0, 0, -11.6, 0], [0, 0, 1, 0]])
    lat = np.array([[-0.6, 0, -1, 0.05], [-2.0, -12.1, 0.5, 0], [4, -0.2, -0.7, 0], [0, 1, 0, 0]])
    A = np.zeros((8, 8))
    A[:4, :4], A[4:, 4:] = lon, lat
    A[2, 5], A[5, 2] = 0.4, 0.4  # q ↔ p: the roll and the short period's −11.6 mix
    fits = [
        types.SimpleNamespace(name="longitudinal", states=(0, 1, 2, 3)),
        types.SimpleNamespace(name="lateral", states=(4, 5, 6, 7)),
    ]
    poles = [p for p in np.linalg.eigvals(A) if p.imag >= 0]
    modes = [types.SimpleNamespace(eigenvalue=p) for p in poles]
    axes = _mode_axes(modes, A, fits)
    for p, axis in zip(poles, axes, strict=True):
        own = np.linalg.eigvals(lon if axis == "lon" else lat)
        assert np.min(np.abs(own - p)) < 0.3
    roll = int(np.argmin([abs(p + 12.1) for p in poles]))
    assert axes[roll] == "lat"
    assert axes.count("lat") == sum(1 for p in np.linalg.eigvals(lat) if p.imag >= 0)
    assert _mode_axes(modes, A, fits[:1]) == [None] * len(modes)


def test_excited_leaves_out_bins_where_a_control_is_its_noise():
    """A bin counts only where the control stands SIGNAL_MARGIN times above its white noise
    floor: a line at 2 % of the largest (above EXCITED_LEVEL) but 5 times the floor is left
    out, one at 20 times is kept."""
    record = np.zeros(12, dtype=int)
    U = np.zeros((12, 1))
    U[[2, 5, 8], 0] = [1.0, np.sqrt(0.02), np.sqrt(0.02)]
    sp = _transforms(U, record)
    floors = np.full((12, 1), 0.02 / 5)
    floors[8] = 0.02 / 20
    kept = excited(dataclasses.replace(sp, noise=floors), [0])
    harmonics = np.round(kept.s.imag / (2 * np.pi) * 10).astype(int)
    assert harmonics.tolist() == [3, 9]
    assert kept.noise.shape == (2, 1)


def card_record(noise: float, seed: int = 0):
    """The thesis's aircraft flown through a classic card: a 3-2-1-1 on each control in turn
    (throttle 2 s a step, surfaces 0.5 s), each a few seconds of a 70 s record; the surfaces'
    positions measured with white noise of `noise` × their amplitude per sample, the outputs'
    1 % of their motion."""
    A, B, C = aircraft_with_engine_lag()
    steps = np.array([1, 1, 1, -1, -1, 1, -1], dtype=float)
    u = np.zeros((int(70 / DT), 4))
    amplitudes = np.array([20.0, 2.0, 2.0, 2.0])
    for j, (start, unit) in enumerate([(5, 2.0), (15, 0.5), (30, 0.5), (45, 0.5)]):
        pulse = np.repeat(steps * amplitudes[j], round(unit / DT))
        u[round(start / DT) : round(start / DT) + pulse.size, j] = pulse
    y = simulate(discretize_foh(A, B, C, np.zeros((8, 4)), DT), u)
    rng = np.random.default_rng(seed)
    measured = u + noise * amplitudes * rng.standard_normal(u.shape)
    return Experiment(measured, y + (0.01 * y.std(axis=0) + 1e-4) * rng.standard_normal(y.shape)), A


def test_a_short_manoeuvre_in_a_long_noisy_record_is_fitted_where_its_inputs_are_known():
    # Bad input tried: surface positions with white noise of a tenth of the pulses' amplitude
    # per sample (the T-6's aileron potentiometer against its sized card). A 3-2-1-1 of 3.5 s
    # in 70 s stands above that noise only below a few hertz; bins of noise at 1 % of the
    # largest bin's power, once counted as excited, took the band to the quarter sample rate
    # and put noise in the regressors (errors in variables): on three seeds the short
    # period's ωn came out 3.5 % low and its ζ 3–7 % low, the Dutch roll's ωn 2.5–3.6 % low,
    # every time. Judged against the noise floor, the band ends where the pulses do, the
    # measured inputs are their conditional means, and the errors scatter about zero.
    errors = {"short period ωn": [], "short period ζ": [], "Dutch roll ωn": []}
    for seed in range(3):
        record, A = card_record(noise=0.1, seed=seed)
        result = aircraft_identify(record)
        assert result.preprocessing.band_hz < 0.6 * 0.25 / DT  # the cap, where it was
        true = np.linalg.eigvals(A[:8, :8])
        for mode in result.modes:
            if mode.name in ("short period", "Dutch roll"):
                t = true[np.argmin(np.abs(true - mode.eigenvalue))]
                errors[f"{mode.name} ωn"].append(mode.frequency / abs(t) - 1)
                if mode.name == "short period":
                    errors["short period ζ"].append(mode.damping / (-t.real / abs(t)) - 1)
    for what, values in errors.items():
        assert len(values) == 3, what
        assert abs(np.mean(values)) < 0.015, what


def test_a_steady_wind_is_not_a_gust():
    # Real flights have a steady wind: the INS's velocity is the air's plus the wind, whose
    # body-axis projection changes as the attitude does. Taken as a gust it followed the
    # manoeuvre (measured: worst eigenvalue 0.19 off with 5.8 m/s of wind); the record's mean
    # wind is subtracted first. (A wind that changes is a gust: the aircraft is accelerated
    # by it, and the vanes measure it as one.)
    u, air, op, navigation, A = gusty_record(seed=5)
    true = np.linalg.eigvals(A[:8, :8])
    windy = navigation.copy()
    windy[:, 1] += 5.0
    windy[:, 2] -= 3.0
    result = aircraft_identify(Experiment(u, air, operating_point=op, navigation=windy))
    found = np.linalg.eigvals(result.continuous.A[:8, :8])
    worst = max(np.min(np.abs(found - t)) / max(abs(t), 1.0) for t in true)
    assert result.aircraft.wind.measured
    assert worst < 0.01


def test_bin_averages_hold_small_values_beside_huge_ones():
    # Bad input tried: a spectrum spanning twenty-five decades (a noise-free record's
    # filter-error information, 1e28 beside 1e-3). A running sum's rounding made the small
    # bins' means negative (-7e11 in place of ~0), and the process noise's solve overflowed.
    rng = np.random.default_rng(3)
    F = 200
    s = 1j * np.linspace(0.1, 60.0, F)
    values = rng.uniform(0.5, 1.5, (F, 2)) * 1e-3
    values[:20, 0] = 1e28  # the low bins huge in one column only
    smooth, width = smooth_bins(values, s)
    assert width == 2 * SMOOTH_BINS + 1
    assert np.all(smooth >= 0)
    far = slice(20 + SMOOTH_BINS, F - SMOOTH_BINS)  # whole windows holding no huge value
    expected = np.array(
        [values[max(0, k - SMOOTH_BINS) : k + SMOOTH_BINS + 1].mean(axis=0) for k in range(F)]
    )
    assert np.allclose(smooth[far], expected[far], rtol=1e-12, atol=0)


def test_calm_air_measured_without_noise_has_no_gust_to_fit():
    # Bad input tried: the INS and the air data agreeing to rounding (calm air, no sensor
    # noise: a simulation). The gusts are then zero but for rounding; given free gains, those
    # grew without bound and the time-domain prediction overflowed (TIC 1.000 on every output
    # of JSBSim's Cessna 182). A gust that small is left out, and the fit is the calm one.
    u, air, op, navigation, A = gusty_record(seed=5, gust=0.0)
    true = np.linalg.eigvals(A[:8, :8])
    result = aircraft_identify(Experiment(u, air, operating_point=op, navigation=navigation))
    found = np.linalg.eigvals(result.continuous.A[:8, :8])
    worst = max(np.min(np.abs(found - t)) / max(abs(t), 1.0) for t in true)
    assert worst < 0.01
    assert result.aircraft.wind.gust_rms == {}
    assert not any("gust" in name for axis in result.aircraft.axes for name in axis.inputs)
    assert np.all(np.isfinite(result.fit.tic))
    assert result.fit.tic_avg < 0.1


def test_calm_air_read_with_sensor_noise_has_no_gust_and_keeps_the_inertial_outputs():
    # Bad input tried: calm air read by noisy sensors (the vanes, the pitot, the INS's
    # velocities and heading at 5 % of the calm manoeuvre's own motion). The "gust" is then
    # the sensors' noise: given free gains on every row, it fitted the phugoid's few bins
    # (JSBSim's Cessna 182, calm air: its phugoid damping 16–20 % high on every seed of ten,
    # within 3 % without; benchmarks/README.md). It is left out and said so, the outputs stay
    # the inertial ones (less noisy than the vanes), and the modes are right. In a gust read
    # by the same sensors the gusts are measured as before.
    u, air, op, navigation, A = gusty_record(seed=5, gust=0.0)
    air_noise = 0.05 * air.std(axis=0)
    nav_noise = np.array([1e-4, *(0.05 * navigation[:, 1:].std(axis=0))])
    true = np.linalg.eigvals(A[:8, :8])
    for gust in (0.0, 1.0):
        u, air, op, navigation, A = gusty_record(seed=5, gust=gust)
        rng = np.random.default_rng(5)
        noisy = air + rng.normal(size=air.shape) * air_noise
        read = navigation + rng.normal(size=navigation.shape) * nav_noise
        result = aircraft_identify(Experiment(u, noisy, operating_point=op, navigation=read))
        found = np.linalg.eigvals(result.continuous.A[:8, :8])
        worst = max(np.min(np.abs(found - t)) / max(abs(t), 1.0) for t in true)
        wind = result.aircraft.wind
        inputs = [name for axis in result.aircraft.axes for name in axis.inputs]
        if gust:
            assert wind.undetected == []
            assert set(wind.gust_rms) == {"airspeed", "alpha", "beta"}
            assert "gust alpha" in inputs
            assert "gust beta" in inputs
            assert worst < 0.05
            continue
        assert wind.undetected == ["airspeed", "alpha", "beta"]
        assert wind.gust_rms == {}
        assert not wind.measured
        assert not any("gust" in name for name in inputs)
        assert worst < 0.02
        assert "airspeed, alpha, beta gust within the sensors' noise (left out)" in format_text(
            result, 1, len(u)
        )
        # the inertial outputs: the time-domain fit is judged against them, not the vanes
        assert result.fit.tic_avg < 0.2


def test_without_vanes_alpha_and_beta_are_synthesised_and_only_the_airspeeds_gust_measured():
    # An aircraft whose air data measures the airspeed only, in a steady wind: α and β from
    # the INS less the estimated wind (agent.ident.aircraft.airangles). The gust's α and β
    # are then unmeasured process noise (0.03° here against the manoeuvre's 0.1°): the modes
    # within a few per cent (measured 1.5 % and 2.5 % on seeds 5 and 6, where the vanes with
    # the INS give 0.1 %), and the result says how α and β were had.
    u, air, op, navigation, A = gusty_record(seed=5, scale=0.015)
    true = np.linalg.eigvals(A[:8, :8])
    windy = navigation.copy()
    windy[:, 1] += 5.0
    windy[:, 2] -= 3.0
    x = air + op
    made = synthesise(x[:, 0], x[:, 3], x[:, 7], windy)
    assert made.wind == pytest.approx((5.0, -3.0), abs=0.3)
    vaneless = air.copy()
    vaneless[:, 1], vaneless[:, 4] = made.alpha - op[1], made.beta - op[4]
    record = Experiment(u, vaneless, operating_point=op, navigation=windy, air_angles=made)
    result = aircraft_identify(record)
    found = np.linalg.eigvals(result.continuous.A[:8, :8])
    worst = max(np.min(np.abs(found - t)) / max(abs(t), 1.0) for t in true)
    assert worst < 0.04
    wind = result.aircraft.wind
    assert wind.air_angles == "synthesised"
    assert len(wind.synthesised) == 1
    assert set(wind.gust_rms) == {"airspeed"}
    assert wind.synthesised[0].wind_mps == pytest.approx((5.0, -3.0), abs=0.3)
    assert not any("gust alpha" in axis.inputs for axis in result.aircraft.axes)
    # Told it was flown closed loop, it is still not refined by prediction error: the
    # synthesised β's gust is one the output does not see, which its noise states do not
    # model (agent.ident.aircraft.model; refined, the worst mode went 26 % off).
    closed = aircraft_identify(record, closed_loop=True)
    assert {a.name: a.estimator for a in closed.aircraft.axes}["lateral"] == "output error"
    assert "alpha, beta synthesised without vanes" in format_text(result, 1, len(u))


def _longitudinal_error(result, A) -> float:
    """The worst longitudinal eigenvalue's error: relative, absolute below 1 1/s."""
    found = np.linalg.eigvals(result.continuous.A[:4, :4])
    return max(np.min(np.abs(found - t)) / max(abs(t), 1.0) for t in np.linalg.eigvals(A[:4, :4]))


def test_an_unmeasured_gust_is_process_noise_and_the_filter_error_method_fits_it():
    # The vanes and the pitot read the gust and nothing measures it (no INS): its rate drives
    # the air-relative V and α as process noise. The residual shows it (the likelihood ratio
    # against white noise alone), so the longitudinal axis takes the filter-error method and
    # says so; against output error on the same records its longitudinal modes are nearer
    # (measured worst eigenvalue 0.23 / 0.24 / 0.33 off against 0.42 / 1.90 / 0.33 on seeds
    # 5–7; the gust, at 0.15 % of the full preset's controls, is most of the motion).
    filtered, output = [], []
    for seed in (5, 6, 7):
        u, air, op, navigation, A = gusty_record(seed=seed)
        # With the INS the gust is measured, a known input: nothing left for process noise.
        measured = aircraft_identify(Experiment(u, air, operating_point=op, navigation=navigation))
        assert {a.estimator for a in measured.aircraft.axes} == {"output error"}
        result = aircraft_identify(Experiment(u, air))
        (longitudinal,) = [a for a in result.aircraft.axes if a.name == "longitudinal"]
        assert longitudinal.estimator == "filter error"
        assert min(longitudinal.process_share[c] for c in ("airspeed", "alpha")) > 0.5
        assert "longitudinal by filter error" in format_text(result, 1, len(u))
        filtered.append(_longitudinal_error(result, A))
        plain = aircraft_identify(Experiment(u, air), process_noise=False)
        assert {a.estimator for a in plain.aircraft.axes} == {"output error"}
        output.append(_longitudinal_error(plain, A))
    assert np.mean(filtered) < 0.5 * np.mean(output)


def test_without_vanes_the_unmeasured_alpha_gust_is_process_noise_the_output_does_not_see():
    # α synthesised from the INS is the inertial α: the gust moves the aircraft (its rate
    # forces the air-relative state) and is absent from the output that measures it, so the
    # filter-error method's noise has that direct path (process.ProcessNoise.direct). Against
    # output error on the same records its longitudinal modes are nearer (measured worst
    # eigenvalue 0.071 / 0.191 / 0.009 off against 0.072 / 0.299 / 0.018 on seeds 5–7; the
    # same noise model without the direct path was not significant on two seeds and 0.661
    # off on the third).
    filtered, output = [], []
    for seed in (5, 6, 7):
        u, air, op, navigation, A = gusty_record(seed=seed)
        x = air + op
        made = synthesise(x[:, 0], x[:, 3], x[:, 7], navigation)
        vaneless = air.copy()
        vaneless[:, 1], vaneless[:, 4] = made.alpha - op[1], made.beta - op[4]
        record = Experiment(u, vaneless, operating_point=op, navigation=navigation, air_angles=made)
        result = aircraft_identify(record)
        (longitudinal,) = [a for a in result.aircraft.axes if a.name == "longitudinal"]
        assert longitudinal.estimator == "filter error"
        assert result.aircraft.wind.air_angles == "synthesised"
        filtered.append(_longitudinal_error(result, A))
        output.append(_longitudinal_error(aircraft_identify(record, process_noise=False), A))
    assert np.mean(filtered) < 0.8 * np.mean(output)


def test_white_sensor_noise_alone_keeps_output_error():
    # Calm air, 2 % white noise on every output: nothing for a process-noise model to explain,
    # and estimating one would cost the fit efficiency (the thesis's aircraft's phugoid
    # scattered 1.6 times its Cramér–Rao bound): the likelihood ratio keeps output error.
    u, air, _, _, A = gusty_record(seed=5, gust=0.0, scale=0.015)
    noisy = air + 0.02 * air.std(axis=0) * np.random.default_rng(5).standard_normal(air.shape)
    result = aircraft_identify(Experiment(u, noisy))
    assert {a.estimator for a in result.aircraft.axes} == {"output error"}
    assert all(a.process_share == {} for a in result.aircraft.axes)
    assert _longitudinal_error(result, A) < 0.05


def test_in_still_air_the_filter_errors_standard_errors_hold_its_distance_from_output_error():
    # Bad input tried: still air (the INS and the air data agree) around a model that is
    # wrong, a throttle whose thrust bends about the trim fitted without its square. The
    # residual's colour is the model's error, which the filter error reads as process noise
    # and output error as error to weight: two estimates, and nothing in the record to choose
    # between them (JSBSim's glider and PC-7 each lose to one of them; benchmarks/README.md).
    # Half the square of their distance joins the variance, so each longitudinal mode's
    # standard error covers that distance over √2 (before: the phugoid's imaginary part
    # 0.0028 for 0.0054/√2, the short period's 0.0065 for 0.025/√2).
    u, air, op, navigation, _ = gusty_record(
        seed=5, gust=0.0, scale=0.03, plan=classic_card(), curve=-0.3
    )
    record = Experiment(u, air, operating_point=op, navigation=navigation)
    filtered = aircraft_identify(record, throttle_curve=False)
    output = aircraft_identify(record, throttle_curve=False, process_noise=False)
    (longitudinal,) = [a for a in filtered.aircraft.axes if a.name == "longitudinal"]
    assert longitudinal.estimator == "filter error"
    assert filtered.aircraft.wind.undetected == ["airspeed", "alpha", "beta"]
    for name in ("phugoid", "short period"):
        (mine,) = [m for m in filtered.modes if m.name == name and complex(m.eigenvalue).imag > 0]
        (other,) = [m for m in output.modes if m.name == name and complex(m.eigenvalue).imag > 0]
        gap = complex(mine.eigenvalue) - complex(other.eigenvalue)
        assert abs(gap) > 0
        assert mine.uncertainty.real >= 0.9 * abs(gap.real) / np.sqrt(2)
        assert mine.uncertainty.imag >= 0.9 * abs(gap.imag) / np.sqrt(2)


def test_process_noise_spectra_that_do_not_converge_leave_output_error(monkeypatch):
    # Bad input tried: a record whose process-noise spectra do not converge (on JSBSim's T-6
    # through the classic card, vanes alone, the Fisher scoring's spectra went non-finite and
    # the eigen-decomposition of the residual's spectral matrix failed, ending the run). The
    # filter error is then given up for that axis and output error's estimate stands, with
    # the result saying which.
    from agent.ident.aircraft import process

    def diverging(*args, **kwargs):
        raise np.linalg.LinAlgError("the process-noise spectra did not converge")

    u, air, *_ = gusty_record(seed=5)
    plain = aircraft_identify(Experiment(u, air), process_noise=False)
    monkeypatch.setattr(process, "estimate", diverging)
    result = aircraft_identify(Experiment(u, air))
    assert {a.estimator for a in result.aircraft.axes} == {"output error"}
    assert np.allclose(result.continuous.A, plain.continuous.A)


def test_the_process_noise_spectra_never_end_below_their_white_start():
    # Bad input tried: a record on which the process-noise spectra's Fisher scoring (no line
    # search) stepped away from its white start and ended with a likelihood 6350 below it
    # (gusty_record seed 7, a third of the usual gust, no INS): the significance test then
    # read "no process noise" and output error was kept, 13.1 % off on the longitudinal
    # modes. Keeping the best spectra met, the filter error is taken: 10.6 %.
    u, air, *_, A = gusty_record(seed=7, gust=0.3)
    result = aircraft_identify(Experiment(u, air))
    (longitudinal,) = [a for a in result.aircraft.axes if a.name == "longitudinal"]
    assert longitudinal.estimator == "filter error"
    plain = aircraft_identify(Experiment(u, air), process_noise=False)
    assert _longitudinal_error(result, A) < _longitudinal_error(plain, A)


def test_the_filter_error_ends_at_the_lower_of_its_minima_under_its_final_spectra(monkeypatch):
    # Bad input tried: a record on which the filter error's passes (parameters at fixed
    # spectra, then the spectra at fixed parameters) end in a shallower basin of their own
    # likelihood: on JSBSim's glider through the sweep in calm air its short period's fast
    # pole came out 7.2–12.7 for 10.0 1/s. Under the final spectra the minimum from the
    # passes' end and the one from output error's estimate are both found and the lower
    # kept (gusty_record seed 11, the vanes alone: its likelihood lower, the longitudinal
    # modes 0.156 off against 0.319; over seeds 5–12 neither way nearer on average).
    u, air, *_ = gusty_record(seed=11)
    fitted = aircraft_identify(Experiment(u, air)).fitted
    monkeypatch.setattr(fit, "RESTART", False)
    passes = aircraft_identify(Experiment(u, air)).fitted
    (kept,), (ended,) = ([f for f in x.fits if f.name == "longitudinal"] for x in (fitted, passes))
    assert kept.noise is not None
    assert ended.noise is not None
    assert np.allclose(kept.noise.Q, ended.noise.Q)
    assert np.allclose(kept.noise.R, ended.noise.R)
    assert kept.cost < ended.cost - 1.0
    assert not np.allclose(kept.A, ended.A)


def test_a_restart_whose_minima_leave_output_errors_dynamics_keeps_the_passes_end(monkeypatch):
    # Bad input tried: a record on which both minima under the final spectra turn the
    # phugoid unstable where output error's is stable (gusty_record seed 7, the vanes alone).
    # Neither is kept and the filter error's passes' end stands, not output error: before the
    # guard the fit fell back to output error, its longitudinal modes 0.326 off the truth
    # against the passes' end's 0.136.
    u, air, *_ = gusty_record(seed=7)
    restarted = aircraft_identify(Experiment(u, air))
    monkeypatch.setattr(fit, "RESTART", False)
    passes = aircraft_identify(Experiment(u, air))
    (kept,), (ended,) = (
        [f for f in x.fitted.fits if f.name == "longitudinal"] for x in (restarted, passes)
    )
    (axis,) = [a for a in restarted.aircraft.axes if a.name == "longitudinal"]
    assert axis.estimator == "filter error"
    assert np.allclose(kept.A, ended.A)
    assert np.all(np.linalg.eigvals(kept.A).real < 0)


def test_a_filter_error_fit_stopped_at_its_iteration_limit_leaves_output_error(monkeypatch):
    # Bad input tried: a record on which the filter-error passes do not reach a minimum (on
    # JSBSim's PA-28 in calm air, a rounding difference of 1e-15 in the bins' averages sent
    # them to the iteration limit and the phugoid 46 % off). With the iterations cut to one
    # per pass no filter-error pass can end at a minimum: output error's estimate stands and
    # the result says which; with the limit as shipped the same record takes the filter error.
    u, air, *_ = gusty_record(seed=5)
    assert {a.estimator for a in aircraft_identify(Experiment(u, air)).aircraft.axes} == {
        "output error",
        "filter error",
    }
    monkeypatch.setattr(fit, "ITERATIONS", 1)
    plain = aircraft_identify(Experiment(u, air), process_noise=False)
    result = aircraft_identify(Experiment(u, air))
    assert {a.estimator for a in result.aircraft.axes} == {"output error"}
    assert np.allclose(result.continuous.A, plain.continuous.A)


def test_a_filter_error_estimate_that_leaves_output_errors_modes_is_not_kept():
    # Bad input tried (eigenvalues as JSBSim's glider gave them in light turbulence, the
    # vanes alone): a filter-error fit that turns output error's stable phugoid unstable,
    # and one that puts a pole at +1.9·10⁴ 1/s beside output error's +0.6 (the card's
    # identification then failed outright). Both give way to output error; a filter-error
    # fit that moves the modes within reason is kept.
    def model(*poles):
        blocks = [
            np.array([[p.real, p.imag], [-p.imag, p.real]]) if p.imag else [[p]] for p in poles
        ]
        return scipy.linalg.block_diag(*blocks)

    output = model(-3.661, 0.595, -0.025 + 0.339j)
    assert not consistent(output, model(19415.0, -3.211, -0.013 + 0.295j))
    assert not consistent(model(-3.6, -0.007 + 0.336j), model(-3.6, 0.017 + 0.278j))
    assert consistent(model(-3.6, -0.007 + 0.336j), model(-3.2, -0.03 + 0.30j))


def test_an_oscillation_longer_than_the_record_is_said_to_be_undetermined():
    """Bad input tried: the full preset's record cut to less than one phugoid period (a
    business jet's phugoid from two 25 s records of one manoeuvre came out 48 % apart with
    nothing said). The result names the phugoid as not determined by the record, with its
    period and the record's length; the whole record, several periods long, says nothing."""
    A, B, C = aircraft_with_engine_lag()
    record = full_preset_record(A, B, C)
    phugoid = min((p for p in np.linalg.eigvals(A[:8, :8]) if p.imag > 1e-6), key=lambda p: abs(p))
    period = 2 * np.pi / phugoid.imag
    whole = aircraft_identify(Experiment(record.u, record.y))
    assert len(record.u) * DT > 2 * period
    assert not [w for w in whole.warnings if "not determined by this record" in w]
    n = int(0.8 * period / DT)
    short = aircraft_identify(Experiment(record.u[:n], record.y[:n]))
    flagged = [w for w in short.warnings if "not determined by this record" in w]
    assert [w.split(" not determined")[0] for w in flagged] == ["phugoid"]
    assert f"longer than the record ({n * DT:.3g} s)" in flagged[0]


def test_a_lateral_run_uses_the_kinematics_of_the_airspeed_and_pitch_it_measures():
    """A lateral-only identification of a record that also measures the airspeed and θ (a
    research aircraft's lateral CSV: `kinematics: false`, φ̇ fitted freely as 0.927 p − 0.080
    β where the data give the kinematic rate). Given as the experiment's flight states, they
    make the kinematics known: φ's row is the kinematics at the trim (p + tan θ r), fixed,
    not fitted; without them it is fitted."""
    u, air, op, _, _ = gusty_record(seed=5, gust=0.0)
    lateral = slice(4, 8)
    flight = {"airspeed": air[:, 0] + op[0], "theta": air[:, 3] + op[3]}
    names = ("beta", "p", "r", "phi")

    def lateral_identify(**extra):
        record = Experiment(u[:, 2:], air[:, lateral], operating_point=op[lateral], **extra)
        return identify(
            record,
            DT,
            input_names=("aileron", "rudder"),
            output_names=names,
            output_roles=names,
            settings=Settings(held_inputs=False),
        )

    known = lateral_identify(flight=flight)
    blind = lateral_identify()
    assert known.aircraft.kinematics
    assert not blind.aircraft.kinematics
    kinematic_row = kinematic_jacobian(op)[7, 4:8]  # φ̇ over β, p, r, φ at the trim
    assert kinematic_row[2] != 0  # tan θ r: the trim is pitched
    np.testing.assert_allclose(known.continuous.A[3, :4], kinematic_row, atol=1e-12)
    # Fitted without them: close on this noise-free record, but the data's, not the rule's.
    assert np.max(np.abs(blind.continuous.A[3, :4] - kinematic_row)) > 1e-6


def _turbulent_candidate(seed: int, **gusts):
    """The full preset in a gust the INS measures and a rolling gust nothing does (`gusts`:
    gusty_record's), as the agent suggests it: its candidate and the aircraft's A."""
    u, air, op, navigation, A = gusty_record(seed=seed, **gusts)
    result = aircraft_identify(Experiment(u, air, operating_point=op, navigation=navigation))
    c = Candidate(
        model_id=f"seed-{seed}",
        axes="full",
        record_dt=DT,
        result=result.document(),
        experiments=(),
        record_s=len(u) * DT,
    )
    return c, A


def test_in_a_rolling_gust_nothing_measures_the_fit_is_judged_where_the_inputs_act():
    # A slow rolling gust (a thermal's edge: 0.002 rad/s² rms below 0.05 rad/s) moves the bank
    # far more than the manoeuvre: the whole record's TIC fails whatever the model. At the
    # excited bins the model fits, another record repeats its modes, and the suggestion's fit
    # step passes; the lateral modes are the aircraft's. Then a record the rolling gust
    # dominates (0.05 rad/s² rms, up to 0.5 rad/s: inside the excited band), where output
    # error's roll mode is imprecise and the lateral axis is refined by prediction error,
    # its roll mode still tens of per cent off: refused, even with another record to
    # compare (its fit at the excited bins fails).
    first, _ = _turbulent_candidate(6, roll_gust=0.002, roll_corner=0.05)
    second, A = _turbulent_candidate(7, roll_gust=0.002, roll_corner=0.05)
    assert second.tic_jj >= TIC_LIMIT
    alone = suggest(second, None, None, None)
    assert not alone.checks["fit"]
    assert "no earlier record to repeat it" in alone.steps[3]
    again = suggest(second, None, None, None, earlier=first)
    assert again.checks == {"stability": True, "quality": True, "modes": True, "fit": True}
    assert "seed-6's modes repeat" in again.steps[3]
    truth = np.linalg.eigvals(A[4:8, 4:8])
    for m in second.result.modes:
        if m.name in ("roll", "Dutch roll"):
            found = complex(*m.eigenvalue)
            nearest = truth[np.argmin(np.abs(truth - found))]
            assert abs(found - nearest) < 0.1 * abs(nearest), (m.name, found, nearest)
    earlier, _ = _turbulent_candidate(5, roll_gust=0.05)
    dominated, _ = _turbulent_candidate(7, roll_gust=0.05)
    verdict = suggest(dominated, None, None, None, earlier=earlier)
    assert dominated.tic_jj >= TIC_LIMIT
    estimators = {a.name: a.estimator for a in dominated.result.aircraft.axes}
    assert estimators["lateral"] == "prediction error"
    assert excited_tic(dominated.result)["lateral"] >= TIC_LIMIT
    assert not verdict.checks["fit"]
    # p's excited bins are the gust's, as its noise model says; φ's misfit (the gust's
    # response integrated) is more than the noise model leaves there.
    assert "its noise model's, above" in verdict.steps[3]
    assert not verdict.update


def test_the_noise_models_yardstick_sees_a_misfit_its_noise_does_not_explain(monkeypatch):
    # A rolling gust nothing measures inside the roll mode's band (corner 1 rad/s), the
    # lateral axis refined by prediction error (closed loop told). What the refined model
    # leaves at p's excited bins is no more than its noise model claims there; the same
    # model with its roll damping L_p halved leaves about twice the band's top, so the fit
    # step would not excuse it. Bad input tried: a model that misfits; a model whose
    # response is not finite (a ratio of nan).
    seen = {}
    original = predictor.misfit_to_noise

    def keep(problem, theta, weights, result, lengths):
        seen.update(problem=problem, theta=theta, weights=weights, result=result, lengths=lengths)
        return original(problem, theta, weights, result, lengths)

    monkeypatch.setattr(predictor, "misfit_to_noise", keep)
    u, air, op, navigation, _ = gusty_record(8, roll_gust=0.002, roll_corner=1.0)
    record = Experiment(u, air, operating_point=op, navigation=navigation)
    result = aircraft_identify(record, closed_loop=True)
    (lateral,) = [a for a in result.aircraft.axes if a.name == "lateral"]
    assert lateral.estimator == "prediction error"
    p = lateral.noise_misfit["p"]
    assert 0 < p.low < 1 < p.high
    assert p.ratio <= p.high
    problem, theta = seen["problem"], seen["theta"]
    A, B, taus, d = problem.unpack(theta)
    row = lateral.outputs.index("p")
    worse = A.copy()
    worse[row, row] *= 0.5
    args = (seen["weights"], seen["result"], seen["lengths"])
    ratio, _, high = original(problem, problem.pack(worse, B, taus, d), *args)[row]
    assert ratio > 1.5 * high  # 2.8 against a band's top of 1.3, measured
    broken = A.copy()
    broken[row, row] = np.nan
    assert np.isnan(original(problem, problem.pack(broken, B, taus, d), *args)).all()


def _roll(result: Identification):
    """`result`'s roll mode."""
    (roll,) = [m for m in result.modes if m.name == "roll"]
    return roll


def test_in_open_loop_the_rolling_gust_is_modelled_only_where_output_errors_roll_is_imprecise():
    # The full preset in a rolling gust nothing measures, flown open loop. A gust that moves
    # the bank within the roll mode's band (corner 1 rad/s): output error's roll mode 18 % off
    # with a σ of 20 %, imprecise, so the lateral axis is refined by prediction error, its
    # noise model reading the gust's own response, and its roll comes within 3 of its σ of
    # the truth. A slower gust (corner 0.05 rad/s) that still shows as process noise (a
    # closed-loop record of it is refined): output error's roll σ under 5 %, and it stands.
    u, air, op, navigation, A = gusty_record(8, roll_gust=0.002, roll_corner=1.0)
    record = Experiment(u, air, operating_point=op, navigation=navigation)
    lateral = np.linalg.eigvals(A[4:8, 4:8])
    true = max(lateral[np.abs(lateral.imag) < 1e-9].real, key=abs)
    plain = _roll(aircraft_identify(record, predictor=False))
    assert plain.uncertainty.frequency > predictor.PRECISE * plain.frequency
    result = aircraft_identify(record)
    assert {a.name: a.estimator for a in result.aircraft.axes}["lateral"] == "prediction error"
    roll = _roll(result)
    assert abs(roll.eigenvalue.real - true) < 3 * roll.uncertainty.real
    assert abs(roll.eigenvalue.real - true) < abs(plain.eigenvalue.real - true)

    u, air, op, navigation, _ = gusty_record(6, roll_gust=0.002, roll_corner=0.05)
    record = Experiment(u, air, operating_point=op, navigation=navigation)
    closed = aircraft_identify(record, closed_loop=True)
    assert {a.name: a.estimator for a in closed.aircraft.axes}["lateral"] == "prediction error"
    result = aircraft_identify(record)
    assert {a.name: a.estimator for a in result.aircraft.axes}["lateral"] == "output error"
    roll = _roll(result)
    assert roll.uncertainty.frequency <= predictor.PRECISE * roll.frequency
    plain = aircraft_identify(record, predictor=False)
    np.testing.assert_allclose(result.continuous.A, plain.continuous.A)


def test_roll_imprecise_reads_output_errors_fastest_subsiding_real_mode():
    # An axis whose fastest real eigenvalue is A's third diagonal entry: its σ is that entry's.
    A = np.diag([-0.05, -1.0, -5.0, -0.5])
    A[0, 3], A[3, 0] = 2.0, -2.0  # a lightly damped pair at ω ≈ 2: not a roll candidate
    covariance = np.zeros((16 + 8, 16 + 8))

    def imprecise(matrix, std):
        covariance[10, 10] = std**2  # vec A's (2, 2)
        return predictor.roll_imprecise(types.SimpleNamespace(A=matrix, covariance=covariance))

    assert not imprecise(A, 0.2)  # 4 %
    assert imprecise(A, 0.3)  # 6 %
    unstable = A.copy()
    unstable[2, 2] = 5.0
    assert imprecise(unstable, 0.0)  # the fastest real one diverges: no roll found
    slow = A.copy()
    slow[1, 1], slow[2, 2] = -0.2, -0.1
    assert imprecise(slow, 0.0)  # nothing faster than a spiral can be
    assert imprecise(A, np.nan)  # bad input tried: a covariance that is not a number


def test_a_prediction_error_fit_that_fails_keeps_output_error_and_says_why(monkeypatch):
    # Bad input tried: a record whose predictor cannot be fitted (the refinement raises, as it
    # does when every start diverges), closed loop and open loop (where output error's roll
    # is imprecise enough to refine it). The frequency-domain fit stands, with a note.
    u, air, op, navigation, _ = gusty_record(3, roll_gust=0.002, roll_corner=1.0)
    record = Experiment(u, air, operating_point=op, navigation=navigation)

    def diverges(*args, **kwargs):
        raise IdentificationFailed("the predictor diverges")

    monkeypatch.setattr(predictor, "refine", diverges)
    note = "lateral axis: prediction error failed (the predictor diverges); output error kept"
    for closed_loop in (True, False):
        kept = aircraft_identify(record, closed_loop=closed_loop)
        plain = aircraft_identify(record, closed_loop=closed_loop, predictor=False)
        assert note in kept.warnings
        np.testing.assert_allclose(kept.continuous.A, plain.continuous.A)
        assert {a.name: a.estimator for a in kept.aircraft.axes}["lateral"] == "output error"


def test_the_normal_equations_keep_every_direction_whatever_the_parameters_units():
    # Bad input tried: a Jacobian whose columns span twelve decades (a derivative in 1/s
    # beside a gain on a squared input whose excursion is tiny), as the filter error's
    # whitening makes them: the pseudo-inverse of JᵀJ dropped the small columns' directions
    # and gave their parameters a variance of almost nothing.
    rng = np.random.default_rng(3)
    J = rng.normal(size=(400, 6))
    scales = 10.0 ** np.array([6, 3, 0, -2, -4, -6])
    exact = np.linalg.inv(J.T @ J) / np.outer(scales, scales)
    H = (J * scales).T @ (J * scales)
    assert np.allclose(normal_inverse(H), exact, rtol=1e-6)
    dropped = np.linalg.pinv(H, rcond=1e-12)
    assert np.diag(dropped)[-1] < 1e-6 * np.diag(exact)[-1]  # what the sandwich used to do


def test_a_record_too_short_for_the_prediction_errors_blocks_keeps_output_error(monkeypatch):
    # Bad input tried: a closed-loop record shorter than two of the refinement's averaging
    # blocks (the blocks made longer than half the record). The refinement refuses it by
    # name, and the frequency-domain fit stands with a note, as for any failed refinement.
    u, air, op, navigation, _ = gusty_record(3, roll_gust=0.002, roll_corner=1.0)
    record = Experiment(u, air, operating_point=op, navigation=navigation)
    monkeypatch.setattr(predictor, "RATE_HZ", 1.5 / (u.shape[0] * DT))
    kept = aircraft_identify(record, closed_loop=True)
    (note,) = [w for w in kept.warnings if "prediction error failed" in w]
    assert "a record shorter than two blocks" in note
    assert {a.name: a.estimator for a in kept.aircraft.axes}["lateral"] == "output error"
    plain = aircraft_identify(record, closed_loop=True, predictor=False)
    np.testing.assert_allclose(kept.continuous.A, plain.continuous.A)
