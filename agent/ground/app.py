"""`sysid console`: the operator's terminal app (Textual) on the XBee link.

Tabs: Status (1), Excite (2), Identify (3), Results (4); an event log along the bottom; the
link state, flight mode, excitation state and nominal model in the top line. F5 aborts a run
from anywhere (x too, outside a text field). Every decision asks for confirmation, is sent
reliably, and its acknowledgement (or the aircraft's reason for refusing) is logged. The app
only draws the GroundStation and calls its commands: everything received is in the ground log.
"""

from __future__ import annotations

import json
from typing import ClassVar

from pydantic import ValidationError
from rich.text import Text
from textual import on
from textual.app import App, ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.css.query import NoMatches
from textual.screen import ModalScreen
from textual.widgets import (
    Button,
    Checkbox,
    DataTable,
    Footer,
    Input,
    Label,
    RichLog,
    Select,
    Static,
    TabbedContent,
    TabPane,
    TextArea,
)
from textual.worker import Worker, WorkerState

from agent.excitation.plan import PRESETS, Plan, preset, refusals, render, summary
from agent.ground.splane import Point, SPlane
from agent.ground.station import GroundStation, Line
from agent.link import messages

REFRESH_S = 0.5
LEVEL_STYLE = {"info": "", "warning": "yellow", "error": "bold red"}
MODE_COLUMNS = ("mode", "eigenvalue", "f Hz", "ζ", "τ s", "MSV", "MCI", "MOI", "EMAC", "MPC", "CMI")


def _num(value: float | None, fmt: str = "{:.2f}") -> str:
    return "–" if value is None else fmt.format(value)


def mode_row(m: messages.ModeReport) -> tuple[str, ...]:
    lam = f"{m.real:+.3f}{m.imag:+.3f}j" if m.imag else f"{m.real:+.3f}"
    return (
        m.name or "–",
        lam,
        _num(m.frequency_hz, "{:.3f}"),
        _num(m.damping),
        _num(m.time_constant_s, "{:.2f}"),
        _num(m.msv, "{:.2g}"),
        _num(m.mci, "{:.2g}"),
        _num(m.moi, "{:.2g}"),
        _num(m.emac, "{:.0f}"),
        _num(m.mpc, "{:.0f}"),
        _num(m.cmi, "{:.0f}"),
    )


class Confirm(ModalScreen[bool]):
    """Yes or no, on one key."""

    BINDINGS: ClassVar = [
        ("y", "answer(True)", "yes"),
        ("n", "answer(False)", "no"),
        ("escape", "answer(False)", "no"),
    ]
    DEFAULT_CSS = """
    Confirm { align: center middle; }
    Confirm > Vertical { width: 60; height: auto; border: thick $warning; padding: 1 2;
                         background: $surface; }
    Confirm Horizontal { height: auto; margin-top: 1; }
    Confirm Button { margin-right: 2; }
    """

    def __init__(self, question: str):
        super().__init__()
        self.question = question

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(self.question)
            with Horizontal():
                yield Button("Yes (y)", id="yes", variant="warning")
                yield Button("No (n)", id="no")

    def action_answer(self, answer: bool) -> None:
        self.dismiss(answer)

    @on(Button.Pressed)
    def _pressed(self, event: Button.Pressed) -> None:
        self.dismiss(event.button.id == "yes")


class Console(App):
    """The ground console; `station` is an open (or opening) GroundStation."""

    TITLE = "suas-sysid ground console"
    CSS = """
    Screen { overflow: hidden; }
    #top { height: 1; background: $boost; }
    #tabs { height: 1fr; }
    #tabs > ContentSwitcher { height: 1fr; }
    TabPane { height: 1fr; padding: 0 1; }
    TabPane > Horizontal { height: 1fr; }
    #log { height: 6; border-top: solid $primary; }
    #flight { width: 34; }
    #sensors { height: auto; }
    #preset-row, #buttons, #decision, #settings-buttons { height: auto; margin-bottom: 1; }
    #preset { width: 24; }
    #plan { width: 1fr; min-width: 36; height: 1fr; }
    #preview { width: 1fr; min-width: 30; padding-left: 1; }
    #results { width: 26; }
    #detail { width: 1fr; }
    #modes, #nominal-modes { height: auto; max-height: 10; }
    .stale { color: $text-muted; text-style: italic; }
    Button { margin-right: 1; min-width: 10; }
    #settings Input, #settings Select { width: 24; }
    #settings Horizontal { height: auto; }
    #settings Label { width: 22; }
    #settings Horizontal { margin-bottom: 0; }
    """
    BINDINGS: ClassVar = [
        Binding("f5", "abort", "ABORT", priority=True),
        Binding("x", "abort", "abort", show=False),
        Binding("1", "tab('status')", "status"),
        Binding("2", "tab('excite')", "excite"),
        Binding("3", "tab('identify')", "identify"),
        Binding("4", "tab('results')", "results"),
        Binding("f2", "arm", "arm plan", priority=True),
        Binding("y", "decide(True)", "accept", show=False),
        Binding("n", "decide(False)", "reject", show=False),
        Binding("r", "revert", "revert", show=False),
        Binding("q", "quit", "quit"),
    ]

    def __init__(self, station: GroundStation, *, run_link: bool = True):
        super().__init__()
        self.station = station
        self.run_link = run_link
        self.selected: str | None = None  # the result shown in the Results tab
        self._events_shown = 0
        self._results_shown: list[str] = []
        self._plan: Plan | None = None
        self._main = None  # the main screen, once mounted
        self._detail_key: tuple | None = None  # what the Results detail shows now

    # -- layout -----------------------------------------------------------------------------

    def compose(self) -> ComposeResult:
        yield Static(id="top")
        with TabbedContent(initial="status", id="tabs"):
            with TabPane("Status 1", id="status"), Horizontal():
                yield Static(id="flight")
                with Vertical():
                    yield DataTable(id="sensors", cursor_type="none", zebra_stripes=True)
                    yield Static(id="health")
            with TabPane("Excite 2", id="excite"):
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
                with Horizontal():
                    yield TextArea(id="plan", soft_wrap=False)
                    yield Static(id="preview")
            with TabPane("Identify 3", id="identify"), VerticalScroll(id="settings"):
                yield from self._settings_form()
            with TabPane("Results 4", id="results-tab"), Horizontal():
                yield DataTable(id="results", cursor_type="row")
                with VerticalScroll(id="detail"):
                    yield Static(id="summary")
                    yield DataTable(id="modes", cursor_type="none")
                    yield Static(id="nominal-title")
                    yield DataTable(id="nominal-modes", cursor_type="none")
                    yield SPlane(id="splane")
                    with Horizontal(id="decision"):
                        yield Button("Accept y", id="accept", variant="success", compact=True)
                        yield Button("Reject n", id="reject", variant="warning", compact=True)
                        yield Button("Revert r", id="revert", compact=True)
        yield RichLog(id="log", max_lines=500, wrap=True)
        yield Footer()

    def _settings_form(self) -> ComposeResult:
        axes = [(a, a) for a in ("lateral", "longitudinal", "full")]
        rows = [
            (
                "identification type",
                Select(axes, value="lateral", allow_blank=False, id="axes", compact=True),
            ),
            ("Markov parameters p", Input("auto", id="markov", compact=True)),
            ("model order n", Input("auto", id="order", compact=True)),
            ("batch (stack runs)", Checkbox("on", id="batch", compact=True)),
            ("update period s", Input("", placeholder="none", id="period", compact=True)),
        ]
        for label, widget in rows:
            with Horizontal():
                yield Label(label)
                yield widget
        with Horizontal(id="settings-buttons"):
            yield Button("Send settings", id="send-settings", variant="primary", compact=True)
        yield Static(id="settings-error")
        yield Static(id="settings-now")

    def _q(self, selector: str, kind=None):
        """A widget of the main screen (the app's own query looks at the top screen, which is
        the confirmation dialog while one is open)."""
        return self._main.query_one(selector, kind)

    def on_mount(self) -> None:
        self._main = self.screen
        self._q("#sensors", DataTable).add_columns("sensor", "state", "Hz", "gaps", "CRC", "age s")
        for table in ("#modes", "#nominal-modes"):
            self._q(table, DataTable).add_columns(*MODE_COLUMNS)
        self._q("#results", DataTable).add_columns("model", "TIC", "sugg.")
        self._load_preset("lateral")
        self.station.listeners.append(self._heard)
        if self.run_link:
            self.run_worker(self.station.run(), name="link", exit_on_error=False)
        self.set_interval(REFRESH_S, self.refresh_all)
        self.refresh_all()

    async def on_unmount(self) -> None:
        if self._heard in self.station.listeners:
            self.station.listeners.remove(self._heard)
        await self.station.close()

    # -- refresh ----------------------------------------------------------------------------

    def _heard(self, what: str) -> None:
        if self._main is None:
            return
        if what == "result":
            self.selected = None  # show the newest
        self.refresh_all()

    def refresh_all(self) -> None:
        try:
            self._settings_now()
            self._top()
            self._status()
            self._events()
            self._results()
        except NoMatches:  # the screen is being taken down (quit): nothing left to draw
            return

    def _top(self) -> None:
        q = self.station.link_quality()
        s = self.station.heard.status
        text = Text()
        if q["up"]:
            text.append(" LINK UP ", "bold black on green")
        else:
            text.append(" LINK LOST ", "bold white on red")
        text.append(f" {_num(q['last_heard_s'], '{:.1f}')} s")
        if q["loss"] is not None:
            text.append(f" · loss {100 * q['loss']:.0f}%")
        if q["rssi_dbm"] is not None:
            text.append(f" · {q['rssi_dbm']} dBm")
        if s is not None:
            text.append(f" │ {s.flight_mode or '?'} │ {s.excitation}")
            if s.identifying:
                text.append(" │ identifying", "bold cyan")
            nominal = " ".join(s.nominal.values()) or "none"
            text.append(f" │ nominal {nominal}")
        self._q("#top", Static).update(text)

    def _settings_now(self) -> None:
        now = self.station.settings_in_effect
        if now is None:
            text = "in effect: the aircraft's configured defaults (none sent yet)"
        else:
            period = f"every {now.update_period_s:g} s" if now.update_period_s else "no period"
            text = (
                f"in effect: {now.axes}, p {now.markov}, n {now.order}, "
                f"batch {'on' if now.batch else 'off'}, {period}"
            )
        self._q("#settings-now", Static).update(text)

    def _status(self) -> None:
        s, age = self.station.heard.status, self.station.status_age()
        flight = self._q("#flight", Static)
        if s is None:
            flight.update("no status heard yet")
            return
        stale = age is not None and age > self.station.config.stale_s
        flight.set_class(stale, "stale")
        deg = 57.29577951308232

        def angle(value: float | None) -> str:
            return _num(None if value is None else value * deg, "{:+.1f}°")

        head = Text(
            f"STALE: {age:.0f} s old\n" if stale else f"status {age:.1f} s old\n",
            "bold red" if stale else "green",
        )
        rows = [
            ("mode", s.flight_mode or "?"),
            ("airspeed", _num(s.airspeed, "{:.1f} m/s")),
            ("altitude", _num(s.altitude, "{:.0f} m")),
            ("α / β", f"{_num(s.alpha, '{:+.1f}°')} / {_num(s.beta, '{:+.1f}°')}"),
            ("roll/pitch", f"{angle(s.roll)} / {angle(s.pitch)}"),
            ("yaw", angle(s.yaw)),
            ("excitation", s.excitation),
            ("identifying", "yes" if s.identifying else "no"),
            ("loop lag", _num(s.loop_lag_ms, "{:.1f} ms")),
        ]
        head.append("\n".join(f"{k:<11} {v}" for k, v in rows))
        flight.update(head)
        table = self._q("#sensors", DataTable)
        table.clear()
        for name, h in s.sensors.items():
            state = str(h.get("state", "?"))
            table.add_row(
                name,
                Text(state, "green" if state == "open" else "bold red"),
                _num(h.get("rate_hz"), "{:.0f}"),
                str(int(h.get("gaps") or 0)),
                str(int(h.get("crc_errors") or 0)),
                _num(h.get("age_s"), "{:.2f}"),
            )
        r = s.recorder
        self._q("#health", Static).update(
            f"recorder: {int(r.get('frames', 0))} frames, "
            f"{int(r.get('catch_up_frames', 0))} caught up, "
            f"{int(r.get('out_of_order', 0))} out of order"
        )

    def _events(self) -> None:
        heard = self.station.heard
        fresh = min(heard.noted - self._events_shown, len(heard.events))
        log = self._q("#log", RichLog)
        for line in list(heard.events)[len(heard.events) - fresh :]:
            log.write(self._line(line))
        self._events_shown = heard.noted

    @staticmethod
    def _line(line: Line) -> Text:
        return Text(f"{line.time:9.1f} {line.text}", LEVEL_STYLE[line.level])

    def _results(self) -> None:
        results = self.station.heard.results
        ids = list(results)
        table = self._q("#results", DataTable)
        if ids != self._results_shown:
            table.clear()
            for model_id in reversed(ids):
                r = results[model_id]
                table.add_row(
                    model_id,
                    f"{r.tic_avg:.3f}",
                    Text("update", "green") if r.suggest_update else Text("no", "red"),
                    key=model_id,
                )
            self._results_shown = ids
        if self.selected is None and ids:
            self.selected = ids[-1]
        self._detail()

    def _detail(self) -> None:
        result = self.station.heard.results.get(self.selected or "")
        nominal = self.station.nominal(result.axes) if result is not None else None
        key = (
            self.selected,
            nominal.model_id if nominal else None,
            len(self.station.heard.results),
        )
        if key == self._detail_key:
            return  # nothing new: keep the tables (and where the operator scrolled) as they are
        self._detail_key = key
        summary_w = self._q("#summary", Static)
        modes = self._q("#modes", DataTable)
        if result is None:
            summary_w.update("no identification result yet")
            return
        tic = ", ".join(f"{o} {t:.3f}" for o, t in zip(result.outputs, result.tic, strict=False))
        text = Text()
        text.append(f"{result.model_id} · {result.axes} · ", "bold")
        text.append(
            "stable" if result.stable else "has a divergent mode",
            "green" if result.stable else "yellow",
        )
        text.append(f"\nTIC {tic}; average {result.tic_avg:.3f}\n")
        text.append(
            "suggestion: UPDATE\n" if result.suggest_update else "suggestion: do not update\n",
            "bold green" if result.suggest_update else "bold yellow",
        )
        for step in result.reasons:
            text.append(f"  {step}\n")
        summary_w.update(text)
        modes.clear()
        for m in result.modes:
            modes.add_row(*mode_row(m))
        title = self._q("#nominal-title", Static)
        table = self._q("#nominal-modes", DataTable)
        table.clear()
        table.display = nominal is not None
        if nominal is None:
            title.update(Text(f"nominal ({result.axes}): none known here", "grey70"))
        else:
            title.update(Text(f"nominal {nominal.model_id}: TIC {nominal.tic_avg:.3f}", "bold"))
            for m in nominal.modes:
                table.add_row(*mode_row(m))
        points = [
            Point(complex(m.real, s * m.imag), "history")
            for r in self.station.heard.results.values()
            if r.axes == result.axes
            for m in r.modes
            for s in ((1, -1) if m.imag else (1,))
        ]
        for kind, r in (("candidate", result), ("nominal", nominal)):
            if r is not None:
                points += [
                    Point(complex(m.real, s * m.imag), kind)
                    for m in r.modes
                    for s in ((1, -1) if m.imag else (1,))
                ]
        self._q("#splane", SPlane).show(points)

    def on_worker_state_changed(self, event: Worker.StateChanged) -> None:
        if event.worker.name == "link" and event.state == WorkerState.ERROR:
            self.station.note("error", f"the radio link stopped: {event.worker.error!r}")

    @on(DataTable.RowHighlighted, "#results")
    def _select(self, event: DataTable.RowHighlighted) -> None:
        if event.row_key is not None and event.row_key.value in self.station.heard.results:
            self.selected = event.row_key.value
            self._detail()

    # -- excitation -------------------------------------------------------------------------

    @on(Select.Changed, "#preset")
    def _preset_changed(self, event: Select.Changed) -> None:
        self._load_preset(str(event.value))

    def _load_preset(self, name: str) -> None:
        plan = preset(name)
        self._q("#plan", TextArea).text = json.dumps(plan.to_compact(), indent=1)

    @on(TextArea.Changed, "#plan")
    def _plan_changed(self, event: TextArea.Changed) -> None:
        self._preview(event.text_area.text)

    def _preview(self, text: str) -> None:
        panel = self._q("#preview", Static)
        try:
            plan = Plan.model_validate_json(text)
        except ValidationError as exc:
            self._plan = None
            problems = "\n".join(
                f"{'.'.join(str(p) for p in e['loc']) or 'plan'}: {e['msg']}"
                for e in exc.errors()[:6]
            )
            panel.update(Text(f"not a valid plan:\n{problems}", "red"))
            return
        self._plan = plan
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

    def action_arm(self) -> None:
        if self._plan is None:
            self.station.note("error", "the plan in the editor is not valid: not sent")
            return
        self._send(lambda: self.station.arm(self._plan))

    def action_abort(self) -> None:
        self._send(self.station.abort)

    @on(Button.Pressed, "#arm")
    def _arm_pressed(self) -> None:
        self.action_arm()

    @on(Button.Pressed, "#abort")
    def _abort_pressed(self) -> None:
        self.action_abort()

    # -- identification settings ------------------------------------------------------------

    @on(Button.Pressed, "#send-settings")
    def _send_settings(self) -> None:
        error = self._q("#settings-error", Static)
        period = self._q("#period", Input).value.strip()
        try:
            settings = messages.IdentSettings(
                axes=self._q("#axes", Select).value,
                markov=_auto_int(self._q("#markov", Input).value),
                order=_auto_int(self._q("#order", Input).value),
                batch=self._q("#batch", Checkbox).value,
                update_period_s=float(period) if period else None,
            )
        except (ValidationError, ValueError) as exc:
            error.update(Text(f"not sent: {_first_error(exc)}", "red"))
            return
        error.update("")
        self._send(lambda: self.station.settings(settings))

    # -- decisions --------------------------------------------------------------------------

    def action_decide(self, accept: bool) -> None:
        if self._q("#tabs", TabbedContent).active != "results-tab":
            return
        model_id = self.selected
        if model_id is None:
            self.station.note("warning", "no result selected")
            return
        verb = "ACCEPT as nominal" if accept else "REJECT"
        self.push_screen(
            Confirm(f"{verb} {model_id}?"),
            lambda yes: yes and self._send(lambda: self.station.decide(model_id, accept)),
        )

    def action_revert(self) -> None:
        if self._q("#tabs", TabbedContent).active != "results-tab":
            return
        self.push_screen(
            Confirm("REVERT to the previous nominal model?"),
            lambda yes: yes and self._send(self.station.revert),
        )

    @on(Button.Pressed, "#accept")
    def _accept_pressed(self) -> None:
        self.action_decide(True)

    @on(Button.Pressed, "#reject")
    def _reject_pressed(self) -> None:
        self.action_decide(False)

    @on(Button.Pressed, "#revert")
    def _revert_pressed(self) -> None:
        self.action_revert()

    # -- helpers ----------------------------------------------------------------------------

    def action_tab(self, tab: str) -> None:
        self._q("#tabs", TabbedContent).active = "results-tab" if tab == "results" else tab

    def _send(self, command) -> None:
        try:
            command()
        except RuntimeError as exc:  # the radio is not open
            self.station.note("error", f"not sent: {exc}")
        self.refresh_all()


def _auto_int(text: str) -> int | str:
    text = text.strip().lower()
    return "auto" if text in ("", "auto") else int(text)


def _first_error(exc: Exception) -> str:
    if isinstance(exc, ValidationError):
        e = exc.errors()[0]
        return f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}"
    return str(exc)
