"""Excite (2): pick a preset or edit a plan, see what it would play (and whether the aircraft
would refuse it) before arming; arm and abort."""

from __future__ import annotations

import json
from collections.abc import Callable

from pydantic import ValidationError
from rich.text import Text
from textual import on
from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical
from textual.widgets import Button, Select, Static, TextArea

from agent.excitation.plan import PRESETS, Plan, preset, refusals, render, summary
from agent.ground.station import GroundStation


class ExciteTab(Vertical):
    def __init__(self, station: GroundStation, send: Callable, **kwargs):
        super().__init__(**kwargs)
        self.station, self.send = station, send
        self.plan: Plan | None = None  # the editor's plan, when valid

    def compose(self) -> ComposeResult:
        with Horizontal(id="preset-row"):
            yield Select(
                [(p, p) for p in PRESETS],
                value="lateral",
                allow_blank=False,
                id="preset",
                compact=True,
            )
            yield Button("Arm F2", id="arm", variant="primary", compact=True)
            yield Button("ABORT F5", id="abort", variant="error", compact=True)
        with Horizontal(id="editor"):
            yield TextArea(id="plan", soft_wrap=False)
            yield Static(id="preview")

    def on_mount(self) -> None:
        self.load_preset("lateral")

    def load_preset(self, name: str) -> None:
        self.query_one("#plan", TextArea).text = json.dumps(preset(name).to_compact(), indent=1)

    @on(Select.Changed, "#preset")
    def _preset_changed(self, event: Select.Changed) -> None:
        self.load_preset(str(event.value))

    @on(TextArea.Changed, "#plan")
    def _plan_changed(self, event: TextArea.Changed) -> None:
        self.preview(event.text_area.text)

    def preview(self, text: str) -> None:
        """Validate the editor's plan and show what it would play, or what is wrong."""
        panel = self.query_one("#preview", Static)
        try:
            plan = Plan.model_validate_json(text)
        except ValidationError as exc:
            self.plan = None
            problems = "\n".join(
                f"{'.'.join(str(p) for p in e['loc']) or 'plan'}: {e['msg']}"
                for e in exc.errors()[:6]
            )
            panel.update(Text(f"not a valid plan:\n{problems}", "red"))
            return
        self.plan = plan
        excitation = self.station.config.excitation
        timeline = render(plan, excitation.rate_hz)
        info = summary(timeline, excitation.surfaces)
        text = Text()
        text.append(f"{plan.id} · {plan.axes} · {info['duration_s']:.1f} s\n", "bold")
        for name, c in info["controls"].items():
            band = "–".join(f"{f:.2f}" for f in c["band_hz"])
            text.append(
                f"{name:<9} peak ±{c['peak']:.1f} {c['unit'] or ''}  "
                f"RPF {c['rpf']:.2f}  {band} Hz\n"
            )
        for warning in info["warnings"]:
            text.append(f"warning: {warning}\n", "yellow")
        for reason in refusals(plan, excitation.rate_hz, excitation.surfaces, excitation.envelope):
            text.append(f"would be refused: {reason}\n", "bold red")
        panel.update(text)

    def arm(self) -> None:
        if self.plan is None:
            self.station.note("error", "the plan in the editor is not valid: not sent")
            return
        plan = self.plan
        self.send(lambda: self.station.arm(plan))

    @on(Button.Pressed, "#arm")
    def _arm_pressed(self) -> None:
        self.arm()

    @on(Button.Pressed, "#abort")
    def _abort_pressed(self) -> None:
        self.send(self.station.abort)
