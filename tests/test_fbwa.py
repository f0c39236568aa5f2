"""ArduPlane's FBWA laws (agent.fbwa) against what ArduPilot's source says they do: the
speed scaling of each term, the integrator's limits, the rudder mix, the scaler's filter, and
a bank hold on a rolling aircraft. Bad input tried: a parameter ArduPlane's FBWA does not
have (refused by name), a non-finite rate (no output, the integrator kept)."""

from __future__ import annotations

import numpy as np
import pytest

from agent.fbwa import DEFAULTS, LOOP_HZ, TRAVEL_DEG, Fbwa, Pid, RateLoop, Sensed

DT = 1.0 / LOOP_HZ


def _loop(**gains) -> RateLoop:
    values = {"kp": 0.0, "ki": 0.0, "kd": 0.0, "kff": 0.0, "imax": 0.666}
    values |= gains
    return RateLoop(Pid(**values, fltt=3.0, flte=0.0, fltd=12.0))


def test_the_feed_forward_scales_with_one_over_speed_and_the_error_terms_with_its_square():
    # AP_FW_Controller: target and gyro enter the PID times S² (S = SCALING_SPEED / EAS), the
    # feed-forward leaves it divided by S: a surface's moment grows with dynamic pressure.
    def first(speed_scaler, **gains):
        return _loop(**gains).step(10.0, speed_scaler, 0.0, DT, 1.0, underspeed=False)

    assert first(1.0, kff=0.345) / first(0.5, kff=0.345) == pytest.approx(2.0)
    assert first(1.0, kp=0.08) / first(0.5, kp=0.08) == pytest.approx(4.0)
    # 10 deg/s at S = 1 with ArduPlane's roll FF of 0.345: 3.45° of aileron.
    assert first(1.0, kff=0.345) == pytest.approx(3.45)
    # True airspeed above equivalent (altitude) takes the feed-forward down with it.
    loop = _loop(kff=0.345)
    assert loop.step(10.0, 1.0, 0.0, DT, 1.25, underspeed=False) == pytest.approx(3.45 / 1.25)


def test_the_integrator_stops_growing_at_full_travel_and_stands_still_underspeed():
    loop = _loop(ki=0.15, kff=0.345)
    for _ in range(50):  # a demand the surface cannot meet: full travel
        out = loop.step(200.0, 1.0, 0.0, DT, 1.0, underspeed=False)
    assert out == TRAVEL_DEG
    held = loop.pid.integrator
    for _ in range(50):
        loop.step(200.0, 1.0, 0.0, DT, 1.0, underspeed=False)
    assert loop.pid.integrator == held  # limited: it may only shrink
    for _ in range(25):  # the demand reversed: once its filtered error turns, it shrinks
        loop.step(-200.0, 1.0, 0.0, DT, 1.0, underspeed=False)
    assert loop.pid.integrator < held
    slow = _loop(ki=0.15)
    slow.step(20.0, 1.0, 0.0, DT, 1.0, underspeed=False)
    before = slow.pid.integrator
    for _ in range(20):
        slow.step(20.0, 1.0, 0.0, DT, 1.0, underspeed=True)
    assert slow.pid.integrator == before
    assert abs(before) <= 0.666


def test_a_non_finite_rate_gives_no_new_output_and_keeps_the_integrator():
    loop = _loop(ki=0.15, kff=0.345)
    for _ in range(10):
        loop.step(10.0, 1.0, 0.0, DT, 1.0, underspeed=False)
    kept = loop.pid.integrator
    out = loop.step(10.0, 1.0, float("nan"), DT, 1.0, underspeed=False)
    assert loop.pid.integrator == kept
    assert np.isfinite(out)


def test_the_speed_scaler_follows_the_airspeed_at_ten_hertz_through_its_filter():
    fbwa = Fbwa()
    level = Sensed(phi=0.0, theta=0.0, p=0.0, q=0.0, r=0.0, eas=30.0)
    fbwa.step(level, roll_deg=0.0, pitch_deg=0.0, dt=0.02)
    assert fbwa.scaler == 1.0  # not yet a tenth of a second
    for _ in range(200):
        fbwa.step(level, roll_deg=0.0, pitch_deg=0.0, dt=0.02)
    assert fbwa.scaler == pytest.approx(15.0 / 30.0, rel=1e-3)
    slow = Sensed(phi=0.0, theta=0.0, p=0.0, q=0.0, r=0.0, eas=2.0)
    for _ in range(200):
        fbwa.step(slow, roll_deg=0.0, pitch_deg=0.0, dt=0.02)
    # Clamped: max(2, SCALING_SPEED / (0.7 · max(AIRSPEED_MIN, 5))) with ArduPlane's defaults.
    assert fbwa.scaler == pytest.approx(15.0 / (0.7 * 9.0), rel=1e-3)


def test_the_rudder_is_half_the_aileron_and_the_pilots_with_the_damper_off():
    fbwa = Fbwa()
    s = Sensed(phi=0.0, theta=0.0, p=0.0, q=0.0, r=0.3, eas=15.0)
    out = fbwa.step(s, roll_deg=10.0, pitch_deg=0.0, rudder_stick=0.1)
    assert out.aileron > 0
    assert out.rudder == pytest.approx(0.5 * out.aileron + 0.1 * TRAVEL_DEG)
    damped = Fbwa({"YAW2SRV_DAMP": 0.5})
    yawing = damped.step(s, roll_deg=0.0, pitch_deg=0.0)
    assert yawing.rudder < 0  # against the yaw rate


def test_a_bank_demand_is_held_on_a_rolling_aircraft_without_a_steady_error():
    # ṗ = L_p p + L_δa δa (L_δa in °/s² per degree of notional travel: 20° of aileron rolls at
    # 100 °/s), the aileron lagging 50 ms: a 20° bank demand is reached and held; the
    # integrator takes up a rolling moment the aircraft keeps (a fuel imbalance: 2 °/s²).
    fbwa = Fbwa()
    L_p, L_da, imbalance, lag = -6.0, 30.0, np.radians(2.0), 0.05
    phi = p = surface = 0.0
    bank = []
    for _ in range(int(12 * LOOP_HZ)):
        s = Sensed(phi=phi, theta=0.0, p=p, q=0.0, r=0.0, eas=15.0)
        out = fbwa.step(s, roll_deg=20.0, pitch_deg=0.0)
        surface += DT / lag * (out.aileron - surface)
        p += DT * (L_p * p + np.radians(L_da * surface) + imbalance)
        phi += DT * p
        bank.append(np.degrees(phi))
    bank = np.array(bank)
    assert bank[-1] == pytest.approx(20.0, abs=0.2)
    assert bank.max() < 20.0 * 1.2
    assert np.argmax(bank > 18.0) * DT < 3.0


def test_a_parameter_changes_by_name_and_an_unknown_one_is_refused():
    with pytest.raises(KeyError, match="RLL_RATE_PP"):
        Fbwa({"RLL_RATE_PP": 1.0})
    fbwa = Fbwa()
    with pytest.raises(KeyError):
        fbwa.set("NOT_A_PARAM", 1.0)
    s = Sensed(phi=0.0, theta=0.0, p=0.0, q=0.0, r=0.0, eas=15.0)
    before = Fbwa().step(s, roll_deg=10.0, pitch_deg=0.0).aileron
    fbwa.set("RLL_RATE_FF", 2 * DEFAULTS["RLL_RATE_FF"])
    after = fbwa.step(s, roll_deg=10.0, pitch_deg=0.0).aileron
    assert after > 1.8 * before


def test_the_sticks_map_to_arduplanes_attitude_limits():
    fbwa = Fbwa()
    assert fbwa.demands(1.0, 1.0, 0.0, 0.0) == pytest.approx((45.0, 20.0))
    assert fbwa.demands(-1.0, -1.0, 0.0, 0.0) == pytest.approx((-45.0, -25.0))
    # Banked 60°: the nose-down limit shrinks with |cos φ|; pitched 30°, the roll limit with cos θ.
    assert fbwa.demands(0.0, -1.0, 0.0, np.radians(60))[1] == pytest.approx(-12.5)
    assert fbwa.demands(1.0, 0.0, np.radians(30), 0.0)[0] == pytest.approx(
        45 * np.cos(np.radians(30))
    )
