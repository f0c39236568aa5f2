"""`sysid console`: the operator's terminal app (Textual) on the XBee link.

Tabs: Status (1), Excite (2), Identify (3), Results (4), Live (5), one widget each
(`agent/ground/tabs/`);
an event log along the bottom; the link state, flight mode, excitation state and nominal model
in the top line. F5 aborts a run from anywhere (x too, outside a text field). Every decision
asks for confirmation, is sent reliably, and its acknowledgement (or the aircraft's reason for
refusing) is logged. The app only draws the GroundStation and calls its commands: everything
received is in the ground log. The layout is `console.tcss`.
"""

from __future__ import annotations

from typing import ClassVar

from rich.text import Text
from textual.app import App, ComposeResult
from textual.binding import Binding
from textual.css.query import NoMatches
from textual.widgets import Footer, RichLog, Static, TabbedContent, TabPane
from textual.worker import Worker, WorkerState

from agent.ground.station import GroundStation, Line
from agent.ground.tabs.excite import ExciteTab
from agent.ground.tabs.identify import IdentifyTab
from agent.ground.tabs.live import LiveTab
from agent.ground.tabs.results import ResultsTab
from agent.ground.tabs.status import StatusTab
from agent.ground.widgets import num

REFRESH_S = 0.5
LEVEL_STYLE = {"info": "", "warning": "yellow", "error": "bold red"}


class Console(App):
    """The ground console; `station` is an open (or opening) GroundStation."""

    TITLE = "suas-sysid ground console"
    CSS_PATH = "console.tcss"
    BINDINGS: ClassVar = [
        Binding("f5", "abort", "ABORT", priority=True),
        Binding("x", "abort", "abort", show=False),
        Binding("1", "tab('status')", "status"),
        Binding("2", "tab('excite')", "excite"),
        Binding("3", "tab('identify')", "identify"),
        Binding("4", "tab('results')", "results"),
        Binding("5", "tab('live')", "live"),
        Binding("f2", "arm", "arm plan", priority=True),
        Binding("y", "decide(True)", "accept", show=False),
        Binding("n", "decide(False)", "reject", show=False),
        Binding("r", "revert", "revert", show=False),
        Binding("f", "frf", "frequency response", show=False),
        Binding("q", "quit", "quit"),
    ]

    def __init__(self, station: GroundStation, *, run_link: bool = True):
        super().__init__()
        self.station = station
        self.run_link = run_link
        self._events_shown = 0
        self._mounted = False
        self.status_tab = StatusTab(station)
        self.excite_tab = ExciteTab(station, self.send)
        self.identify_tab = IdentifyTab(station, self.send, id="settings")
        self.results_tab = ResultsTab(station, self.send)
        self.live_tab = LiveTab(station)

    @property
    def selected(self) -> str | None:
        """The result shown in the Results tab."""
        return self.results_tab.selected

    def compose(self) -> ComposeResult:
        yield Static(id="top")
        with TabbedContent(initial="status", id="tabs"):
            with TabPane("Status 1", id="status"):
                yield self.status_tab
            with TabPane("Excite 2", id="excite"):
                yield self.excite_tab
            with TabPane("Identify 3", id="identify"):
                yield self.identify_tab
            with TabPane("Results 4", id="results-tab"):
                yield self.results_tab
            with TabPane("Live 5", id="live"):
                yield self.live_tab
        yield RichLog(id="log", max_lines=500, wrap=True)
        yield Footer()

    def on_mount(self) -> None:
        self._mounted = True
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
        if not self._mounted:
            return
        if what == "result":
            self.results_tab.selected = None  # show the newest
        self.refresh_all()

    def refresh_all(self) -> None:
        try:
            self.identify_tab.show()
            self._top()
            self.status_tab.show()
            self._events()
            self.results_tab.show()
            self.live_tab.show()
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
        text.append(f" {num(q['last_heard_s'], '{:.1f}')} s")
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
        self._main_screen().query_one("#top", Static).update(text)

    def _events(self) -> None:
        heard = self.station.heard
        fresh = min(heard.noted - self._events_shown, len(heard.events))
        log = self._main_screen().query_one("#log", RichLog)
        for line in list(heard.events)[len(heard.events) - fresh :]:
            log.write(_line(line))
        self._events_shown = heard.noted

    def _main_screen(self):
        """The main screen (the app's own query looks at the top screen, which is the
        confirmation dialog while one is open)."""
        return self.screen_stack[0]

    def on_worker_state_changed(self, event: Worker.StateChanged) -> None:
        if event.worker.name == "link" and event.state == WorkerState.ERROR:
            self.station.note("error", f"the radio link stopped: {event.worker.error!r}")

    # -- actions from anywhere --------------------------------------------------------------

    def action_tab(self, tab: str) -> None:
        self._tabs().active = "results-tab" if tab == "results" else tab

    def action_arm(self) -> None:
        self.excite_tab.arm()

    def action_abort(self) -> None:
        self.send(self.station.abort)

    def action_decide(self, accept: bool) -> None:
        if self._tabs().active == "results-tab":
            self.results_tab.decide(accept)

    def action_revert(self) -> None:
        if self._tabs().active == "results-tab":
            self.results_tab.revert()

    def action_frf(self) -> None:
        if self._tabs().active == "results-tab":
            self.results_tab.ask_frf()

    def _tabs(self) -> TabbedContent:
        return self._main_screen().query_one("#tabs", TabbedContent)

    def send(self, command) -> None:
        """Carry out a station command; one the radio cannot take is logged, not raised."""
        try:
            command()
        except RuntimeError as exc:  # the radio is not open
            self.station.note("error", f"not sent: {exc}")
        self.refresh_all()


def _line(line: Line) -> Text:
    return Text(f"{line.time:9.1f} {line.text}", LEVEL_STYLE[line.level])
