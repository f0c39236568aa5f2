"""The ground console driven by Textual's pilot, over the real link: real digi-xbee on both
ends of an emulated XBee pair, the console's GroundStation on one, a scripted aircraft-side
LinkSession on the other.

Bad input tried: a plan the aircraft refuses (its reason shown), a plan that is not valid JSON
in the editor (not sent), a revert with no previous nominal (refused with the reason),
settings with a non-numeric p (not sent), the radio link going silent (shown as lost).
"""

from __future__ import annotations

import asyncio
import io
import json
import math
import re

import pytest

from agent.clock import LoopClock
from agent.config import Excitation
from agent.ground.app import Console
from agent.ground.splane import SPlane
from agent.ground.station import GroundStation
from agent.link import messages
from tests import waiting
from tests.ground.aircraft import result, rig

pytestmark = [pytest.mark.usefixtures("no_leaked_tasks"), pytest.mark.timeout(60)]


async def until(pilot, predicate, what: str) -> None:
    """Until predicate() holds, the app running meanwhile (tests.waiting)."""
    await waiting.until(predicate, what, pilot.pause)


def text_of(app, selector: str) -> str:
    return str(app.query_one(selector).render())


def drawn(app, selector: str) -> str:
    """What a widget draws, rich tables included, as plain text."""
    from rich.console import Console as RichConsole

    out = RichConsole(width=200, record=True, file=io.StringIO())
    out.print(app.query_one(selector).content)
    return out.export_text()


def log_text(app) -> str:
    """The event log pane as rendered (its wrapped lines joined again)."""
    return " ".join(" ".join(line.text for line in app.query_one("#log").lines).split())


@pytest.fixture
async def console(tmp_path):
    async with rig(tmp_path) as r:
        station = GroundStation(r.config, LoopClock(), base=tmp_path)
        app = Console(station)
        async with app.run_test(size=(110, 36)) as pilot:
            await until(pilot, lambda: station.link_up, "link up")
            yield app, pilot, r, station


async def test_status_renders_and_stale_sensors_show(console):
    app, pilot, r, _ = console
    await until(pilot, lambda: "22.0 m/s" in text_of(app, "#flight"), "status")
    assert "LINK UP" in text_of(app, "#top")
    assert "MANUAL" in text_of(app, "#top")
    flight = text_of(app, "#flight")
    assert "305 m" in flight
    assert "+3.0°" in flight  # α 0.052 rad
    sensors = app.query_one("#sensors")
    assert sensors.row_count == 2
    assert [str(c) for c in sensors.get_row_at(1)][:2] == ["airdata", "waiting"]
    r.aircraft.airspeed = 25.5
    await until(pilot, lambda: "25.5 m/s" in text_of(app, "#flight"), "a status update")
    # The recorder's counters, each under its own name: frames assembled after a late
    # wake-up, and those that waited for a live sensor's late sample.
    r.aircraft.recorder = {"frames": 1300.0, "catch_up_frames": 4.0, "waited_frames": 7.0}
    await until(pilot, lambda: "(4 late, 7 waited)" in text_of(app, "#health"), "counters")
    # The ground module's RSSI (AT DB) of the last frame heard.
    r.channel.rssi_dbm = -71
    await until(pilot, lambda: "-71 dBm" in text_of(app, "#top"), "RSSI")


async def test_a_preset_is_armed_and_acknowledged_and_a_refusal_shows_its_reason(console):
    app, pilot, r, _ = console
    await pilot.press("2")
    await pilot.pause(0.1)
    assert "RPF" in text_of(app, "#preview")
    assert "lateral" in text_of(app, "#preview")
    await pilot.press("f2")
    await until(pilot, lambda: "arm lateral: acknowledged" in log_text(app), "ack")
    armed = [m for m in r.aircraft.inbox if isinstance(m, messages.Arm)]
    assert armed[0].plan.id == "lateral"
    await until(pilot, lambda: "│ armed" in text_of(app, "#top"), "armed status")
    # The aircraft refuses the next one: the reason is in the log, in red.
    r.aircraft.refuse["arm"] = "plan 'lateral' refused: aileron: 12 deg exceeds max_amplitude"
    await pilot.press("f2")
    await until(pilot, lambda: "REFUSED" in log_text(app), "refusal")
    assert "exceeds max_amplitude" in log_text(app)
    # A plan that does not parse is not sent.
    app.query_one("#plan").text = '{"id": "x", "axes": "lateral", "segments": ['
    await pilot.pause(0.1)
    assert "not a valid plan" in text_of(app, "#preview")
    sent = len(r.aircraft.inbox)
    await pilot.press("f2")
    await pilot.pause(0.3)
    assert len(r.aircraft.inbox) == sent
    assert "not valid: not sent" in log_text(app)
    # F5 aborts from anywhere, even with the editor focused.
    app.query_one("#plan").focus()
    await pilot.press("f5")
    await until(
        pilot, lambda: any(isinstance(m, messages.Abort) for m in r.aircraft.inbox), what="abort"
    )


async def test_a_plan_is_sized_by_the_aircraft_and_the_sized_plan_armed(console):
    app, pilot, r, _ = console
    await pilot.press("2")
    await pilot.pause(0.1)
    assert "not sized" in text_of(app, "#sizing")
    await pilot.press("f3")
    await until(pilot, lambda: "sized by build-up" in text_of(app, "#sizing"), "sizing")
    assert "aileron" in text_of(app, "#sizing")
    assert "Arm sized" in str(app.query_one("#arm").label)
    await pilot.press("f2")
    await until(pilot, lambda: "arm lateral: acknowledged" in log_text(app), "ack")
    armed = next(m for m in r.aircraft.inbox if isinstance(m, messages.Arm))
    asked = next(m for m in r.aircraft.inbox if isinstance(m, messages.SizeRequest))
    build_up = Excitation().sizing.build_up
    for segment, original in zip(armed.plan.segments, asked.plan.segments, strict=True):
        for control, signal in segment.signals.items():
            assert signal.amplitude == pytest.approx(build_up * original.signals[control].amplitude)
    # An edit drops the sizing: F2 then arms the plan as written.
    app.query_one("#plan").text = app.query_one("#plan").text.replace('"lateral"', '"lat2"', 1)
    await pilot.pause(0.1)
    assert "not sized" in text_of(app, "#sizing")
    assert str(app.query_one("#arm").label) == "Arm F2"


async def test_a_result_renders_and_accept_reject_revert_round_trip(console, tmp_path):
    app, pilot, r, _ = console
    await pilot.press("4")
    r.aircraft.session.send_reliable(result("lat-1"))
    await until(pilot, lambda: "lat-1" in text_of(app, "#summary"), "result")
    assert app.query_one("#modes").row_count == 3
    assert "UPDATE" in text_of(app, "#summary")
    splane = app.query_one("#splane", SPlane)
    assert {p.kind for p in splane.points} == {"candidate"}
    assert re.search(r"✕.?Dutch roll", text_of(app, "#splane"))  # named beside its mark
    # The mode picked in the table: reversed on the plane, its row (with σ) beneath.
    await until(
        pilot,
        lambda: "Dutch roll: λ -0.800+3.100j (σ 0.12, 0.25)" in text_of(app, "#splane"),
        "row",
    )
    app.query_one("#modes").move_cursor(row=1)
    await until(pilot, lambda: "roll: λ -9.500" in text_of(app, "#splane"), "the roll's row")
    # Accept, confirmed: the aircraft gets the decision; its status then names the nominal.
    await pilot.press("y")
    await pilot.press("y")
    await until(pilot, lambda: "accept lat-1: acknowledged" in log_text(app), "accept")
    await until(pilot, lambda: "nominal lat-1" in text_of(app, "#top"), "nominal")
    # A second result: shown beside the nominal, which is highlighted in the s-plane.
    r.aircraft.session.send_reliable(result("lat-2", shift=0.3, update=False))
    await until(pilot, lambda: "lat-2" in text_of(app, "#summary"), "second result")
    assert "nominal lat-1" in text_of(app, "#nominal-title")
    assert app.query_one("#nominal-modes").row_count == 3
    assert {p.kind for p in splane.points} == {"history", "nominal", "candidate"}
    assert "◇" in text_of(app, "#splane")
    assert "∘" in text_of(app, "#splane")  # the Dutch roll's 2σ ellipse
    # A pair's frequency response, asked of the aircraft: measured points over the model's
    # line, the low-coherence ones counted.
    app.query_one("#frf-pair").value = "aileron → p"
    await pilot.press("f")
    await until(pilot, lambda: "lat-2  aileron → p" in text_of(app, "#bode"), "the response")
    request = next(m for m in r.aircraft.inbox if isinstance(m, messages.FrfRequest))
    assert (request.model_id, request.input, request.output) == ("lat-2", "aileron", "p")
    bode = text_of(app, "#bode")
    assert "30 frequencies, 7 Welch segments" in bode
    assert bode.count("●") + bode.count("×") >= 25  # measured points (some share a cell)
    assert "·" in bode  # the model's line
    assert "γ² low at 6 of 30: not to be trusted there" in bode
    # Reject it, but first say no to the confirmation: nothing is sent.
    await pilot.press("n")
    await pilot.press("n")
    await pilot.pause(0.3)
    assert not any(isinstance(m, messages.Decision) and not m.accept for m in r.aircraft.inbox)
    await pilot.press("n")
    await pilot.press("y")
    await until(pilot, lambda: "reject lat-2: acknowledged" in log_text(app), "reject")
    # Revert with no previous nominal: refused, with the aircraft's reason.
    await pilot.press("r")
    await pilot.press("y")
    await until(pilot, lambda: "REFUSED — no previous lateral" in log_text(app), "revert")
    decisions = [
        (m.model_id, m.accept) for m in r.aircraft.inbox if isinstance(m, messages.Decision)
    ]
    assert decisions == [("lat-1", True), ("lat-2", False)]
    # Everything is in the ground log too, results in full.
    log = next((tmp_path / "ground-logs").glob("*_ground_*.jsonl")).read_text().splitlines()
    records = [json.loads(line) for line in log]
    results = [x for x in records if x["dir"] == "rx" and x["message"]["kind"] == "result"]
    assert [x["message"]["model_id"] for x in results] == ["lat-1", "lat-2"]
    assert results[0]["message"]["A"] == result("lat-1").A  # the matrices in full
    assert any(x["dir"] == "tx" and x["message"]["kind"] == "decision" for x in records)


async def test_the_settings_shown_are_those_in_effect_and_an_edit_says_it_is_not_sent(console):
    app, pilot, r, _ = console
    await pilot.press("3")
    # Nothing sent yet: the aircraft's status says what is in effect, and the form shows it.
    await until(pilot, lambda: "reported by the aircraft" in text_of(app, "#settings-now"), "it")
    assert "each plan's own axes, p auto, n auto, batch off" in text_of(app, "#settings-now")
    assert app.query_one("#axes").value == "plan"
    assert text_of(app, "#settings-pending") == ""
    # A press stays on the button longer than the edits below take (Textual's "active" effect,
    # 0.2 s by default, which ignores a second click meanwhile as a double click): the click
    # after the edits must still send them.
    app.query_one("#send-settings").active_effect_duration = 30.0
    # Bad input tried: a p that is not a number is not sent.
    app.query_one("#markov").value = "twelve"
    await pilot.click("#send-settings")
    await until(pilot, lambda: "not sent" in text_of(app, "#settings-error"), "the error")
    await until(pilot, lambda: "not valid" in text_of(app, "#settings-pending"), "marked")
    # An edit is marked, field by field, until the aircraft reports it in effect.
    app.query_one("#markov").value = "12"
    app.query_one("#period").value = "30"
    app.query_one("#batch").value = True
    app.query_one("#axes").value = "lateral"
    await until(
        pilot,
        lambda: (
            "not sent: type, p, batch, update period differ from the settings in effect"
            in text_of(app, "#settings-pending")
        ),
        "the edit marked",
    )
    await pilot.click("#send-settings")
    await until(pilot, lambda: "settings lateral: acknowledged" in log_text(app), "ack")
    settings = [m for m in r.aircraft.inbox if isinstance(m, messages.IdentSettings)][-1]
    assert (settings.axes, settings.markov, settings.order, settings.batch) == (
        "lateral",
        12,
        "auto",
        True,
    )
    assert settings.update_period_s == 30.0
    await until(pilot, lambda: "p 12" in text_of(app, "#settings-now"), "in effect")
    assert "lateral" in text_of(app, "#settings-now")
    assert "every 30 s" in text_of(app, "#settings-now")
    await until(pilot, lambda: text_of(app, "#settings-pending") == "", "nothing pending")


async def test_an_aircraft_that_does_not_report_its_settings_shows_them_as_not_known(tmp_path):
    async with rig(tmp_path) as r:
        r.aircraft.settings = None  # an older agent's status
        station = GroundStation(r.config, LoopClock(), base=tmp_path)
        app = Console(station)
        async with app.run_test(size=(110, 36)) as pilot:
            await until(pilot, lambda: station.heard.status is not None, "status")
            await pilot.press("3")
            assert "not known here yet" in text_of(app, "#settings-now")
            assert "not sent" in text_of(app, "#settings-pending")
            await pilot.click("#send-settings")
            await until(
                pilot,
                lambda: "acknowledged by the aircraft" in text_of(app, "#settings-now"),
                "ack",
            )
            assert "each plan's own axes" in text_of(app, "#settings-now")
            assert text_of(app, "#settings-pending") == ""


async def test_what_is_heard_is_drawn_without_any_timer(console):
    """A status, and a result, each redraw their tab as they are heard: the app's one
    timer (the link's liveness, the status's age) is stopped meanwhile."""
    app, pilot, r, _ = console
    await until(pilot, lambda: "22.0 m/s" in text_of(app, "#flight"), "status")
    app.ticker.pause()
    try:
        r.aircraft.airspeed = 27.5
        await until(pilot, lambda: "27.5 m/s" in text_of(app, "#flight"), "the next status")
        await pilot.press("4")
        r.aircraft.session.send_reliable(result("lat-7"))
        await until(pilot, lambda: "lat-7" in text_of(app, "#summary"), "the result")
        assert app.query_one("#results").row_count == 1
        assert app.query_one("#modes").row_count == 3
    finally:
        app.ticker.resume()


async def test_results_of_earlier_sessions_are_listed_at_start(tmp_path):
    logs = tmp_path / "ground-logs"
    logs.mkdir()
    record = {"dir": "rx", "message": messages.to_dict(result("lat-3"))}
    (logs / "0001_ground_2026-01-01.jsonl").write_text(json.dumps(record) + "\n")
    async with rig(tmp_path) as r:
        station = GroundStation(r.config, LoopClock(), base=tmp_path)
        app = Console(station)
        async with app.run_test(size=(110, 36)) as pilot:
            await pilot.press("4")
            await until(pilot, lambda: "lat-3" in text_of(app, "#summary"), "the earlier result")
            assert app.query_one("#results").row_count == 1


async def test_a_console_quit_while_its_radio_opens_leaves_no_reader_on_the_port(tmp_path):
    """Bad input tried: the console quit while digi-xbee is still reading the module's
    parameters (a busy laptop: the open takes seconds). The station holds the radio before it
    opens, so closing it gives the open up and waits for it: no digi-xbee reader is left on
    the port, nor the opening thread (the station used to learn of the radio only once it was
    open, and a quit meanwhile left both running)."""
    import threading

    async def turn(_: float) -> None:  # one turn of the loop: the module (on it) not answered
        await asyncio.sleep(0)

    async with rig(tmp_path) as r:
        before = set(threading.enumerate())  # the rig's own radio has its threads
        station = GroundStation(r.config, LoopClock(), base=tmp_path)
        running = asyncio.create_task(station.run(), name="ground")
        await waiting.until(
            lambda: any(
                t.name.startswith("xbee-open") for t in set(threading.enumerate()) - before
            ),
            "the open under way",
            pause=turn,
        )
        assert not station.radio.is_open
        running.cancel()
        await asyncio.gather(running, return_exceptions=True)
        await station.close()
        assert not station.radio.is_open
        alive = [
            t
            for t in set(threading.enumerate()) - before
            if t.is_alive() and (type(t).__name__ == "PacketListener" or "xbee-open" in t.name)
        ]
        assert not alive, alive


def test_a_status_or_live_frame_still_waiting_gives_way_to_the_next():
    from agent.ground import events, posted

    status = [posted.posted(events.StatusHeard(messages.Status(time=t), t)) for t in (1.0, 2.0)]
    assert status[0].can_replace(status[1])
    frames = [posted.posted(events.LiveFrame(live(k))) for k in (0, 1)]
    assert frames[0].can_replace(frames[1])
    assert frames[0].can_replace(posted.posted(events.LiveFrame(None)))
    # Each result, answer and log line counts.
    results = [posted.posted(events.ResultHeard(result(m))) for m in ("lat-1", "lat-2")]
    assert not results[0].can_replace(results[1])
    assert not status[0].can_replace(results[0])
    line = events.Noted(events.Line(1.0, "info", "x"))
    assert not posted.posted(line).can_replace(posted.posted(line))


async def test_a_silent_link_is_shown_as_lost_and_status_as_stale(console):
    app, pilot, r, _ = console
    await until(pilot, lambda: "LINK UP" in text_of(app, "#top"), "link up")
    r.channel.outage = True
    await until(pilot, lambda: "LINK LOST" in text_of(app, "#top"), "lost")
    await until(pilot, lambda: "STALE" in text_of(app, "#status-age"), "stale")
    r.channel.outage = False
    await until(pilot, lambda: "LINK UP" in text_of(app, "#top"), "back")


def test_percentages_never_print_as_exponents():
    from agent.ground.widgets import percent

    assert [percent(v) for v in (100.0, 99.96, 10.0, 9.9, 0.35, 0.0, 1e-5, None)] == [
        "100",
        "100",
        "10",
        "9.9",
        "0.35",
        "0",
        "<0.01",
        "–",
    ]


def test_a_refused_step_of_the_suggestion_reaches_the_results_tab_with_its_reason():
    """Bad input tried: a lateral candidate without a Dutch roll and with a pole at −2008 1/s
    on a 100 Hz record. The aircraft's suggestion refuses it at step 2b; the step's line, with
    the missing mode's reason and the pole, crosses the link's schema and is what the results
    tab shows under "do not update"."""
    import numpy as np

    from agent.ground.tabs.results import _summary
    from agent.ident.document import ModeDocument
    from agent.models import Candidate, suggest
    from agent.runtime.identification import result_message
    from tests.documents import OUTPUTS, lateral_document

    def mode(name, re, emac):
        return ModeDocument(
            name=name,
            eigenvalue=(re, 0.0),
            frequency_rad_s=abs(re),
            damping=1.0,
            time_constant_s=-1 / re,
            msv=100.0,
            mci=100.0,
            moi=100.0,
            emac=emac,
            mpc=100.0,
            cmi=None,
        )

    reason = "no named mode: no lateral pair damped below ζ = 0.95"
    result = lateral_document(
        dt=0.01,
        tic=dict.fromkeys(OUTPUTS, 0.1),
        tic_avg=0.1,
        modes=[mode("spiral", -0.2, 90.0), mode("roll", -9.0, 90.0), mode(None, -2008.0, None)],
        missing_modes=[{"name": "Dutch roll", "reason": reason}],
    )
    data = ((np.zeros((10, 2)), np.zeros((10, 4))),)
    candidate = Candidate(
        model_id="lat-9", axes="lateral", record_dt=0.01, result=result, experiments=data
    )
    suggestion = suggest(candidate, None, None, None)
    heard = messages.from_dict(messages.to_dict(result_message(candidate, suggestion)))
    assert heard.checks["modes"] is False
    shown = str(_summary(heard))
    assert "suggestion: do not update" in shown
    assert f"2b modes: MISSING Dutch roll ({reason})" in shown
    assert "OUT OF RANGE: pole -2008 1/s faster than 126 rad/s" in shown


def live(
    k: int, stage: str = "", stage_s: float | None = None, expected_s: float | None = None
) -> messages.Live:
    """The k-th second of a lateral run as the aircraft sends it (tenths of degrees)."""
    t = [k + 0.1 * i for i in range(10)]
    playing = not stage
    return messages.Live(
        time=100.0 + k,
        dt=0.1,
        plan_id="lateral-1" if playing else None,
        plan_fraction=(k + 1) / 41 if playing else None,
        plan_s=41.0 if playing else None,
        stage=stage,
        stage_s=stage_s,
        stage_expected_s=expected_s,
        tenths={
            "aileron_cmd": [30 if (x % 2) < 1 else -30 for x in t],
            "aileron": [28 if (x % 2) < 1 else -28 for x in t],
            "p": [int(100 * math.sin(x)) for x in t],
            "phi": [None] * 10,  # no data yet: shown as such
        },
    )


async def test_the_live_view_shows_the_run_its_identification_and_strip_charts(console):
    app, pilot, r, station = console
    await pilot.press("5")
    for k in range(3):
        r.aircraft.session.send_live(live(k))
        await until(
            pilot, lambda k=k: len(station.heard.strips.get("p", ())) == 10 * (k + 1), "live"
        )
    await until(pilot, lambda: "lateral-1: 3 of 41 s" in text_of(app, "#plan-text"), "progress")
    assert app.query_one("#plan-progress").progress == pytest.approx(100 * 3 / 41)
    assert list(station.heard.strips) == ["aileron_cmd", "aileron", "p", "phi"]
    await until(pilot, lambda: len(app.query_one("#strip-p").traces) == 1, "the strips")
    # The aileron's chart: its command (yellow) and the surface (cyan) as lines on one scale.
    aileron = app.query_one("#strip-aileron")
    assert [colour for _, colour in aileron.traces] == ["yellow", "cyan"]
    assert len(aileron.traces[0][0]) == 30
    drawn = text_of(app, "#strip-aileron")
    assert any("\u2801" <= ch <= "\u28ff" for ch in drawn)  # braille dots
    assert text_of(app, "#value-aileron") == "+3.0 +2.8 °\n-3.0 … +3.0"
    assert text_of(app, "#value-phi") == "– °"  # no data, not a made-up zero
    # After the plan: the identification's stage. The first has no expectation (no bar);
    # then the aircraft's expectation sets the bar; a result ends the live view.
    r.aircraft.session.send_live(live(3, "identifying", 2.5))
    await until(pilot, lambda: "identifying 2.5 s" in text_of(app, "#ident-text"), "stage")
    assert "about" not in text_of(app, "#ident-text")
    assert app.query_one("#ident-progress").progress == 0.0
    r.aircraft.session.send_live(live(4, "comparing with nominal", 1.0, 2.5))
    await until(pilot, lambda: "of about 2.5 s" in text_of(app, "#ident-text"), "expected")
    assert "comparing with nominal 1.0 s" in text_of(app, "#ident-text")
    assert app.query_one("#ident-progress").progress == pytest.approx(40.0)
    r.aircraft.session.send_live(live(5, "comparing with nominal", 9.0, 2.5))
    await until(pilot, lambda: "9.0 s" in text_of(app, "#ident-text"), "overdue")
    assert app.query_one("#ident-progress").progress == 99.0  # an expectation: never 100 %
    r.aircraft.session.send_reliable(result("lat-1"))
    await until(pilot, lambda: "idle" in text_of(app, "#ident-text"), "the run over")


async def test_gains_are_proposed_shown_beside_the_autopilots_applied_and_reverted(console):
    """The Gains tab: G asks, the proposal's rows (autopilot, designed, proposed) and each
    set's loops are drawn, an axis not proposed says why; A applies after a confirmation, V
    reverts; the aircraft's reports shown with the values read back. Bad input tried: an
    apply with no proposal yet (not sent), an apply the aircraft refuses (its reason shown),
    a current set that does not hold the axis (shown as unstable)."""
    app, pilot, r, _ = console
    await pilot.press("6")
    await pilot.pause(0.1)
    assert "no proposal" in drawn(app, "#gains-table")
    sent = len(r.aircraft.inbox)
    await pilot.press("a")
    await pilot.pause(0.2)
    assert len(r.aircraft.inbox) == sent
    assert "no gain proposal to apply" in log_text(app)
    await pilot.press("g")
    await until(pilot, lambda: "lat-1-g1" in drawn(app, "#gains-table"), "proposal")
    table = drawn(app, "#gains-table")
    assert "RLL_RATE_FF" in table
    assert "0.345" in table
    assert "0.69" in table
    loops = drawn(app, "#gains-loops")
    assert "UNSTABLE" in loops
    assert "58°" in loops
    assert "+0.90 s / −1.10 s" in loops  # each way's step where the linkage differs
    assert "55% of the way" in loops
    assert "pitch: the model has no elevator input" in loops
    r.aircraft.refuse["gains-apply"] = "a plan is armed: gains are never changed while one is"
    await pilot.press("a")
    await pilot.press("y")
    await until(pilot, lambda: "REFUSED" in log_text(app), "refusal")
    assert "a plan is armed" in log_text(app)
    del r.aircraft.refuse["gains-apply"]
    await pilot.press("a")
    await pilot.press("y")
    await until(pilot, lambda: "APPLIED" in drawn(app, "#gains-report"), "applied")
    assert "RLL_RATE_FF 0.69" in drawn(app, "#gains-report")
    applied = [m for m in r.aircraft.inbox if isinstance(m, messages.GainsApply)]
    assert [m.proposal for m in applied] == ["lat-1-g1", "lat-1-g1"]
    await pilot.press("v")
    await pilot.press("y")
    await until(pilot, lambda: "REVERTED" in drawn(app, "#gains-report"), "reverted")
    assert any(isinstance(m, messages.GainsRevert) for m in r.aircraft.inbox)
