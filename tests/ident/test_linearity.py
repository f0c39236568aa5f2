"""The linear range from the aircraft's own records (agent.ident.aircraft.linearity and
agent.sizing.linear_range): the larger record's model priced on the smaller record by that
record's own fit criterion. On the thesis's aircraft (A.2, the engine's lags), 5 % white noise:
two records of the full preset at amplitudes 2.5× apart from the same linear aircraft, and the
same two where the larger one was flown by an aircraft whose pitch stiffness is 40 % higher (an
amplitude-dependent short period, as JSBSim's PC-7 has: benchmarks/README.md).

Bad input tried: records of different channels (nothing compared), amplitudes too close, one
control up and another down (no span), no fitted record."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest

from agent import sizing
from agent.ident import Experiment
from agent.ident import job as jobs
from agent.ident.aircraft import linearity
from agent.ident.convert import discretize_foh
from agent.ident.fit import simulate
from agent.runtime.worker import new_worker
from tests.ident.test_aircraft import (
    DT,
    INPUTS,
    RECORDED,
    aircraft_identify,
    aircraft_with_engine_lag,
    full_preset_record,
    window_job,
)

NOISE = 0.05  # of each output's rms
SMALL = 0.4  # the smaller record's amplitudes, of the larger's
STIFFER = 1.4  # the larger record's pitch stiffness (M_α), of the small-amplitude aircraft's


def _record(A, B, C, scale: float, seed: int) -> Experiment:
    base = full_preset_record(A, B, C)
    u = base.u * scale
    model = discretize_foh(A, B, C, np.zeros((8, 4)), DT)
    y = simulate(model, u)
    rms = np.sqrt(np.mean(full_preset_record(*aircraft_with_engine_lag()).y ** 2, axis=0))
    rng = np.random.default_rng(seed)
    return Experiment(u, y + NOISE * rms * rng.normal(size=y.shape))


@functools.cache
def _identified(stiffer: float, scale: float, seed: int):
    A, B, C = aircraft_with_engine_lag()
    if scale == 1.0:
        A = A.copy()
        A[2, 1] *= stiffer  # q̇ per α
    return aircraft_identify(_record(A, B, C, scale, seed))


def _flown(scale: float) -> dict[str, float]:
    return {c: 10.0 * scale for c in ("throttle", "elevator", "aileron", "rudder")}


def _entry(stiffer: float, scale: float, seed: int):
    result = _identified(stiffer, scale, seed)
    return result.document(), result.fitted, _flown(scale)


def test_a_linear_aircraft_explains_its_smaller_record_with_the_larger_ones_model():
    small, big = _identified(1.0, SMALL, 1).fitted, _identified(1.0, 1.0, 2).fitted
    excess = linearity.excess(small, big)
    assert set(excess) == {"longitudinal", "lateral"}
    assert max(excess.values()) < sizing.LINEARITY_EXCESS / 2, excess
    big_doc, big_fit, big_flown = _entry(1.0, 1.0, 2)
    assert sizing.linear_range(big_doc, big_fit, big_flown, [_entry(1.0, SMALL, 1)]) == {}


def test_a_short_period_that_moves_with_the_amplitude_holds_the_longitudinal_controls():
    small, big = _identified(STIFFER, SMALL, 1).fitted, _identified(STIFFER, 1.0, 2).fitted
    excess = linearity.excess(small, big)
    assert excess["longitudinal"] > sizing.LINEARITY_EXCESS, excess
    assert excess["lateral"] < sizing.LINEARITY_EXCESS / 2, excess  # the other axis is linear
    big_doc, big_fit, big_flown = _entry(STIFFER, 1.0, 2)
    limits = sizing.linear_range(big_doc, big_fit, big_flown, [_entry(STIFFER, SMALL, 1)])
    assert set(limits) == {"elevator"}  # the short period's control, not the throttle
    for amplitude, why in limits.values():
        assert amplitude == pytest.approx(10.0 * SMALL)
        assert "short period" in why
    # The same pair the other way round: this model is the smaller record's.
    small_doc, small_fit, small_flown = _entry(STIFFER, SMALL, 1)
    assert sizing.linear_range(small_doc, small_fit, small_flown, [(big_doc, big_fit, big_flown)])


def test_no_span_no_limit():
    big_doc, big_fit, big_flown = _entry(STIFFER, 1.0, 2)
    small = _entry(STIFFER, SMALL, 1)
    # Amplitudes too close to tell a repeat from the amplitude.
    near = (small[0], small[1], {c: v / (1.2 * SMALL) for c, v in small[2].items()})
    assert sizing.linear_range(big_doc, big_fit, big_flown, [near]) == {}
    # The elevator up and the throttle down between the two: no one direction.
    mixed = (small[0], small[1], {**small[2], "throttle": 20.0})
    limits = sizing.linear_range(big_doc, big_fit, big_flown, [mixed])
    assert "elevator" not in limits
    # No fitted record: nothing to price a model on.
    assert sizing.linear_range(big_doc, None, big_flown, [small]) == {}
    # Records of different channels are not compared.
    record = _record(*aircraft_with_engine_lag(), SMALL, 1)
    gliding = aircraft_identify(
        Experiment(record.u[:, 1:], record.y), inputs=("elevator", "aileron", "rudder")
    )
    assert linearity.costs(gliding.fitted, big_fit) == {}


def test_the_worker_gives_back_the_fitted_record_the_sizing_prices_models_on():
    """The agent's job in its real worker process (spawned, as onboard): a window of one
    record comes back with its fitted axes, which price its own model at no excess."""
    record = _record(*aircraft_with_engine_lag(), SMALL, 1)
    trim = np.array([25.0, 0.05, 0.0, 0.05, 0.0, 0.0, 0.0, 0.0])  # a flight state to be about
    window = dict(zip(INPUTS, record.u.T, strict=True)) | dict(
        zip(RECORDED, (record.y + trim).T, strict=True)
    )
    job = window_job(window)
    with new_worker() as worker:
        outcome = worker.submit(jobs.run, job).result(timeout=600)
        assert outcome.ok, outcome.reason
        assert {fit.name for fit in outcome.fitted.fits} == {"longitudinal", "lateral"}
        assert all(
            v == pytest.approx(0.0, abs=1e-9)
            for v in linearity.excess(outcome.fitted, outcome.fitted).values()
        )


def test_a_model_whose_dynamics_are_not_numbers_holds_nothing():
    """Bad input tried: the larger record's model diverged (its longitudinal A NaN, as a fit
    that ran away leaves it): no evidence of a nonlinearity, no limit, and the sizing goes on."""
    big_doc, big_fit, big_flown = _entry(STIFFER, 1.0, 2)
    broken = dataclasses.replace(
        big_fit,
        fits=[
            dataclasses.replace(f, A=np.full_like(f.A, np.nan)) if f.name == "longitudinal" else f
            for f in big_fit.fits
        ],
    )
    small = _entry(STIFFER, SMALL, 1)
    # the broken model's response is not a number: its cost, and the excess, are not finite
    assert not np.isfinite(linearity.excess(small[1], broken)["longitudinal"])
    assert sizing.linear_range(big_doc, broken, big_flown, [small]) == {}


def test_a_refit_that_fails_holds_nothing(monkeypatch):
    """Bad input tried: the refit of the smaller record at the larger model's dynamics fails
    (a singular normal matrix, as a record that does not move a state gives): that pair is no
    evidence, no limit, and the sizing goes on; the same pair holds the elevator when the
    refit runs."""
    big = _entry(STIFFER, 1.0, 2)
    small = _entry(STIFFER, SMALL, 1)
    assert "elevator" in sizing.linear_range(*big, [small])

    def singular(*args, **kwargs):
        raise np.linalg.LinAlgError("Singular matrix")

    monkeypatch.setattr(linearity, "excess", singular)
    assert sizing.linear_range(*big, [small]) == {}
