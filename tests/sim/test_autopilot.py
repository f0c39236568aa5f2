"""The real MAVSDK driver against the emulated ArduPlane over UDP loopback, with JSBSim
behind it.

Bad input tried: overrides from a wrong system id, an override of the pilot's switch
channel, overrides while the switch is low (RCx_OPTION 46), overrides that stop without a
release, and the autopilot vanishing mid-run.
"""

from __future__ import annotations

import asyncio

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from agent.sim.ardupilot import Params
from drivers.autopilot.driver import AutopilotError
from tests.sim.flight import SWITCH, flight

pytestmark = pytest.mark.usefixtures("no_leaked_tasks")


async def _override(link, pwm: dict[int, int], seconds: float, rate: float = 50.0) -> float:
    """Send overrides at `rate` for `seconds`; the loop time of the last one."""
    last = 0.0
    for _ in range(round(seconds * rate)):
        await link.command(pwm)
        last = asyncio.get_running_loop().time()
        await asyncio.sleep(1 / rate)
    return last


def _raw_override(f, pwm: dict[int, int]) -> None:
    """RC_CHANNELS_OVERRIDE with these channels, as the driver's system sends it but without
    the driver's refusal of the switch channel, arriving at the emulated ArduPlane from the
    driver's address (every other channel left alone: 65535 on 1–8, 0 on 9–18)."""
    ap = f.aircraft.autopilot
    mav = mavlink.MAVLink(None, srcSystem=ap.params.sysid_mygcs, srcComponent=190)
    values = [pwm.get(ch, 65535 if ch <= 8 else 0) for ch in range(1, 19)]
    message = mav.rc_channels_override_encode(ap.params.sysid, 1, *values)
    ap.datagram_received(message.pack(mav), next(iter(ap.peers)))


async def test_telemetry_arrives_at_the_configured_rates(tmp_path):
    async with flight(tmp_path, attitude_hz=50, vfr_hud_hz=10, rc_channels_hz=20) as f:
        assert f.link.connected
        await asyncio.sleep(0.5)  # rates set
        before = dict(f.link.received)
        await asyncio.sleep(2.0)
        got = {k: (f.link.received[k] - before.get(k, 0)) / 2.0 for k in f.link.received}
    assert got["ATTITUDE"] == pytest.approx(50, rel=0.15)
    assert got["VFR_HUD"] == pytest.approx(10, rel=0.15)
    assert got["RC_CHANNELS"] == pytest.approx(20, rel=0.15)
    assert got["HEARTBEAT"] == pytest.approx(1, abs=0.6)
    assert f.states[-1].airspeed == pytest.approx(31.3, abs=1.0)  # 60 kt, trimmed
    assert f.link.flight_mode == "MANUAL"


async def test_overrides_move_the_jsbsim_surfaces_through_the_servo_model(tmp_path):
    async with flight(tmp_path) as f:
        await asyncio.sleep(0.3)
        plant, autopilot = f.aircraft.plant, f.aircraft.autopilot
        start = plant.state()["rudder"]
        trace = []

        async def watch():
            while True:
                trace.append((f.clock.now(), plant.state()["rudder"]))
                await asyncio.sleep(0.005)

        f.aircraft.pilot.set_switch(True)  # RCx_OPTION 46: overrides enabled
        watcher = asyncio.create_task(watch(), name="watch")
        t0 = f.clock.now()
        await _override(f.link, {4: 1900}, 0.8)  # rudder: full deflection one way
        watcher.cancel()
        await asyncio.gather(watcher, return_exceptions=True)
        assert autopilot.outputs[4] == 1900
        await f.link.release([4])
        await asyncio.sleep(0.1)
        released = autopilot.outputs[4]
    times, rudder = np.array(trace).T
    final = rudder[-1]
    assert abs(final - start) > 10  # degrees: the surface went over
    # Servo model: 20 ms of dead time, then at most 4 normalised units/s (full ±1 in 0.5 s).
    moved = times[np.abs(rudder - start) > 0.5][0] - t0
    assert moved >= 0.02
    reach = times[np.abs(rudder - final) < 0.05 * abs(final - start)][0] - t0
    assert reach >= 0.02 + 0.8 / 4.0 * 0.9
    assert released == f.aircraft.pilot(0)[3]  # back to the pilot's stick


async def test_a_larger_pwm_rolls_right_pitches_up_and_yaws_right_as_arduplane(tmp_path):
    # ArduPlane's RC inputs rise for roll right, pitch up and yaw right; each is a negative
    # deflection in eq. 3.1's sign (δA right trailing edge down, δE down, δR left), which is
    # what the config's direction −1 on the three surfaces says (docs/excitation.md, "Signs").
    async with flight(tmp_path) as f:
        await asyncio.sleep(0.3)
        plant, pilot = f.aircraft.plant, f.aircraft.pilot
        pilot.set_switch(True)  # RCx_OPTION 46: overrides enabled
        for channel, surface, rate in (
            (1, "aileron", "p"),
            (2, "elevator", "q"),
            (4, "rudder", "r"),
        ):
            before = plant.state()
            await _override(f.link, {channel: pilot.stick(channel) + 200}, 0.3)
            after = plant.state()
            await f.link.release([channel])
            await asyncio.sleep(1.0)  # the pilot's trimmed stick again
            assert after[surface] - before[surface] < -2.0, surface  # degrees, eq. 3.1's sign
            assert after[rate] - before[rate] > 0.01, rate  # rad/s: right, up, right


async def test_overrides_from_a_wrong_system_id_are_ignored(tmp_path):
    async with flight(tmp_path, system_id=200) as f:
        f.aircraft.pilot.set_switch(True)
        await _override(f.link, {1: 1900}, 0.3)
        counters = dict(f.aircraft.autopilot.counters)
        output = f.aircraft.autopilot.outputs[1]
    assert counters["overrides_wrong_sysid"] >= 10
    assert counters.get("overrides", 0) == 0
    assert output == f.aircraft.pilot(0)[0]


async def test_stopped_overrides_return_to_the_pilot_after_rc_override_time(tmp_path):
    params = Params(switch_channel=SWITCH, rc_override_time_s=0.3)
    async with flight(tmp_path, params=params) as f:
        f.aircraft.pilot.set_switch(True)
        stopped = await _override(f.link, {2: 1800}, 0.4)
        clock = f.clock
        assert f.aircraft.autopilot.outputs[2] == 1800
        while f.aircraft.autopilot.outputs[2] == 1800 and clock.now() - stopped < 2.0:
            await asyncio.sleep(0.005)
        lapsed = clock.now() - stopped
    # The emulator stamps an override at its 100 Hz tick: ±10 ms around the 0.3 s.
    assert 0.3 - 0.011 <= lapsed < 0.3 + 0.03
    assert f.aircraft.autopilot.counters["override_timeouts"] >= 1


async def test_the_switch_is_read_and_never_overridden(tmp_path):
    async with flight(tmp_path) as f:
        await asyncio.sleep(0.3)
        assert f.switch[-1][0] < 1700  # the pilot's switch is low
        # Switch low with RCx_OPTION 46: every override is refused by the autopilot.
        await _override(f.link, {1: 1900}, 0.2)
        assert f.aircraft.autopilot.counters["overrides_switch_low"] >= 5
        assert f.aircraft.autopilot.outputs[1] != 1900
        f.aircraft.pilot.set_switch(True)
        await asyncio.sleep(0.2)
        assert f.switch[-1][0] >= 1700  # the driver sees the flip
        with pytest.raises(AutopilotError, match="pilot's switch"):
            await f.link.command({SWITCH: 1000, 1: 1600})
        # Even sent raw, the autopilot never overrides the switch channel.
        for _ in range(10):
            _raw_override(f, {SWITCH: 1000})
            await asyncio.sleep(0.02)
        await asyncio.sleep(0.1)
        assert f.switch[-1][0] >= 1700


async def test_killing_the_autopilot_reports_link_loss_within_the_deadline(tmp_path):
    async with flight(tmp_path, link_timeout_s=0.4) as f:
        await asyncio.sleep(0.5)
        clock = f.clock
        f.tasks[0].cancel()  # the emulator dies mid-run
        killed = clock.now()
        while f.link.connected and clock.now() - killed < 3.0:
            await asyncio.sleep(0.01)
        lost = [t for up, _, t in f.links if not up]
        assert lost, "no link loss reported"
        assert lost[0] - killed <= 0.4 + 0.05 + 0.1  # timeout + watchdog period + one message
        with pytest.raises(AutopilotError, match="no autopilot link"):
            await f.link.command({1: 1500})


async def test_a_run_aborts_when_the_autopilot_link_is_lost(tmp_path):
    from agent.config import Config
    from agent.excitation.plan import preset
    from agent.excitation.scheduler import Scheduler, Window

    async with flight(tmp_path, link_timeout_s=0.4) as f:
        clock = f.clock
        scheduler = Scheduler(Config().excitation, f.link, clock)
        f.on_switch, f.on_state = scheduler.update_switch, scheduler.update_state
        f.on_servos = scheduler.update_servos
        f.on_link = lambda up, why: None if up else scheduler.abort(f"autopilot link: {why}")
        windows: list[Window] = []
        scheduler.subscribe(lambda e: windows.append(e) if isinstance(e, Window) else None)
        f.tasks.append(asyncio.create_task(scheduler.run(), name="scheduler"))
        await asyncio.sleep(0.5)
        scheduler.arm(preset("lateral"))
        f.aircraft.pilot.set_switch(True)
        await asyncio.sleep(1.5)
        assert scheduler.status == "running"
        f.tasks[0].cancel()  # the autopilot goes away mid-run
        killed = clock.now()
        while not windows and clock.now() - killed < 3.0:
            await asyncio.sleep(0.01)
    assert windows[0].outcome == "aborted"
    # Link timeout + watchdog period, plus the trim and release attempts and the scheduling
    # slack of a loaded test process.
    assert windows[0].end - killed < 0.4 + 0.05 + 0.5
    assert "autopilot link" in windows[0].reason or "no autopilot link" in windows[0].reason


def _mavlink_to(f):
    """A ground station's own MAVLink connection to the emulated ArduPlane (pymavlink, UDP)."""
    from pymavlink import mavutil

    host, port = f.aircraft.mavlink_address
    gcs = mavutil.mavlink_connection(f"udpout:{host}:{port}", source_system=255)
    gcs.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    return gcs


async def _receive(gcs, kind: str, seconds: float, **match):
    """The first `kind` message matching `match` within `seconds`, else None."""
    deadline = asyncio.get_running_loop().time() + seconds
    while asyncio.get_running_loop().time() < deadline:
        m = gcs.recv_match(type=kind, blocking=False)
        if m is None:
            await asyncio.sleep(0.01)
        elif all(getattr(m, k) == v for k, v in match.items()):
            return m
    return None


async def test_fbwa_holds_the_bank_the_stick_asks_for(tmp_path):
    # MAV_CMD_DO_SET_MODE to FBWA (custom mode 5) over UDP, acknowledged, the heartbeat
    # saying so; then the roll stick, overridden to ask for 20° of bank, banks the JSBSim Cub
    # there through ArduPlane's laws and its default gains, and released, levels it. Bad input
    # tried: a mode ArduPlane has but this emulation does not fly (AUTO, 10): refused.
    async with flight(tmp_path) as f:
        gcs = _mavlink_to(f)
        try:
            for mode, result in ((10, mavlink.MAV_RESULT_FAILED), (5, mavlink.MAV_RESULT_ACCEPTED)):
                gcs.mav.command_long_send(
                    1, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, 1, mode, 0, 0, 0, 0, 0
                )
                ack = await _receive(gcs, "COMMAND_ACK", 2.0, command=mavlink.MAV_CMD_DO_SET_MODE)
                assert ack is not None, mode
                assert ack.result == result, mode
            beat = await _receive(gcs, "HEARTBEAT", 2.5, custom_mode=5)
            assert beat is not None
            assert beat.base_mode & mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
        finally:
            gcs.close()
        ap = f.aircraft.autopilot
        f.aircraft.pilot.set_switch(True)
        stick = ap.rc_trim[1] + round(400 * 20 / 45)
        await _override(f.link, {1: stick}, 6.0)
        banked = np.degrees(f.aircraft.truth["phi"])
        demand = ap.surfaces["roll_demand"]
        await f.link.release([1])
        await asyncio.sleep(6.0)
        level = np.degrees(f.aircraft.truth["phi"])
    assert demand == pytest.approx(20.0, abs=0.5)
    assert banked == pytest.approx(20.0, abs=3.0)
    assert abs(level) < 3.0


async def test_parameters_are_read_and_set_by_name_over_mavlink(tmp_path):
    # PARAM_REQUEST_READ, PARAM_SET and PARAM_REQUEST_LIST as a ground station sends them, the
    # answers as ArduPlane gives them. Bad input tried: a PARAM_SET of a name the vehicle does
    # not have (no answer, counted), a NaN value (refused, the old value kept).
    from agent.fbwa import DEFAULTS

    async with flight(tmp_path) as f:
        gcs = _mavlink_to(f)
        try:
            gcs.mav.param_request_read_send(1, 1, b"RLL_RATE_FF", -1)
            value = await _receive(gcs, "PARAM_VALUE", 2.0, param_id="RLL_RATE_FF")
            assert value is not None
            assert value.param_value == pytest.approx(0.345)
            assert value.param_type == mavlink.MAV_PARAM_TYPE_REAL32
            assert value.param_count == len(DEFAULTS)
            gcs.mav.param_request_read_send(1, 1, b"RLL2SRV_RMAX", -1)
            value = await _receive(gcs, "PARAM_VALUE", 2.0, param_id="RLL2SRV_RMAX")
            assert value is not None
            assert value.param_type == mavlink.MAV_PARAM_TYPE_INT16
            gcs.mav.param_set_send(1, 1, b"RLL_RATE_FF", 0.5, mavlink.MAV_PARAM_TYPE_REAL32)
            value = await _receive(gcs, "PARAM_VALUE", 2.0, param_id="RLL_RATE_FF")
            assert value is not None
            assert value.param_value == pytest.approx(0.5)
            assert f.aircraft.autopilot.fbwa.roll.pid.kff == pytest.approx(0.5)
            for name, bad in ((b"RLL_RATE_XX", 1.0), (b"RLL_RATE_FF", float("nan"))):
                gcs.mav.param_set_send(1, 1, name, bad, mavlink.MAV_PARAM_TYPE_REAL32)
            assert await _receive(gcs, "PARAM_VALUE", 0.5) is None
            assert f.aircraft.autopilot.counters["params_refused"] == 2
            assert f.aircraft.autopilot.fbwa.params["RLL_RATE_FF"] == pytest.approx(0.5)
            gcs.mav.param_request_list_send(1, 1)
            seen = {}
            while len(seen) < len(DEFAULTS):
                value = await _receive(gcs, "PARAM_VALUE", 2.0)
                assert value is not None, sorted(set(DEFAULTS) - set(seen))
                seen[value.param_id] = value.param_index
            assert sorted(seen.values()) == list(range(len(DEFAULTS)))
        finally:
            gcs.close()


async def test_the_driver_sets_reads_back_and_reverts_parameters_over_mavsdk(tmp_path):
    # The agent's way (MAVSDK's param plugin): set two of ArduPlane's rate gains, read them
    # back, then put the old ones back (a revert). Bad input tried: a name the autopilot does
    # not have (refused by name, the rest not sent), every PARAM_SET lost on the way with
    # the link up (refused: timeout), and a cut link (refused, nothing claimed).
    async with flight(tmp_path) as f:
        ap = f.aircraft.autopilot
        old = await f.link.parameters(["RLL_RATE_FF", "RLL_RATE_P"])
        assert old == {"RLL_RATE_FF": pytest.approx(0.345), "RLL_RATE_P": pytest.approx(0.08)}
        new = {"RLL_RATE_FF": 0.5, "RLL_RATE_P": 0.2}
        read = await f.link.set_parameters(new)
        assert read == {k: pytest.approx(v) for k, v in new.items()}
        assert ap.fbwa.params["RLL_RATE_FF"] == pytest.approx(0.5)
        assert ap.fbwa.roll.pid.kp == pytest.approx(0.2)
        await f.link.set_parameters(old)
        assert ap.fbwa.params["RLL_RATE_P"] == pytest.approx(0.08)
        # ArduPlane answers no PARAM_SET of a name it lacks: MAVSDK times out as for a lost
        # one, and the rest are not sent (each would wait as long).
        with pytest.raises(AutopilotError, match=r"RLL_RATE_XX \(timeout\).*RLL_RATE_I not sent"):
            await f.link.set_parameters({"RLL_RATE_XX": 1.0, "RLL_RATE_I": 0.2})
        assert ap.fbwa.params["RLL_RATE_I"] == pytest.approx(0.15)
        await f.link.set_parameters({"RLL_RATE_I": 0.2})
        assert ap.fbwa.params["RLL_RATE_I"] == pytest.approx(0.2)
        # ArduPlane's integer parameters (AP_Int16: the rate limits), which MAVSDK refuses to
        # read or set as floats: read and set as integers, a value rounded, not truncated.
        assert await f.link.parameters(["RLL2SRV_RMAX"]) == {"RLL2SRV_RMAX": 0.0}
        read = await f.link.set_parameters({"RLL2SRV_RMAX": 30.0, "PTCH2SRV_RMAX_UP": 12.7})
        assert read == {"RLL2SRV_RMAX": 30.0, "PTCH2SRV_RMAX_UP": 13.0}
        assert ap.fbwa.params["PTCH2SRV_RMAX_UP"] == 13.0
        ap.drop_param_sets = True  # every PARAM_SET lost on the way, telemetry still flowing
        with pytest.raises(AutopilotError, match=r"PTCH_RATE_FF \(timeout\)"):
            await f.link.set_parameters({"PTCH_RATE_FF": 0.9})
        ap.drop_param_sets = False
        assert ap.counters["params_dropped"] >= 1
        ap.link_up = False  # the telemetry radio lost: refused, nothing claimed
        with pytest.raises(AutopilotError, match=r"PTCH_RATE_FF|no autopilot link"):
            await f.link.set_parameters({"PTCH_RATE_FF": 0.9})
        ap.link_up = True
    assert ap.fbwa.params["PTCH_RATE_FF"] == pytest.approx(0.345)


async def test_in_fbwa_a_plan_plays_on_the_sticks_and_the_laws_fly_the_surfaces(tmp_path):
    """The scheduler with the real driver against the emulated ArduPlane in FBWA: trim is the
    pilot's stick (RC_CHANNELS), the aileron doublet's overrides are bank demands about it,
    ArduPlane's laws move the surface and bank the JSBSim Cub, and after the run the stick is
    the pilot's again: the demand back at wings level."""
    from agent.config import Config
    from agent.excitation.plan import preset
    from agent.excitation.scheduler import Event, Scheduler, Window

    async with flight(tmp_path) as f:
        ap = f.aircraft.autopilot
        assert ap.set_mode(5)
        scheduler = Scheduler(Config().excitation, f.link, f.clock)
        f.on_switch, f.on_state = scheduler.update_switch, scheduler.update_state
        f.on_servos, f.on_sticks = scheduler.update_servos, scheduler.update_sticks
        events: list = []
        scheduler.subscribe(events.append)
        f.tasks.append(asyncio.create_task(scheduler.run(), name="scheduler"))
        while f.link.flight_mode != "FBWA":
            await asyncio.sleep(0.05)
        await asyncio.sleep(1.0)  # a trim window of sticks
        plan = preset("lateral")
        scheduler.arm(plan)
        f.aircraft.pilot.set_switch(True)
        demands, banks = [], []
        while not any(isinstance(e, Window) for e in events):
            demands.append(ap.surfaces.get("roll_demand", 0.0))
            banks.append(np.degrees(f.aircraft.truth["phi"]))
            await asyncio.sleep(0.02)
        f.aircraft.pilot.set_switch(False)
        await asyncio.sleep(1.0)
        after = ap.surfaces["roll_demand"]
    started = next(e for e in events if isinstance(e, Event) and e.kind == "started")
    assert "the sticks': FBWA" in started.detail
    window = next(e for e in events if isinstance(e, Window))
    assert window.outcome == "finished"
    # The 4° aileron doublet at 20 µs per degree is ±80 µs of stick: ±9° of bank demanded
    # (the stick's ±400 µs, RCn_MIN…MAX about its trim, for ROLL_LIMIT_DEG 45°), about wings
    # level.
    assert max(demands) == pytest.approx(9.0, abs=0.5)
    assert min(demands) == pytest.approx(-9.0, abs=0.5)
    assert np.max(np.abs(banks)) > 3.0  # the laws flew it
    assert abs(after) < 0.5
