"""`sysid sim --interactive` under Textual's pilot: the operator arms the lateral preset from
the console, the simulated pilot flips the switch, the real agent identifies in its worker,
the result crosses the emulated radios and renders, and the operator's accept makes it the
aircraft's nominal model.

SAVE_SCREENSHOT=DIR also writes the console's screens as SVG there (the pictures in the README
and docs/console.md: `make screenshot`).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from agent.sim.flight import SimOptions, console_flight
from tests.ground.test_console import log_text, text_of, until

pytestmark = [pytest.mark.usefixtures("no_leaked_tasks"), pytest.mark.timeout(180)]


async def test_operator_flies_the_lateral_preset_from_the_console(tmp_path):
    save = os.environ.get("SAVE_SCREENSHOT")
    flight = console_flight(SimOptions(preset="lateral", directory=tmp_path))
    async with flight as (sim, app), app.run_test(size=(120, 40)) as pilot:
        station = app.station
        await until(pilot, lambda: station.link_up, "link up")
        await until(pilot, lambda: "m/s" in text_of(app, "#flight"), "status")
        if save:
            Path(save).mkdir(parents=True, exist_ok=True)
            app.save_screenshot("console-status.svg", path=save)
        await pilot.press("2")
        await pilot.press("f2")
        await until(pilot, lambda: "arm lateral: acknowledged" in log_text(app), "ack")
        await until(pilot, lambda: "lateral started" in log_text(app), "start")
        # The live view while the plan plays: its progress, and strip charts of the commands,
        # the surfaces and the lateral responses, in display units.
        await pilot.press("5")
        await until(
            pilot,
            lambda: (
                station.heard.live is not None and (station.heard.live.plan_fraction or 0) > 0.1
            ),
            "the plan's progress",
        )
        strips = station.heard.strips
        assert {"aileron_cmd", "rudder_cmd", "aileron", "rudder", "beta", "p", "r", "phi"} <= set(
            strips
        )
        command = [v for _, v in strips["aileron_cmd"] if v is not None]
        assert max(abs(v) for v in command) > 1.0  # degrees: the plan's doublets are playing
        # The surface is shown from its trim, as its command is: it starts near zero.
        surface = [v for _, v in strips["aileron"] if v is not None]
        assert abs(surface[0]) < 1.0, surface[:5]
        await until(pilot, lambda: "lateral" in text_of(app, "#plan-text"), "the progress text")
        if save:
            app.save_screenshot("console-live.svg", path=save)
        await until(pilot, lambda: station.heard.results, "the result")
        await pilot.press("4")
        await pilot.pause(0.5)
        model_id = next(iter(station.heard.results))
        assert model_id in text_of(app, "#summary")
        assert app.query_one("#modes").row_count >= 2
        if save:
            app.save_screenshot("console-results.svg", path=save)
        await pilot.press("y")
        await pilot.press("y")
        await until(pilot, lambda: f"accept {model_id}: acknowledged" in log_text(app), "accept")
        await until(pilot, lambda: f"nominal {model_id}" in text_of(app, "#top"), "nominal")
    assert sim.agent.models.nominal_id("lateral") == model_id
    assert not sim.aircraft.pilot.switch_high  # the pilot took the switch back after the run
    ground_logs = list((tmp_path / "ground-logs").glob("*_ground_*.jsonl"))
    assert ground_logs
    assert model_id in ground_logs[0].read_text()
    # The live view went on after the plan: the margin recorded, then the identification.
    records = [json.loads(line) for line in ground_logs[0].read_text().splitlines()]
    stages = {r["message"].get("stage") for r in records if r["message"].get("kind") == "live"}
    assert "recording margin" in stages
    # The margin's bar runs against its known length ([recorder] excitation_margin_s).
    margins = [
        r["message"]
        for r in records
        if r["message"].get("kind") == "live" and r["message"].get("stage") == "recording margin"
    ]
    assert all(
        m["stage_expected_s"] == sim.agent.config.recorder.excitation_margin_s for m in margins
    )
