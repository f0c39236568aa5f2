"""`sysid tune`'s design (agent.tune) on known linear aircraft, and the command.

Bad input tried: a linkage whose sign turns the aileron against the roll (refused by name), a
model without the axis's surface (refused by name), an output file that is the model itself,
an output that is not .param, a --linkage without a gain, a servo lag of 5 s, a negative time
constant, a scaling speed of 0, a model file that is not JSON."""

from __future__ import annotations

import json

import numpy as np
import pytest

from agent.cli import main
from agent.config import Config
from agent.fbwa import DEFAULTS
from agent.tune import (
    DUTCH_ROLL_TARGET,
    GAIN_MARGIN_DB,
    PHASE_MARGIN,
    RATE_SHARE,
    Actuator,
    Model,
    TuneError,
    assess,
    axis_plant,
    design_axis,
    notional_link,
    param_file,
    step_trace,
    toward,
)
from agent.tune import design as design_from
from tests.documents import continuous_document

# A roll axis: ṗ = L_p p + L_δa δa, φ̇ = p (δa in measured degrees, L_δa per degree).
OUTPUTS = ("p", "phi")
INPUTS = ("aileron",)


def roll_model(L_p: float = -5.0, L_da: float = 0.3):
    return {"A": [[L_p, 0.0], [1.0, 0.0]], "B": [[L_da], [0.0]], "C": np.eye(2)}


def roll_plant(**kw):
    return axis_plant(
        roll_model(**kw),
        INPUTS,
        OUTPUTS,
        surface="aileron",
        rate="p",
        angle="phi",
        axis_outputs=OUTPUTS,
        slow=("phi",),
    )


def design(lag_s=0.05, link=0.5, **kw):
    return design_axis(
        "roll", roll_plant(**kw), Actuator(link=link, lag_s=lag_s), eas=20.0, scaling_speed=20.0
    )


def test_the_feed_forward_flies_the_demanded_rate_and_the_loops_keep_their_margins():
    tune = design()
    # Steady roll rate per notional degree: L_δa / |L_p| · link = 0.3/5 rad/s per degree …
    per_degree = np.degrees(0.3 / 5.0) * 0.5
    assert tune.params["RLL_RATE_FF"] == pytest.approx(1 / per_degree, rel=1e-3)
    assert tune.rate_loop.phase_deg >= PHASE_MARGIN
    assert tune.attitude_loop.phase_deg >= PHASE_MARGIN
    assert tune.attitude_loop.gain_db >= GAIN_MARGIN_DB
    assert tune.attitude_loop.rejection_rad_s > 0
    assert 0 < tune.overshoot_pct < 10
    assert 0.2 < tune.rise_s < 3.0


def test_the_rate_limit_is_the_rate_flown_with_part_of_the_servos_travel():
    """RMAX: the steady rate at RATE_SHARE of the ±45° travel, whole degrees per second; a
    surface twice as strong flies twice the rate before it saturates."""
    per_degree = np.degrees(0.3 / 5.0) * 0.5  # deg/s per notional degree (above)
    tune = design()
    assert tune.params["RLL2SRV_RMAX"] == np.floor(RATE_SHARE * per_degree * 45.0)
    assert 0 < tune.params["RLL2SRV_RMAX"] < 20.0 / tune.params["RLL2SRV_TCONST"]
    strong = design(L_da=0.6)
    assert strong.params["RLL2SRV_RMAX"] == pytest.approx(2 * tune.params["RLL2SRV_RMAX"], abs=1)


def test_a_linkage_with_more_travel_one_way_is_designed_for_each_way():
    """Differential travel (agent.excitation.follow's even part: 0.6 per degree one way, 0.4
    the other): the loop shaped and its margins kept on the stronger way (P, I and TCONST as
    a symmetric linkage of 0.6 gives), the feed-forward on the mean (FF as 0.5's), RMAX from
    the weaker way, and each way's step predicted: the weaker one slower."""
    plant = roll_plant()
    even = design_axis("roll", plant, Actuator(link=0.5, even=0.1), eas=20.0, scaling_speed=20.0)
    strong = design(link=0.6)
    mean, weak = design(link=0.5), design(link=0.4)
    for name in ("RLL_RATE_P", "RLL_RATE_I", "RLL2SRV_TCONST"):
        assert even.params[name] == pytest.approx(strong.params[name], rel=1e-3), name
    assert even.params["RLL_RATE_FF"] == pytest.approx(mean.params["RLL_RATE_FF"], rel=1e-3)
    assert even.params["RLL2SRV_RMAX"] == weak.params["RLL2SRV_RMAX"]
    assert even.params["RLL2SRV_RMAX"] < strong.params["RLL2SRV_RMAX"]
    assert even.attitude_loop.gain_db >= GAIN_MARGIN_DB
    assert even.attitude_loop.gain_db == pytest.approx(strong.attitude_loop.gain_db, abs=0.05)
    # Each way its own step: the weaker way starts slower (half a second in, less of the
    # bank), and a linkage mirrored (more travel for a negative output) mirrors the steps.
    assert even.down is not None
    assert mean.down is None
    assert mean.each_way()["−"] == mean.each_way()["+"]
    actuator = Actuator(link=0.5, even=0.1)
    at_half = {
        sign: step_trace("roll", plant, actuator, even.params, 20.0, 1.0, 20.0, sign=sign)[1][500]
        for sign in (1, -1)
    }
    assert at_half[-1] < 0.95 * at_half[1], at_half
    mirrored = design_axis(
        "roll", plant, Actuator(link=0.5, even=-0.1), eas=20.0, scaling_speed=20.0
    )
    assert mirrored.params == even.params
    assert mirrored.each_way()["+"] == pytest.approx(even.each_way()["−"])
    assert mirrored.each_way()["−"] == pytest.approx(even.each_way()["+"])


def test_the_pitch_rate_limits_each_come_from_their_own_way():
    """PTCH2SRV_RMAX_UP from the travel a positive (nose-up) output has, RMAX_DN from the
    other's: an elevator with more up travel than down allows more pitch-up rate."""
    model = {"A": [[-4.0, 0.0], [1.0, 0.0]], "B": [[0.4], [0.0]], "C": np.eye(2)}
    plant = axis_plant(
        model,
        INPUTS,
        ("q", "theta"),
        surface="aileron",
        rate="q",
        angle="theta",
        axis_outputs=("q", "theta"),
        slow=("theta",),
    )
    tune = design_axis("pitch", plant, Actuator(link=0.5, even=0.2), eas=20.0, scaling_speed=20.0)
    per_degree = np.degrees(0.4 / 4.0)
    up, down = tune.params["PTCH2SRV_RMAX_UP"], tune.params["PTCH2SRV_RMAX_DN"]
    assert up == np.floor(RATE_SHARE * per_degree * 0.7 * 45.0)
    assert down == np.floor(RATE_SHARE * per_degree * 0.3 * 45.0)
    # A knee away from trim (5° of nose-down output): the travel beyond it counts at its own
    # rate, RMAX from the secant over RATE_SHARE of the travel each way.
    kneed = design_axis(
        "pitch", plant, Actuator(link=0.5, even=0.2, knee=-5.0), eas=20.0, scaling_speed=20.0
    )
    output = RATE_SHARE * 45.0
    up_moved = 0.7 * output  # above the knee all the way
    down_moved = 0.7 * 5.0 + 0.3 * (output - 5.0)  # 0.7 to the knee, 0.3 beyond
    assert kneed.params["PTCH2SRV_RMAX_UP"] == np.floor(per_degree * up_moved)
    assert kneed.params["PTCH2SRV_RMAX_DN"] == np.floor(per_degree * down_moved)
    assert kneed.params["PTCH2SRV_RMAX_DN"] > down
    with pytest.raises(TuneError, match="would not move one way"):
        design_axis("pitch", plant, Actuator(link=0.5, even=0.5), eas=20.0, scaling_speed=20.0)


def test_a_slower_servo_gets_less_rate_gain_and_a_lower_crossover():
    # ArduPlane's AUTOTUNE limit-cycles on slow servos (ArduPilot issue 17900): the design sees
    # the servo's lag in its margins.
    fast, slow = design(lag_s=0.02), design(lag_s=0.15)
    assert slow.params["RLL_RATE_P"] < fast.params["RLL_RATE_P"]
    assert slow.rate_loop.crossover_rad_s < fast.rate_loop.crossover_rad_s
    assert slow.attitude_loop.phase_deg >= PHASE_MARGIN


def test_a_demanded_time_constant_the_rate_loop_cannot_carry_is_lengthened_and_said():
    tune = design_axis(
        "roll",
        roll_plant(L_p=-1.0),
        Actuator(link=0.5, lag_s=0.1),
        eas=20.0,
        scaling_speed=20.0,
        tconst=0.1,
    )
    assert tune.params["RLL2SRV_TCONST"] > 0.1
    assert any("TCONST" in note and "not 0.1" in note for note in tune.notes)


def test_a_set_of_gains_is_assessed_as_the_design_predicts_its_own():
    """The design's gains assessed again give its margins and step; a set whose P is ten
    times the design's (a limit cycle on a real aircraft) is not sound."""
    plant, actuator = roll_plant(), Actuator(link=0.5, lag_s=0.05)
    tune = design_axis("roll", plant, actuator, eas=20.0, scaling_speed=20.0)
    again = assess("roll", plant, actuator, tune.params, eas=20.0, scaling_speed=20.0)
    assert again.sound()
    # (the parameters are rounded as ArduPlane takes them)
    assert again.attitude_loop.phase_deg == pytest.approx(tune.attitude_loop.phase_deg, rel=1e-3)
    assert again.rise_s == pytest.approx(tune.rise_s, rel=1e-3)
    hot = {**tune.params, "RLL_RATE_P": 10 * tune.params["RLL_RATE_P"]}
    assert not assess("roll", plant, actuator, hot, eas=20.0, scaling_speed=20.0).sound()


def test_a_step_toward_the_design_changes_no_gain_by_more_than_the_limit():
    """From ArduPlane's defaults to a design whose FF is several times theirs: with the limit
    ×2 every gain moves the same share of the way, none by more than ×2, and the set it
    stops at keeps the margins; with a limit the change fits in, the design itself."""
    plant, actuator = roll_plant(L_da=0.05), Actuator(link=0.5, lag_s=0.05)
    tune = design_axis("roll", plant, actuator, eas=20.0, scaling_speed=20.0)
    current = {n: DEFAULTS[n] for n in tune.params}
    ratio = max(
        max(tune.params[n], current[n]) / min(tune.params[n], current[n])
        for n in tune.params
        if tune.params[n] > 0 and current[n] > 0
    )
    assert ratio > 2.5
    step = toward(
        "roll", plant, actuator, current, tune.params, eas=20.0, scaling_speed=20.0, max_step=2.0
    )
    assert 0 < step.share < 1
    assert step.assessed.sound()
    for n, v in step.params.items():
        if current[n] > 0 and v > 0:
            assert 1 / 2.0001 <= v / current[n] <= 2.0001, n
    # The rate limit is set as designed at once (from ArduPlane's 0, no limit): a share of
    # it would limit harder than the design.
    assert current["RLL2SRV_RMAX"] == 0
    assert step.params["RLL2SRV_RMAX"] == tune.params["RLL2SRV_RMAX"] > 0
    whole = toward(
        "roll",
        plant,
        actuator,
        current,
        tune.params,
        eas=20.0,
        scaling_speed=20.0,
        max_step=ratio * 1.01,
    )
    assert whole.share == pytest.approx(1.0)
    assert whole.params == pytest.approx(tune.params, rel=1e-3)


def test_a_reversed_linkage_or_a_missing_surface_is_refused_by_name():
    with pytest.raises(TuneError, match="linkage sign"):
        design(link=-0.5)
    with pytest.raises(TuneError, match="no elevator"):
        axis_plant(
            roll_model(),
            INPUTS,
            OUTPUTS,
            surface="elevator",
            rate="p",
            angle="phi",
            axis_outputs=OUTPUTS,
            slow=("phi",),
        )


def test_the_param_file_is_arduplanes_name_comma_value():
    text = param_file([design()], ["a header"])
    lines = [line for line in text.splitlines() if not line.startswith("#")]
    parsed = dict(line.split(",") for line in lines)
    assert set(parsed) == {
        "RLL2SRV_TCONST",
        "RLL_RATE_FF",
        "RLL_RATE_P",
        "RLL_RATE_I",
        "RLL_RATE_D",
        "RLL2SRV_RMAX",
    }
    assert all(name in DEFAULTS for name in parsed)
    assert float(parsed["RLL_RATE_D"]) == 0.0


def test_notional_degrees_reach_the_surface_through_the_installation():
    # ±45° of ArduPlane output is ±500 µs; 20 µs per degree, the direction reversed.
    assert notional_link(-1, 20.0, 500.0) == pytest.approx(-500 / 45 / 20)


def _model_file(tmp_path):
    """A `sysid identify --json`-shaped model of both axes at 25 m/s: V, α, q, θ, β, p, r, φ."""
    A = np.zeros((8, 8))
    A[0, 0], A[0, 3] = -0.05, -9.81  # V̇: drag, gravity
    A[1, 1], A[1, 2] = -2.0, 1.0  # α̇ = q − Z_α α
    A[2, 1], A[2, 2] = -20.0, -3.0  # q̇: α stiffness, damping
    A[3, 2] = 1.0  # θ̇ = q
    A[4, 4], A[4, 6] = -0.5, -1.0  # β̇ = −Y_β β − r
    A[5, 4], A[5, 5] = -2.0, -5.0  # ṗ: dihedral, damping
    A[6, 4], A[6, 6] = 4.0, -0.5  # ṙ: weathercock, damping
    A[7, 5] = 1.0  # φ̇ = p
    B = np.zeros((8, 2))
    B[5, 0] = -0.3  # aileron: measured positive rolls left (eq. 3.1, trailing edge down)
    B[2, 1] = -0.4  # elevator: trailing edge down pitches down
    outputs = ["Vt", "alpha", "q", "theta", "beta", "p", "r", "phi"]
    doc = continuous_document(A, B, ["aileron", "elevator"], outputs).model_dump(mode="json")
    path = tmp_path / "model.json"
    path.write_text(json.dumps(doc))
    return path


def test_sysid_tune_prints_writes_a_param_file_and_one_json_object(tmp_path, capsys):
    model = _model_file(tmp_path)
    out = tmp_path / "gains.param"
    code = main(["tune", str(model), "--scaling-speed", "25", "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    for says in ("roll:", "pitch:", "phase margin", "a 20° step", "a 5° step"):
        assert says in text
    written = dict(
        line.split(",") for line in out.read_text().splitlines() if not line.startswith("#")
    )
    assert float(written["SCALING_SPEED"]) == 25.0
    assert float(written["RLL_RATE_FF"]) > 0
    assert float(written["PTCH_RATE_FF"]) > 0
    code = main(["tune", str(model), "--scaling-speed", "25", "--json"])
    document = json.loads(capsys.readouterr().out)  # exactly one object
    assert code == 0
    assert [a["axis"] for a in document["axes"]] == ["roll", "pitch"]
    for axis in document["axes"]:
        assert axis["whole_loop"]["phase_margin_deg"] >= PHASE_MARGIN
        assert axis["defaults"]["RLL_RATE_FF" if axis["axis"] == "roll" else "PTCH_RATE_FF"]


@pytest.mark.parametrize(
    ("extra", "says"),
    [
        (["--out", "MODEL"], "the model being tuned"),
        (["--out", "gains.txt"], "give a .param file"),
        (["--linkage", "aileron"], "SURFACE=GAIN"),
        (["--servo-lag", "5"], "--servo-lag 5: seconds between 0 and 1"),
        (["--roll-tconst", "-1"], "time constants here are"),
        (["--scaling-speed", "0"], "m/s between 1 and 200"),
    ],
)
def test_sysid_tune_refuses_bad_input_with_one_json_error(tmp_path, capsys, extra, says):
    model = _model_file(tmp_path)
    extra = [
        str(model) if e == "MODEL" else str(tmp_path / e) if e.endswith(".txt") else e
        for e in extra
    ]
    code = main(["tune", str(model), "--scaling-speed", "25", "--json", *extra])
    out, err = capsys.readouterr()
    assert code == 2
    document = json.loads(out)
    assert says in document["error"]["message"] or says in err
    assert model.exists()


def test_a_model_file_that_is_not_json_is_refused(tmp_path, capsys):
    bad = tmp_path / "model.json"
    bad.write_text("{not json")
    assert main(["tune", str(bad)]) == 2
    assert "not JSON" in capsys.readouterr().err


def test_the_linkage_and_lag_a_run_measured_are_read_from_the_execution_log(tmp_path, capsys):
    # The agent logs each surface's linkage on a finished run (agent.logs.Logbook.linkage):
    # `sysid tune --exec-log` designs with the last run's that has one. Bad input tried: a line
    # cut by a crash (skipped), a later run's empty linkage (not taken), and a log with no
    # linkage line (refused by name).
    model = _model_file(tmp_path)
    log = tmp_path / "0001_exec_20261128.jsonl"
    lines = [
        '{"utc": "x", "level": "INFO", "message": "agent started"}',
        '{"utc": "x", "level": "INFO", "linkage": {"aileron": {"gain": 0.5, "lag_s": 0.04',
        json.dumps({"linkage": {"aileron": {"gain": 0.5, "lag_s": 0.04, "correlation": 0.99}}}),
        json.dumps({"linkage": {}}),  # a later run where no surface followed: not taken
    ]
    log.write_text("\n".join(lines) + "\n")
    args = ["tune", str(model), "--scaling-speed", "25", "--json"]
    assert main([*args, "--exec-log", str(log)]) == 0
    measured = json.loads(capsys.readouterr().out)
    assert measured["measured_linkage"] == {
        "aileron": {"gain": 0.5, "lag_s": 0.04, "even": 0.0, "knee": 0.0}
    }
    assert main(args) == 0
    given = json.loads(capsys.readouterr().out)
    roll = {a["axis"]: a for a in measured["axes"]}["roll"]
    roll_given = {a["axis"]: a for a in given["axes"]}["roll"]
    # Half the linkage: twice the feed-forward for the same roll rate.
    ff = roll["params"]["RLL_RATE_FF"] / roll_given["params"]["RLL_RATE_FF"]
    assert ff == pytest.approx(2.0, rel=1e-3)
    empty = tmp_path / "0002_exec_20261128.jsonl"
    empty.write_text(lines[0] + "\n")
    assert main([*args, "--exec-log", str(empty)]) == 2
    assert "no run's linkage" in json.loads(capsys.readouterr().out)["error"]["message"]


def test_the_linkages_travel_each_way_from_the_execution_log_is_designed_with(tmp_path, capsys):
    """A run that measured the aileron's travel differ each way (even 0.1 beside a gain of
    0.5): the design predicts each way's step and takes RMAX from the weaker way. Bad input
    tried: an even part as large as the gain (the surface would not move one way: refused
    when it is the only surface, noted and left out beside a usable one), a gain that is not a
    number, a NaN knee (noted and left out)."""
    model = _model_file(tmp_path)
    args = ["tune", str(model), "--scaling-speed", "25", "--json", "--exec-log"]
    log = tmp_path / "0001_exec_20261206.jsonl"
    link = {"gain": 0.5, "lag_s": 0.04, "correlation": 0.99}
    log.write_text(json.dumps({"linkage": {"aileron": {**link, "even": 0.1}}}) + "\n")
    assert main([*args, str(log)]) == 0
    differs = json.loads(capsys.readouterr().out)
    assert differs["measured_linkage"]["aileron"]["even"] == 0.1
    log.write_text(json.dumps({"linkage": {"aileron": {**link, "even": 0.0}}}) + "\n")
    assert main([*args, str(log)]) == 0
    even = json.loads(capsys.readouterr().out)
    roll, level = ({a["axis"]: a for a in d["axes"]}["roll"] for d in (differs, even))
    assert roll["each_way"]["+"] != roll["each_way"]["-"]
    assert level["each_way"]["+"] == level["each_way"]["-"]
    assert roll["params"]["RLL2SRV_RMAX"] < level["params"]["RLL2SRV_RMAX"]
    log.write_text(json.dumps({"linkage": {"aileron": {**link, "even": 0.5}}}) + "\n")
    assert main([*args, str(log)]) == 2
    assert "no usable linkage" in json.loads(capsys.readouterr().out)["error"]["message"]
    # Beside a usable aileron: an elevator that would not move one way, a rudder whose gain
    # is not a number, a throttle whose knee is NaN (the log's "NaN" token): each noted and
    # left out, the design made with the aileron's.
    both = {
        "aileron": link,
        "elevator": {**link, "even": 0.5},
        "rudder": {**link, "gain": "x"},
        "throttle": {**link, "knee": float("nan")},
    }
    log.write_text(json.dumps({"linkage": both}) + "\n")
    assert main([*args, str(log)]) == 0
    noted = json.loads(capsys.readouterr().out)
    assert list(noted["measured_linkage"]) == ["aileron"]
    for surface in ("elevator", "rudder", "throttle"):
        assert any(n.startswith(f"{surface}: the log's linkage") for n in noted["notes"])


def _lateral_with_rudder(N_beta=4.0, N_r=-0.5, rudder=-0.3):
    """The `_model_file` aircraft with a rudder (measured positive yaws left, as the aileron's
    rolls left) and the Dutch roll set by N_β and N_r."""
    A = np.zeros((8, 8))
    A[0, 0], A[0, 3] = -0.05, -9.81
    A[1, 1], A[1, 2] = -2.0, 1.0
    A[2, 1], A[2, 2] = -20.0, -3.0
    A[3, 2] = 1.0
    A[4, 4], A[4, 6] = -0.5, -1.0
    A[5, 4], A[5, 5] = -2.0, -5.0
    A[6, 4], A[6, 6] = N_beta, N_r
    A[7, 5] = 1.0
    B = np.zeros((8, 3))
    B[5, 0], B[2, 1], B[6, 2] = -0.3, -0.4, rudder
    return Model(
        id="lateral",
        inputs=["aileron", "elevator", "rudder"],
        outputs=["Vt", "alpha", "q", "theta", "beta", "p", "r", "phi"],
        A=A,
        B=B,
        C=np.eye(8),
        trim={"Vt": 25.0},
    )


def test_the_yaw_damper_brings_a_light_dutch_roll_to_its_target_within_the_margin():
    cfg = Config()
    designed = design_from(
        _lateral_with_rudder(), cfg.identification.channels, cfg.excitation.surfaces
    )
    yaw = designed.yaw
    assert yaw.zeta(yaw.before) < DUTCH_ROLL_TARGET
    assert yaw.params["YAW2SRV_DAMP"] > 0
    assert yaw.zeta(yaw.after) >= DUTCH_ROLL_TARGET
    assert yaw.gain_margin_db >= GAIN_MARGIN_DB
    assert designed.params()["YAW2SRV_DAMP"] == yaw.params["YAW2SRV_DAMP"]


def test_a_damped_dutch_roll_or_a_rudder_the_damper_cannot_use_leaves_it_off():
    # Bad input tried: a rudder whose sign turns the damper against the yaw rate.
    cfg = Config()
    channels, surfaces = cfg.identification.channels, cfg.excitation.surfaces
    damped = design_from(_lateral_with_rudder(N_r=-4.0), channels, surfaces).yaw
    assert damped.params["YAW2SRV_DAMP"] == 0.0
    assert "no damper" in damped.notes[0]
    reversed_ = design_from(_lateral_with_rudder(rudder=0.3), channels, surfaces).yaw
    assert reversed_.params["YAW2SRV_DAMP"] == 0.0
    assert "left off" in reversed_.notes[0]
