"""The JSBSim plant: trim, linearisation truth, flying, turbulence seeds, bad requests.

Real JSBSim (the pip package and its J-3 Cub), no stand-ins.
"""

from __future__ import annotations

import numpy as np
import pytest

from agent.sim.plant import INPUTS, LINEAR_INPUTS, LINEAR_STATES, OUTPUTS, Plant, PlantError

DT = 0.02


@pytest.fixture(scope="module")
def cub():
    return Plant()


def test_trim_and_linearisation_leave_a_flying_simulation(cub):
    assert 0.0 < cub.trim["throttle"] < 1.0
    # FGLinearization sets the step to 0; the plant restores it, so time advances.
    assert cub.dt == pytest.approx(1 / 200)
    start = cub.time
    cub.fly(np.zeros((10, len(INPUTS))), DT)
    assert cub.time == pytest.approx(start + 10 * DT)
    lin = cub.linearisation
    assert lin.A.shape == (len(lin.state_names),) * 2
    assert {LINEAR_STATES[o] for o in OUTPUTS} <= set(lin.state_names)
    assert {LINEAR_INPUTS[i] for i in INPUTS} <= set(lin.input_names)


def test_linearisation_has_the_aircraft_modes():
    lam = Plant().linearisation.eigenvalues()
    pairs = lam[lam.imag > 1e-6]
    # A Dutch roll (ωn 1–4 rad/s) and a phugoid (ωn < 0.6 rad/s), both stable.
    assert any(1.0 < abs(s) < 4.0 and s.real < 0 for s in pairs)
    assert any(abs(s) < 0.6 and s.real < 0 for s in pairs)


def test_trimmed_flight_stays_trimmed_without_inputs():
    plant = Plant()
    y = plant.fly(np.zeros((500, len(INPUTS))), DT)
    drift = np.abs(y - y[0]).max(axis=0)
    assert drift[OUTPUTS.index("Vt")] < 0.05  # m/s over 10 s
    assert drift[OUTPUTS.index("q")] < 1e-3


def test_elevator_response_has_the_sign_of_the_linearisation():
    plant = Plant()
    lin = plant.linearisation
    b = lin.B[lin.state_names.index("Q"), lin.input_names.index("DeCmd")]
    u = np.zeros((50, len(INPUTS)))
    u[5:, INPUTS.index("elevator")] = 0.05
    y = plant.fly(u, DT)
    dq = y[10, OUTPUTS.index("q")] - y[0, OUTPUTS.index("q")]
    assert np.sign(dq) == np.sign(b)
    assert abs(dq) > 1e-4


def test_turbulence_is_repeatable_per_seed_and_differs_between_seeds():
    u = np.zeros((300, len(INPUTS)))
    a = Plant(turbulence=1.0, seed=3).fly(u, DT)
    b = Plant(turbulence=1.0, seed=3).fly(u, DT)
    c = Plant(turbulence=1.0, seed=4).fly(u, DT)
    assert np.array_equal(a, b)
    assert not np.allclose(a, c)
    assert np.std(a[:, OUTPUTS.index("p")]) > 1e-3  # it is felt


def test_bad_requests_are_refused_with_the_reason(cub):
    """Bad input tried: an aircraft JSBSim does not have; a sample time that is not a whole
    number of integration steps."""
    with pytest.raises(PlantError, match="no aircraft"):
        Plant("NoSuchPlane")
    with pytest.raises(PlantError, match="whole number"):
        cub.fly(np.zeros((2, len(INPUTS))), 0.0123)


def test_jsbsims_banner_stays_off_stdout():
    # `--json` promises one JSON object on stdout; JSBSim's C++ prints a banner on creation.
    import subprocess
    import sys

    code = "from agent.sim.plant import Plant; Plant(); print('{\"ok\": 1}')"
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    assert done.stdout == '{"ok": 1}\n'
    assert "JSBSim" in done.stderr  # moved, not lost


def test_sim_json_on_an_aircraft_jsbsim_does_not_have_is_one_error_object():
    # Bad input: `sysid sim --aircraft no-such-aircraft --json`; stdout is still one object.
    import json
    import subprocess
    import sys

    command = [sys.executable, "-m", "agent", "sim", "--aircraft", "no-such-aircraft", "--json"]
    done = subprocess.run(command, capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 2
    assert done.stdout.count("\n") == 1  # one line: JSBSim's banner and errors went to stderr
    error = json.loads(done.stdout)["error"]
    assert error == {
        "kind": "error",
        "exit": 2,
        "message": "JSBSim has no aircraft 'no-such-aircraft' (sysid sim --list-aircraft)",
    }


def test_the_attitude_keeps_step_with_the_body_rates():
    # JSBSim's default rectangular Euler for the rotation left θ half a step (2.5 ms) behind
    # the rates: θ̇ − (q cos φ − r sin φ) was 1.6 % of θ̇ on a surface multisine. With the
    # plant's second-order integrators it is below 0.1 %.
    plant = Plant(linearise=False)
    t = np.arange(2000) * plant.dt
    theta, q, r, phi = (np.empty(len(t)) for _ in range(4))
    for k, time in enumerate(t):
        plant.command(
            {
                "elevator": 0.05 * np.sin(2 * np.pi * 1.1 * time),
                "aileron": 0.05 * np.sin(2 * np.pi * 0.7 * time),
            }
        )
        plant.step()
        s = plant.state()
        theta[k], q[k], r[k], phi[k] = s["theta"], s["q"], s["r"], s["phi"]
    rate = (theta[2:] - theta[:-2]) / (2 * plant.dt)
    kinematic = (q * np.cos(phi) - r * np.sin(phi))[1:-1]
    assert np.std(rate - kinematic) < 1e-3 * np.std(rate)


def test_a_servo_moves_its_surface_along_a_ramp_and_the_state_reads_it_there():
    # Over a 4-step ramp the surface reads halfway after 2 steps and at the command after 4;
    # a jump held over the tick instead would read the end value at once.
    plant = Plant(linearise=False)
    start = plant.state()["elevator"]
    target = plant.trim["elevator"] + 0.1
    plant.set_normalised({"elevator": target}, steps=4)
    plant.step()
    plant.step()
    halfway = plant.state()["elevator"]
    plant.step()
    plant.step()
    end = plant.state()["elevator"]
    assert end != pytest.approx(start)
    assert halfway == pytest.approx((start + end) / 2, rel=1e-6)
    plant.step()  # the ramp over, the surface stays
    assert plant.state()["elevator"] == pytest.approx(end, rel=1e-9)
    with pytest.raises(PlantError, match="at least one step"):
        plant.set_normalised({"elevator": target}, steps=0)


def test_the_pitch_gust_is_the_vertical_gusts_gradient_along_the_path_at_any_heading():
    # MIL-F-8785C: q_g = s (w_g / V) / (1 + τ s), τ = 4b/(πV). JSBSim makes its gusts in the
    # mean wind's axes (north without wind) and turns its roll and pitch gusts into body axes
    # by the heading, so heading 60° the pitch gust was mostly the independent roll gust (18 %
    # explained on the Cub). The plant keeps the gusts' axes on the aircraft's heading.
    plant = Plant(turbulence=1.0, seed=5, heading_deg=60.0, linearise=False)
    n = 8000  # 40 s at 200 Hz
    q_gust, w_gust, speed = np.empty(n), np.empty(n), np.empty(n)
    for k in range(n):
        plant.step()
        f = plant.fdm
        q_gust[k] = f["atmosphere/q-turb-rad_sec"]
        w_gust[k] = f["atmosphere/turb-down-fps"]
        speed[k] = f["velocities/vt-fps"]
    span = plant.fdm["metrics/bw-ft"]
    tau = 4 * span / np.pi / speed.mean()
    s = 2j * np.pi * np.fft.rfftfreq(n, plant.dt)
    model = s * np.fft.rfft(w_gust / speed) / (1 + tau * s)
    measured = np.fft.rfft(q_gust)
    band = (np.abs(s) > 0.3) & (np.abs(s) < 20)
    gain = np.vdot(model[band], measured[band]) / np.vdot(model[band], model[band])
    rest = measured[band] - gain * model[band]
    assert 1 - np.sum(np.abs(rest) ** 2) / np.sum(np.abs(measured[band]) ** 2) > 0.9
    assert abs(gain - 1) < 0.1


def test_a_glider_trims_in_a_steady_glide_and_has_no_throttle():
    """JSBSim's SGS 1-26 has no engine: JSBSim's own trim refuses it (u̇ needs a throttle), and
    its FGLinearization crashes the process on it. Trimmed in a glide, it stays there; a
    throttle command moves nothing, and no engine speed is reported."""
    glider = Plant("sgs126", airspeed_kts=50.0, altitude_ft=3000.0)
    assert glider.kind == "none"
    assert glider.engines == 0
    assert glider.linearisation is None
    assert -5.0 < glider.glide_deg < -1.0  # a glide, about L/D 23
    start = glider.state()
    # Its true airspeed at 3000 ft is what its air data measure, above the 50 kt (25.7 m/s)
    # calibrated airspeed it was trimmed at by the density's ratio (√(ρ0/ρ) = 1.045):
    # the envelope is taken about it.
    assert glider.true_airspeed == pytest.approx(start["Vt"], rel=1e-6)
    assert glider.true_airspeed == pytest.approx(50.0 * 0.514444 * 1.045, rel=0.01)
    assert "rpm" not in start
    glider.fly(np.tile([0.5, 0.0, 0.0, 0.0], (500, 1)), DT)  # 10 s, the throttle "open"
    after = glider.state()
    assert after["Vt"] == pytest.approx(start["Vt"], rel=0.01)
    assert after["theta"] == pytest.approx(start["theta"], abs=np.radians(0.2))
    sink = (start["alt"] - after["alt"]) / 10.0
    assert sink == pytest.approx(start["Vt"] * np.sin(np.radians(-glider.glide_deg)), rel=0.1)


def test_a_turbine_moves_on_every_engine_and_reports_no_engine_speed():
    """JSBSim's T-6 (direct thrust, N1/N2 spools) has no `engine-rpm`: the plant must not
    ask for one (sysid sim ended in a KeyError on it)."""
    t6 = Plant("t6texan2", airspeed_kts=150.0, linearise=False)
    assert t6.kind == "turbine"
    assert "rpm" not in t6.state()
    before = float(t6.fdm["propulsion/engine/thrust-lbs"])
    t6.fly(np.tile([0.05, 0.0, 0.0, 0.0], (25, 1)), DT)
    assert float(t6.fdm["propulsion/engine/thrust-lbs"]) > 1.05 * before


def test_a_twin_trims_with_both_engines_running():
    """JSBSim's C310 (two pistons) leaves its second engine's mixture lean: untouched, its
    trim at 100 kt failed ("udot doesn't appear to be trimmable", the second engine at 0 rpm).
    Both engines run, at one throttle, and it stays trimmed."""
    twin = Plant("c310", airspeed_kts=100.0, linearise=False)
    assert (twin.kind, twin.engines) == ("piston", 2)
    rpm = [float(twin.fdm[f"propulsion/engine[{k}]/engine-rpm"]) for k in range(2)]
    assert min(rpm) > 1000.0
    assert rpm[1] == pytest.approx(rpm[0], rel=0.01)
    start = twin.state()
    twin.fly(np.tile([0.0, 0.0, 0.0, 0.0], (250, 1)), DT)  # 5 s at the trim
    assert twin.state()["Vt"] == pytest.approx(start["Vt"], rel=0.01)


@pytest.mark.parametrize(("aircraft", "speed"), [("pc7", 150.0), ("DHC6", 130.0)])
def test_a_turboprop_is_trimmed_with_its_engines_running_and_stays_trimmed(aircraft, speed):
    """JSBSim's turboprop engine (FGTurboProp) gives no power while time is frozen and drops
    to idle at the first step after a frozen evaluation: JSBSim's trim failed on the PC-7
    ("udot doesn't appear to be trimmable"), and the DHC-6 it trimmed lost 9 kt in 6 s at idle
    power once the surfaces were read between steps. Both fly level, their gas generators at
    power, through 20 s of ramps read as the sensors read them."""
    plant = Plant(aircraft, airspeed_kts=speed, linearise=False)
    assert plant.kind == "turboprop"
    n1 = [f"propulsion/engine[{k}]/n1" for k in range(plant.engines)]
    start, power = plant.state(), [float(plant.fdm[p]) for p in n1]
    assert min(power) > 75.0  # idle is 60 %
    for k in range(4000):
        if k % 4 == 0:  # a servo's ramp each 50 Hz tick, the state read inside it
            plant.set_normalised({"elevator": plant.trim["elevator"]}, steps=2)
            plant.state()
        plant.step()
    after = plant.state()
    assert after["Vt"] == pytest.approx(start["Vt"], abs=0.2)  # m/s over 20 s
    assert after["theta"] == pytest.approx(start["theta"], abs=np.radians(0.2))
    assert after["phi"] == pytest.approx(start["phi"], abs=np.radians(0.5))
    assert [float(plant.fdm[p]) for p in n1] == pytest.approx(power, abs=0.1)
    assert after["rpm"] > 1000.0


def test_an_aircraft_neither_trim_can_fly_level_is_refused_with_both_named():
    """Bad input: JSBSim's P-51D at 200 kt, whose engine does not turn without FlightGear's
    systems (0 rpm at any throttle). JSBSim's trim fails ("udot doesn't appear to be
    trimmable"), the plant's own is tried and fails too: one PlantError that says so, with
    the accelerations left, and nothing on stdout."""
    with pytest.raises(PlantError, match="JSBSim's own trim failed too") as caught:
        Plant("p51d", airspeed_kts=200.0, linearise=False)
    assert "residual accelerations" in str(caught.value)


def test_a_turboprops_surfaces_are_read_along_the_ramp_without_idling_its_engine():
    # The same ramp as the Cub's above: read from the plant's map of its flight controls,
    # the positions match where JSBSim puts the surfaces once a step has flown them.
    plant = Plant("pc7", airspeed_kts=150.0, linearise=False)
    n1 = float(plant.fdm["propulsion/engine/n1"])
    start = plant.state()["elevator"]
    plant.set_normalised({"elevator": plant.trim["elevator"] + 0.1}, steps=4)
    plant.step()
    plant.step()
    halfway = plant.state()["elevator"]
    plant.step()
    plant.step()
    end = plant.state()["elevator"]  # the map's
    assert end != pytest.approx(start)
    assert halfway == pytest.approx((start + end) / 2, rel=1e-6)
    plant.step()  # the ramp over: JSBSim's own
    assert plant.state()["elevator"] == pytest.approx(end, rel=1e-9)
    assert float(plant.fdm["propulsion/engine/n1"]) == pytest.approx(n1, abs=0.05)


def sim_error(*args: str) -> tuple[int, dict]:
    """`sysid sim ARGS --json` that fails: its exit code and its one object's error (stdout
    holds that one line: JSBSim's banner and complaints go to stderr)."""
    import json
    import subprocess
    import sys

    command = [sys.executable, "-m", "agent", "sim", *args, "--json"]
    done = subprocess.run(command, capture_output=True, text=True, timeout=120, check=False)
    assert done.stdout.count("\n") == 1, done.stdout
    return done.returncode, json.loads(done.stdout)["error"]


def test_an_aircraft_that_needs_flightgear_is_refused_by_name_with_one_json_object():
    """Bad input: JSBSim's Fokker Dr.I reads a property only FlightGear provides (its
    pushback) and JSBSim raises at its initial conditions; that was an internal error, with
    JSBSim's complaint on stdout before the JSON."""
    with pytest.raises(PlantError, match="FlightGear"):
        Plant("dr1", airspeed_kts=70.0, linearise=False)
    code, error = sim_error("--aircraft", "dr1", "--speed-kts", "70")
    assert code == 2
    assert error["kind"] == "error"
    assert "pushback" in error["message"]
    assert "FlightGear" in error["message"]


def test_a_flight_that_reaches_the_ground_ends_at_once_saying_so():
    """Bad input: a glider trimmed 20 ft above the ground (`--altitude-ft 20`). JSBSim flies on
    through the terrain after a hard impact; `sysid sim` then waited out its deadlines with its
    sensors gone and blamed a busy machine (a DHC-6 whose engine idled dived in at 23 s and the
    flight ended after 981 s). Now it ends when the aircraft is down, and says so."""
    code, error = sim_error("--aircraft", "sgs126", "--altitude-ft", "20")
    assert code == 1
    assert "the simulated aircraft stopped: it touched the ground" in error["message"]
    assert "busy" not in error["message"]
