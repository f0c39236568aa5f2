"""Plans: presets, rendering, radio encoding, refusal before flight, servo-model warnings."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from agent.channels import AXIS_SETS
from agent.config import Config, Envelope, Surface
from agent.excitation import servo
from agent.excitation.plan import (
    FULL_PERIOD_S,
    FULL_THROTTLE_TOP_HZ,
    PHUGOID_LINES_GAIN,
    PRESET_CONTROLS,
    PRESETS,
    Doublet,
    Multisine,
    Plan,
    PlanRefused,
    Segment,
    Steps,
    Sweep,
    check,
    full_harmonics,
    preset,
    render,
    summary,
)

CONFIG = Config().excitation
SURFACES, ENVELOPE = CONFIG.surfaces, CONFIG.envelope


def test_full_preset_is_orthogonal_odd_and_plays_all_four_controls_at_once():
    timeline = check(preset("full"), 50.0, SURFACES, ENVELOPE)
    report = summary(timeline, SURFACES)
    assert report["max_cross_correlation"] < 1e-9
    for name in ("aileron", "rudder", "elevator", "throttle"):
        assert report["controls"][name]["rpf"] <= 1.12
    # The throttle holds the phugoid's band, the surfaces 0.12–2 Hz; one 80 s period each.
    assert report["controls"]["throttle"]["band_hz"][1] < FULL_THROTTLE_TOP_HZ
    for name in ("aileron", "rudder", "elevator"):
        low, high = report["controls"][name]["band_hz"]
        assert low >= FULL_THROTTLE_TOP_HZ
        assert high <= 2.0
    assert report["warnings"] == []
    harmonics = full_harmonics()
    every = [k for h in harmonics.values() for k in h]
    assert len(every) == len(set(every))
    assert all(k % 2 == 1 for k in every)
    # Each control's spectrum holds its own odd harmonics of 1/80 s and nothing else.
    for name, wanted in harmonics.items():
        played = timeline.values[name][timeline.active[name]]
        assert played.size == round(FULL_PERIOD_S * 50.0)
        power = np.abs(np.fft.rfft(played)) ** 2
        lines = set(np.flatnonzero(power > 1e-6 * power.max()))
        assert lines == set(wanted)
        # Starts at a zero crossing: no jump off trim.
        assert abs(played[0]) < 1e-9
    # All four play together over the whole excitation.
    active = np.array([timeline.active[c] for c in harmonics])
    assert np.all(active.all(axis=0) == active.any(axis=0))


def test_presets_follow_the_thesis_sequences():
    lateral = render(preset("lateral"), 50.0)
    a, r = lateral.values["aileron"], lateral.values["rudder"]
    # Aileron doublet first, rudder doublet after it; never both at once.
    assert np.flatnonzero(a)[-1] < np.flatnonzero(r)[0]
    longitudinal = render(preset("longitudinal"), 50.0)
    e, t = longitudinal.values["elevator"], longitudinal.values["throttle"]
    assert np.flatnonzero(e)[-1] < np.flatnonzero(t)[0]
    # Throttle: two counts up, one count down (figure 4.4).
    steps = t[longitudinal.active["throttle"]]
    assert np.count_nonzero(steps > 0) == 2 * np.count_nonzero(steps < 0)


@pytest.mark.parametrize("name", PRESETS)
def test_every_run_starts_and_ends_at_trim(name):
    timeline = render(preset(name), 100.0)
    lead = round(preset(name).lead_s * 100)
    for values in timeline.values.values():
        assert not values[:lead].any()
        assert values[-1] == 0.0


@pytest.mark.parametrize("name", PRESETS)
def test_plans_survive_the_radio_encoding(name):
    plan = preset(name, amplitude={c: 2.5 for c in PRESET_CONTROLS[name][:1]})
    data = plan.to_bytes()
    assert len(data) < 768  # three XBee payloads at most (the full preset's 80 harmonics)
    assert Plan.from_bytes(data) == plan


def test_malformed_plans_are_rejected_with_the_field_named():
    # Bad input tried: truncated bytes, an unknown signal kind, a zero amplitude, repeated
    # harmonics, an unknown control, a step level outside ±1.
    data = preset("full").to_bytes()
    with pytest.raises(ValidationError):
        Plan.from_bytes(data[:-7])
    with pytest.raises(ValidationError, match="kind"):
        Plan.from_bytes(data.replace(b'"multisine"', b'"chirp"'))
    with pytest.raises(ValidationError, match="amplitude must not be 0"):
        Doublet(pulse_s=1.0, amplitude=0.0)
    with pytest.raises(ValidationError, match="distinct"):
        Multisine(harmonics=(3, 3), period_s=20.0, amplitude=1.0)
    bad = {
        "id": "x",
        "axes": "lateral",
        "segments": [{"signals": {"flaps": {"kind": "doublet", "pulse_s": 1, "amplitude": 1}}}],
    }
    with pytest.raises(ValidationError, match="unknown control"):
        Plan.model_validate(bad)
    steps = {"kind": "steps", "levels": [2], "hold_s": 1, "amplitude": 5}
    with pytest.raises(ValidationError, match="within −1"):
        Plan.model_validate(
            {"id": "x", "axes": "lateral", "segments": [{"signals": {"throttle": steps}}]}
        )


@pytest.mark.parametrize(
    "harmonic", [b"1" + b"0" * 400, b"1e400", b"1e300"], ids=["10**400", "1e400", "1e300"]
)
def test_a_harmonic_no_float_holds_is_refused_by_its_key(harmonic):
    # Bad input tried: a multisine harmonic of 10**400 (an OverflowError traceback when its
    # frequency was computed), 1e400 (infinity in JSON) and 1e300 written as a number.
    data = (
        b'{"id":"x","axes":"lateral","segments":[{"signals":{"aileron":{"kind":"multisine",'
        b'"harmonics":[' + harmonic + b'],"period_s":10,"amplitude":3}}}]}'
    )
    with pytest.raises(ValidationError) as caught:
        Plan.from_bytes(data)
    locs = [e["loc"] for e in caught.value.errors()]
    assert ("segments", 0, "signals", "aileron", "multisine", "harmonics", 0) in locs


def _one(signal, name="aileron", free_s=0.0) -> Plan:
    return Plan(id="t", axes="lateral", segments=(Segment(signals={name: signal}, free_s=free_s),))


def test_plans_outside_the_envelope_are_refused_before_start():
    # Bad input tried: an amplitude past max_amplitude, a plan longer than max_duration_s, a
    # sweep above the command rate's Nyquist frequency, a control with no calibration.
    with pytest.raises(PlanRefused, match=r"aileron: 12 deg from trim exceeds its max_amplitude"):
        check(_one(Doublet(pulse_s=1.0, amplitude=-12.0)), 50.0, SURFACES, ENVELOPE)
    with pytest.raises(PlanRefused, match=r"lasts 101.0 s, longer than .* max_duration_s = 90"):
        check(_one(Doublet(pulse_s=1.0, amplitude=2.0), free_s=98.0), 50.0, SURFACES, ENVELOPE)
    fast = Sweep(f0_hz=1.0, f1_hz=30.0, duration_s=5.0, amplitude=2.0)
    with pytest.raises(PlanRefused, match="30 Hz, not below the 25 Hz Nyquist"):
        check(_one(fast), 50.0, SURFACES, ENVELOPE)
    only_aileron = {"aileron": SURFACES["aileron"]}
    with pytest.raises(PlanRefused, match="rudder is not a configured control"):
        check(preset("lateral"), 50.0, only_aileron, ENVELOPE)
    # All reasons at once, so the operator fixes the plan in one go.
    with pytest.raises(PlanRefused) as caught:
        check(_one(Doublet(pulse_s=1.0, amplitude=12.0), free_s=98.0), 50.0, SURFACES, ENVELOPE)
    assert "max_amplitude" in str(caught.value)
    assert "max_duration_s" in str(caught.value)
    strict = Envelope(max_duration_s=30.0)
    with pytest.raises(PlanRefused, match="max_duration_s = 30"):
        check(preset("full"), 50.0, SURFACES, strict)


@pytest.mark.parametrize(
    ("axes", "control", "signal"),
    [
        ("lateral", "elevator", Doublet(pulse_s=0.5, amplitude=3.0)),
        ("longitudinal", "rudder", Doublet(pulse_s=1.0, amplitude=3.0)),
    ],
)
def test_a_plan_playing_a_control_its_axis_set_does_not_identify_is_refused(axes, control, signal):
    # Input: a lateral plan with an elevator doublet (it used to fly), and a longitudinal one
    # with a rudder doublet. The full set takes every control.
    plan = Plan(
        id="t",
        axes=axes,
        segments=(Segment(signals={PRESET_CONTROLS[axes][0]: signal, control: signal}),),
    )
    takes = ", ".join(AXIS_SETS[axes][0])
    with pytest.raises(PlanRefused) as caught:
        check(plan, 50.0, SURFACES, ENVELOPE)
    assert f"{control}: not an input of the {axes} model ({takes})" in str(caught.value)
    assert f'play only {takes}, or fly the plan as axes "full"' in str(caught.value)
    assert check(plan.model_copy(update={"axes": "full"}), 50.0, SURFACES, ENVELOPE).count > 0


ABSURD = [
    (Multisine(harmonics=(1_000_000,), period_s=10.0, amplitude=2.0), "100000 Hz, not below"),
    (
        Sweep(f0_hz=1e-9, f1_hz=1.0, duration_s=10.0, dwell_cycles=2.0, amplitude=2.0),
        "longer than the envelope's max_duration_s",
    ),
    (Doublet(pulse_s=1e-4, amplitude=2.0), "holds a level for 0.0001 s, shorter than one"),
    (Steps(levels=(1.0, -1.0), hold_s=0.005, amplitude=2.0), "shorter than one command period"),
]


@pytest.mark.parametrize(("signal", "message"), ABSURD, ids=["harmonic", "dwell", "pulse", "hold"])
def test_absurd_plans_are_refused_from_their_parameters_without_rendering(
    signal, message, monkeypatch
):
    """Bad input tried (an operator's typo, from the console or the radio): a multisine
    harmonic of 1e6 (it used to hang or take 3 GB in rendering), a sweep from 1e-9 Hz with two
    dwell cycles (2e9 s), a doublet pulse of 1e-4 s and a step held 5 ms (no command period:
    a traceback). Refused with the reason before anything is rendered."""
    import agent.excitation.plan as plan_module

    def no_render(*args):
        raise AssertionError("rendered")

    monkeypatch.setattr(plan_module, "render", no_render)
    with pytest.raises(PlanRefused, match=message):
        check(_one(signal), 50.0, SURFACES, ENVELOPE)
    bold = signal.model_copy(update={"amplitude": 12.0})  # and every other reason with it
    with pytest.raises(PlanRefused, match="exceeds its max_amplitude"):
        check(_one(bold), 50.0, SURFACES, ENVELOPE)


SERVO = Surface(
    channel=1, us_per_unit=20.0, direction=1, max_amplitude=10.0, rate_limit=150.0, travel=8.0
)


def test_servo_model_warns_when_a_sweep_outruns_the_servo():
    # A 1–10 Hz linear sweep at ±4°: 2π f A passes 150 °/s at f ≈ 6 Hz (t ≈ 5.5 s of 10); a
    # fifth of each cycle is too fast from f ≈ 6.3 Hz (t ≈ 5.9 s).
    dt = 0.01
    fast = Sweep(f0_hz=1.0, f1_hz=10.0, duration_s=10.0, amplitude=4.0).samples(dt)
    warnings = servo.distortion_warnings("elevator", fast, dt, SERVO)
    assert len(warnings) == 1
    assert "servo rate limit 150 deg/s" in warnings[0]
    first = float(warnings[0].rsplit("t = ", 1)[1].split(" s")[0])
    assert 4.0 < first < 7.0
    slow = Sweep(f0_hz=0.2, f1_hz=2.0, duration_s=10.0, amplitude=4.0).samples(dt)
    assert servo.distortion_warnings("elevator", slow, dt, SERVO) == []
    big = Doublet(pulse_s=1.0, amplitude=9.0).samples(dt)
    assert "exceeds the servo travel of 8 deg" in servo.distortion_warnings("e", big, dt, SERVO)[0]


def test_pwm_conversion_direction_and_clamping():
    reverse = SERVO.model_copy(update={"direction": -1, "min_us": 1400})
    values = np.array([0.0, 2.0, -2.0, -10.0])
    assert servo.to_pwm(values, 1500, SERVO).tolist() == [1500, 1540, 1460, 1300]
    assert servo.to_pwm(values, 1500, reverse).tolist() == [1500, 1460, 1540, 1700]
    assert servo.to_pwm(np.array([6.0]), 1500, reverse).tolist() == [1400]  # clamped
    assert servo.pwm_clamped(np.array([6.0, 1.0]), 1500, reverse) == 1


def test_presets_leave_out_the_controls_an_aircraft_lacks():
    """A glider has no throttle: its presets play the surfaces alone, a segment left with no
    signal goes, and a plan left with nothing is refused by name."""
    from agent.config import Channels
    from agent.excitation.plan import only

    surfaces = ("elevator", "aileron", "rudder")
    full = preset("full", controls=surfaces)
    assert sorted(full.controls()) == ["aileron", "elevator", "rudder"]
    # Its elevator plays the throttle's low lines (the phugoid's) too, at PHUGOID_LINES_GAIN.
    elevator = full.segments[0].signals["elevator"]
    low = full_harmonics()["throttle"]
    assert set(low) <= set(elevator.harmonics)
    played = render(full, 50.0)
    u = played.values["elevator"][played.active["elevator"]]
    line = np.abs(np.fft.rfft(u))
    assert line[list(low)] == pytest.approx(PHUGOID_LINES_GAIN * line[max(elevator.harmonics)])
    longitudinal = preset("longitudinal", controls=surfaces)
    assert longitudinal.controls() == ["elevator"]
    assert len(longitudinal.segments) == 1  # the throttle's steps went with their segment
    with pytest.raises(ValueError, match="plays none of"):
        only(preset("longitudinal"), ("aileron",))
    assert Channels().axis_set("longitudinal", surfaces)[0] == ("elevator",)
    assert Channels().axis_set("longitudinal")[0] == ("throttle", "elevator")


def test_a_shape_is_checked_and_carried_over_the_radio():
    """Bad input tried (a forged plan from the radio or a plan file): breakpoints out of
    order, a gain of 0, above 1 or NaN, a frequency of 0 or infinite, more breakpoints than
    MAX_BREAKPOINTS: each refused by the plan's validation, as any malformed plan is."""
    from agent.excitation.plan import MAX_BREAKPOINTS

    sweep = dict(kind="sweep", f0_hz=0.1, f1_hz=2.0, duration_s=20.0, amplitude=3.0)
    for bad in (
        [[1.0, 0.5], [0.5, 1.0]],
        [[0.5, 0.5], [0.5, 1.0]],
        [[0.5, 0.0]],
        [[0.5, 1.5]],
        [[0.0, 0.5]],
        [[0.5, float("nan")]],
        [[float("inf"), 0.5]],
        [[0.01 * (i + 1), 1.0] for i in range(MAX_BREAKPOINTS + 1)],
    ):
        with pytest.raises(ValidationError):
            Plan.model_validate(
                {
                    "id": "s",
                    "axes": "full",
                    "segments": [{"signals": {"elevator": {**sweep, "shape": bad}}}],
                }
            )
    shaped = Sweep(
        **{k: v for k, v in sweep.items() if k != "kind"}, shape=((0.2, 0.3), (1.0, 1.0))
    )
    plan = Plan(id="s", axes="full", segments=(Segment(signals={"elevator": shaped}),))
    assert Plan.from_bytes(plan.to_bytes()) == plan
    # The shape only takes amplitude away: the rendered peak stays within the amplitude.
    assert np.max(np.abs(render(plan, 50.0).values["elevator"])) <= 3.0
    flat = plan.model_copy(
        update={
            "segments": (Segment(signals={"elevator": shaped.model_copy(update={"shape": ()})}),)
        }
    )
    assert b"shape" not in flat.to_bytes()  # a flat signal carries no shape
