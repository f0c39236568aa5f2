"""Conversions and time alignment, on known answers."""

from __future__ import annotations

import math
import random

import pytest

from agent.config import AirDataPort, Calibration, SurfacePort
from drivers.airdata.codec import AirData
from drivers.airdata.driver import AirDataConverter, true_airspeed
from drivers.surfaces.codec import SurfaceFrame
from drivers.surfaces.driver import SurfaceConverter, counts_to_degrees, gang
from drivers.timing import DeviceClock, Unwrap
from drivers.vectornav.codec import VnAscii, VnPacket
from drivers.vectornav.driver import (
    convert_ascii,
    convert_binary,
    euler_to_quaternion,
    gps_to_unix,
    quaternion_to_euler,
    register_75,
)


@pytest.mark.parametrize("angles", [(0.1, -0.2, 0.3), (-1.2, 0.7, -2.9), (0.0, 1.5, 3.1)])
def test_quaternion_euler_round_trip(angles):
    q = euler_to_quaternion(*angles)
    assert math.isclose(sum(c * c for c in q), 1.0)
    assert quaternion_to_euler(*q) == pytest.approx(angles, abs=1e-12)


def test_quaternion_axes_follow_3_2_1_euler():
    # A pure 90° yaw is the quaternion (0, 0, sin 45°, cos 45°).
    s = math.sqrt(0.5)
    assert quaternion_to_euler(0, 0, s, s) == pytest.approx((0, 0, math.pi / 2))
    assert quaternion_to_euler(s, 0, 0, s) == pytest.approx((math.pi / 2, 0, 0))


def test_gps_time_to_utc():
    # 2017-01-01T00:00:00Z was GPS week 1930, 0 s of week + 18 leap seconds (GPS − UTC).
    gps = 1930 * 604_800 + 18
    assert gps_to_unix(gps, 18) == 1_483_228_800


def test_vn200_binary_conversion():
    q = euler_to_quaternion(0.1, 0.05, 1.0)
    packet = VnPacket(
        {
            "common.time_startup": 2_500_000_000,
            "common.time_gps": 1_400_000_000_000_000_000,
            "common.quaternion": q,
            "common.angular_rate": (0.1, 0.2, 0.3),
        }
    )
    reading = convert_binary(18)(packet)
    assert reading.device_time == pytest.approx(2.5)
    assert (reading.values["phi"], reading.values["theta"], reading.values["psi"]) == pytest.approx(
        (0.1, 0.05, 1.0)
    )
    assert reading.values["q"] == 0.2
    assert reading.values["utc"] == pytest.approx(315_964_800 + 1.4e9 - 18)
    # Bad input tried: a NaN attitude is dropped, not published.
    bad = VnPacket({"common.quaternion": (math.nan, 0.0, 0.0, 1.0)})
    assert convert_binary(18)(bad) is None


def test_vn200_ascii_conversion_degrees_to_radians():
    message = VnAscii(
        "VNYMR",
        {
            "yaw": 90.0,
            "pitch": 0.0,
            "roll": -45.0,
            "mag_x": 0,
            "mag_y": 0,
            "mag_z": 0,
            "accel_x": 0,
            "accel_y": 0,
            "accel_z": -9.8,
            "gyro_x": 0.1,
            "gyro_y": 0,
            "gyro_z": 0,
        },
    )
    reading = convert_ascii(18)(message)
    assert reading.values["psi"] == pytest.approx(math.pi / 2)
    assert reading.values["phi"] == pytest.approx(-math.pi / 4)
    assert reading.device_time is None  # $VNYMR carries no time: the arrival time is used


def test_register_75_command():
    command = register_75(100.0, ["common.time_startup", "common.quaternion"])
    body, check = command[1:].rstrip(b"\r\n").split(b"*")
    assert body == b"VNWRG,75,3,8,01,0011"
    from drivers.codec import crc16_xmodem

    assert int(check, 16) == crc16_xmodem(body)


def test_true_airspeed_from_ias():
    # Sea level ISA: TAS = IAS. At 3000 m pressure altitude ρ/ρ₀ = 0.7423: TAS = IAS/√0.7423.
    assert true_airspeed(20.0, 101_325.0, 0.0) == pytest.approx(20.0, rel=1e-3)
    assert true_airspeed(20.0, 70_108.0, 3000.0) == pytest.approx(
        20.0 / math.sqrt(0.7423), rel=2e-3
    )


def test_airdata_flags_the_probe_limit_and_converts_angles():
    convert = AirDataConverter(AirDataPort())
    r = convert(AirData(5, 20.0, 19.98, -3.0, 100.0, 101_500.0, 100_000.0))
    assert r.values["alpha"] == pytest.approx(19.98 * math.pi / 180)
    assert r.values["alpha_clipped"] == 1.0
    assert r.values["beta_clipped"] == 0.0
    assert r.device_time == pytest.approx(0.05)
    # The five-digit counter wraps: 99999 → 00000 continues in time.
    convert = AirDataConverter(AirDataPort())
    convert(AirData(99_999, 20, 0, 0, 0, 101_325, 101_325))
    assert convert(AirData(0, 20, 0, 0, 0, 101_325, 101_325)).device_time == pytest.approx(1000.0)
    # Bad input tried: a zero static pressure (a dead sensor) is dropped.
    assert convert(AirData(1, 20, 0, 0, 0, 101_325, 0.0)) is None


def test_an_airspeed_only_probe_records_no_angles():
    # `vanes = false`: the probe's α and β fields (here a clipped 19.98°) carry nothing; they
    # are recorded as missing, never as a reading or a clip, and the airspeed is kept.
    convert = AirDataConverter(AirDataPort(vanes=False))
    r = convert(AirData(5, 20.0, 19.98, -3.0, 100.0, 101_500.0, 100_000.0))
    assert math.isnan(r.values["alpha"])
    assert math.isnan(r.values["beta"])
    assert r.values["alpha_clipped"] == 0.0
    assert r.values["Vt"] == pytest.approx(true_airspeed(20.0, 100_000.0, 100.0))


def test_surface_calibration_table_poly_and_ganging():
    table = Calibration(table=((100, -20.0), (512, 0.0), (900, 25.0)))
    assert counts_to_degrees(306, table) == pytest.approx(-10.0)
    assert counts_to_degrees(706, table) == pytest.approx(12.5)
    assert counts_to_degrees(1023, table) == pytest.approx(25.0)  # held beyond the table
    poly = Calibration(poly=(-128.0, 0.25))
    assert counts_to_degrees(600, poly) == pytest.approx(22.0)
    # Eq. 3.1: right aileron down +5°, left up −5° is δA = +5°; both elevators +2° is δE = +2°.
    each = {"aileron_left": -5.0, "aileron_right": 5.0, "elevator_left": 2.0}
    each |= {"elevator_right": 2.0, "rudder": 1.0, "flap_left": 10.0, "flap_right": 10.0}
    g = gang(each)
    assert g == {"aileron": 5.0, "elevator": 2.0, "rudder": 1.0, "flap": 10.0}
    with pytest.raises(ValueError, match="exactly one"):
        Calibration(table=((0, 0.0), (1, 1.0)), poly=(0.0, 1.0))
    with pytest.raises(ValueError, match="strictly increasing"):
        Calibration(table=((5, 0.0), (5, 1.0)))


def test_surface_converter_unwraps_millis():
    convert = SurfaceConverter(SurfacePort())
    counts = (512,) * 7
    assert convert(SurfaceFrame(1, 2**32 - 5, counts, 0)).device_time == pytest.approx(
        (2**32 - 5) / 1000
    )
    assert convert(SurfaceFrame(2, 5, counts, 0)).device_time == pytest.approx((2**32 + 5) / 1000)


def test_device_clock_tracks_the_least_delayed_sample():
    rng = random.Random(3)
    clock = DeviceClock()
    offset = 1234.5  # agent time − device time
    errors = []
    for k in range(3000):
        device = k * 0.01
        latency = 0.0005 + rng.expovariate(1 / 0.004)  # jittery serial + loop latency
        local = clock.local(device, device + offset + latency)
        if k > 100:
            errors.append(abs(local - (device + offset)))
    assert max(errors) < 0.002  # the jitter itself reaches 30 ms
    # Bad input tried: the device restarts (its clock jumps back): the estimate restarts.
    resets = clock.resets
    local = clock.local(0.5, 3000 * 0.01 + offset + 1.0)
    assert clock.resets == resets + 1
    assert local == pytest.approx(3000 * 0.01 + offset + 1.0)


def test_unwrap():
    unwrap = Unwrap(100)
    assert [unwrap(v) for v in (97, 99, 1, 3, 2, 50, 99, 0)] == [
        97,
        99,
        101,
        103,
        102,
        150,
        199,
        200,
    ]
