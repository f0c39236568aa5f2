"""`sysid console`: the operator's terminal app (Textual) on the XBee link.

Tabs: Status (1), Excite (2), Identify (3), Results (4), Live (5), Gains (6), one widget each
(`agent/ground/tabs/`);
an event log along the bottom; the link state, flight mode, excitation state and nominal model
in the top line. F5 aborts a run from anywhere (x too, outside a text field). Every decision
asks for confirmation, is sent reliably, and its acknowledgement (or the aircraft's reason for
refusing) is logged. The app only draws the GroundStation and calls its commands: everything
received is in the ground log. The layout is `console.tcss`.

Nothing is redrawn on a timer: the station hands each thing it hears to the app as a typed
event, the app posts it to itself as a Textual message (`agent.ground.posted`), and its
handlers set the reactive state of the tab that shows it, which redraws what changed. One
timer (`ticker`) updates the values that change with time passing alone: the link's liveness
and the status's age.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from rich.text import Text
from textual.app import App, ComposeResult
from textual.binding import Binding
from textual.reactive import var
from textual.timer import Timer
from textual.widgets import Footer, RichLog, Static, TabbedContent, TabPane
from textual.worker import Worker, WorkerState

from agent.ground import events, posted
from agent.ground.events import Line
from agent.ground.station import GroundStation
from agent.ground.tabs.excite import ExciteTab
from agent.ground.tabs.gains import GainsTab
from agent.ground.tabs.identify import IdentifyTab
from agent.ground.tabs.live import LiveTab
from agent.ground.tabs.results import ResultsTab
from agent.ground.tabs.status import StatusTab
from agent.ground.widgets import num
from agent.link import messages

# The link is lost when no frame came for its deadline, and a status grows old, with nothing
# heard: time passing is their only event, so the ticker looks at them this often (the
# seconds shown to a tenth; a lost link shown within half a second).
TICK_S = 0.5
LEVEL_STYLE = {"info": "", "warning": "yellow", "error": "bold red"}


@dataclass(frozen=True, kw_only=True)
class LinkView:
    """The top line's link indicators, as shown (so an unchanged one redraws nothing)."""

    up: bool
    last_heard_s: float | None
    loss_percent: int | None
    rssi_dbm: int | None


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
        Binding("6", "tab('gains')", "gains"),
        Binding("f3", "size", "size plan", priority=True),
        Binding("f2", "arm", "arm plan", priority=True),
        Binding("y", "decide(True)", "accept", show=False),
        Binding("n", "decide(False)", "reject", show=False),
        Binding("r", "revert", "revert", show=False),
        Binding("f", "frf", "frequency response", show=False),
        Binding("g", "gains('propose')", "propose gains", show=False),
        Binding("a", "gains('apply')", "apply gains", show=False),
        Binding("v", "gains('revert')", "revert gains", show=False),
        Binding("q", "quit", "quit"),
    ]

    link: var[LinkView | None] = var(None, init=False)
    """The link's indicators, from the ticker."""
    status: var[messages.Status | None] = var(None, init=False)
    """The status last heard (the top line's flight mode, excitation and nominal)."""

    def __init__(self, station: GroundStation, *, run_link: bool = True):
        super().__init__()
        self.station = station
        self.run_link = run_link
        self.ticker: Timer | None = None  # the one timer (TICK_S), once mounted
        self.status_tab = StatusTab(station.config.stale_s)
        self.excite_tab = ExciteTab(station, self.send)
        self.identify_tab = IdentifyTab(station, self.send, id="settings")
        self.results_tab = ResultsTab(station, self.send)
        self.live_tab = LiveTab(station)
        self.gains_tab = GainsTab(station, self.send)

    @property
    def selected(self) -> str | None:
        """The result shown in the Results tab."""
        return self.results_tab.selected

    def compose(self) -> ComposeResult:
        self.top = Static(id="top")
        self.log_pane = RichLog(id="log", max_lines=500, wrap=True)
        yield self.top
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
            with TabPane("Gains 6", id="gains"):
                yield self.gains_tab
        yield self.log_pane
        yield Footer()

    def on_mount(self) -> None:
        for line in self.station.heard.events:  # noted before the screen was up
            self.log_pane.write(_line(line))
        self.results_tab.heard(None)  # results read back from earlier ground logs
        self.station.subscribe(self._heard)
        if self.run_link:
            self.run_worker(self.station.run(), name="link", exit_on_error=False)
        self.ticker = self.set_interval(TICK_S, self._tick)
        self._tick()
        self._top()

    async def on_unmount(self) -> None:
        self.station.unsubscribe(self._heard)
        await self.station.close()

    # -- what the station heard: one handler each ----------------------------------------------

    def _heard(self, event: events.Event) -> None:
        """The station's subscriber: each event becomes a message to this app (the station
        runs on the app's loop; post_message would also take it from another thread)."""
        self.post_message(posted.posted(event))

    def on_status_heard(self, message: posted.StatusHeard) -> None:
        status = message.heard.status
        self._look_at_link()  # a frame just heard: the link is up
        self.status = status
        self.status_tab.status = status
        self.status_tab.age = round(self.station.clock.now() - message.heard.at, 1)
        self.results_tab.nominal = tuple(sorted(status.nominal.items()))
        self.identify_tab.reported = status.settings

    def on_live_frame(self, message: posted.LiveFrame) -> None:
        self.live_tab.live = message.heard.live

    def on_result_heard(self, message: posted.ResultHeard) -> None:
        self.results_tab.heard(message.heard.result.model_id)

    def on_frf_heard(self, message: posted.FrfHeard) -> None:
        r = message.heard.report
        self.results_tab.frf = (r.model_id, r.input, r.output)

    def on_sizing_heard(self, message: posted.SizingHeard) -> None:
        self.excite_tab.sized(message.heard.sizing)

    def on_gains_heard(self, message: posted.GainsHeard) -> None:
        heard = message.heard
        if heard.gains is not None:
            self.gains_tab.gains = heard.gains
        if heard.report is not None:
            self.gains_tab.report = heard.report

    def on_ack_heard(self, message: posted.AckHeard) -> None:
        command = message.heard.command
        if isinstance(command.message, messages.IdentSettings):
            self.identify_tab.answered(command)

    def on_noted(self, message: posted.Noted) -> None:
        self.log_pane.write(_line(message.heard.line))

    # -- time passing -----------------------------------------------------------------------

    def _tick(self) -> None:
        """The values that change with time alone: the link's liveness and the status's age
        (each redraws only when its shown value changed)."""
        self._look_at_link()
        age = self.station.status_age()
        self.status_tab.age = None if age is None else round(age, 1)

    def _look_at_link(self) -> None:
        q = self.station.link_quality()
        heard = q["last_heard_s"]
        self.link = LinkView(
            up=q["up"],
            last_heard_s=None if heard is None else round(heard, 1),
            loss_percent=None if q["loss"] is None else round(100 * q["loss"]),
            rssi_dbm=q["rssi_dbm"],
        )

    def watch_link(self) -> None:
        self._top()

    def watch_status(self) -> None:
        self._top()

    def _top(self) -> None:
        link, s = self.link, self.status
        text = Text()
        if link is not None and link.up:
            text.append(" LINK UP ", "bold black on green")
        else:
            text.append(" LINK LOST ", "bold white on red")
        text.append(f" {num(None if link is None else link.last_heard_s, '{:.1f}')} s")
        if link is not None and link.loss_percent is not None:
            text.append(f" · loss {link.loss_percent}%")
        if link is not None and link.rssi_dbm is not None:
            text.append(f" · {link.rssi_dbm} dBm")
        if s is not None:
            text.append(f" │ {s.flight_mode or '?'} │ {s.excitation}")
            if s.identifying:
                text.append(" │ identifying", "bold cyan")
            nominal = " ".join(s.nominal.values()) or "none"
            text.append(f" │ nominal {nominal}")
        self.top.update(text)

    def on_worker_state_changed(self, event: Worker.StateChanged) -> None:
        if event.worker.name == "link" and event.state == WorkerState.ERROR:
            self.station.note("error", f"the radio link stopped: {event.worker.error!r}")

    # -- actions from anywhere --------------------------------------------------------------

    def action_tab(self, tab: str) -> None:
        self._tabs().active = "results-tab" if tab == "results" else tab

    def action_arm(self) -> None:
        self.excite_tab.arm()

    def action_size(self) -> None:
        self.excite_tab.request_sizing()

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

    def action_gains(self, what: str) -> None:
        if self._tabs().active == "gains":
            getattr(self.gains_tab, what)()

    def _tabs(self) -> TabbedContent:
        """The tabs (the app's own query looks at the top screen, which is the confirmation
        dialog while one is open)."""
        return self.screen_stack[0].query_one("#tabs", TabbedContent)

    def send(self, command) -> None:
        """Carry out a station command; one the radio cannot take is logged, not raised."""
        try:
            command()
        except RuntimeError as exc:  # the radio is not open
            self.station.note("error", f"not sent: {exc}")


def _line(line: Line) -> Text:
    return Text(f"{line.time:9.1f} {line.text}", LEVEL_STYLE[line.level])
