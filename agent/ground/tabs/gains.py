"""Gains (6): ArduPlane's FBWA roll and pitch gains designed onboard from the nominal model
(agent/runtime/gains.py, docs/tuning.md). G asks for a proposal: each gain as the autopilot
holds it, as designed and as the proposal sets it (a step toward the design where a gain
would change by more than [tuning] max_step), and each set's predicted loop — crossover, phase
and gain margins, delay margin, disturbance rejection, a step's rise and overshoot. A applies
the proposal, V reverts to the set it replaced; each asks for confirmation. The last apply,
revert or failure is shown with the values the autopilot read back."""

from __future__ import annotations

from collections.abc import Callable

from rich.table import Table
from rich.text import Text
from textual import on
from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical
from textual.reactive import var
from textual.widgets import Button, Static

from agent.ground.station import GroundStation
from agent.ground.widgets import Confirm, num
from agent.link import messages


class GainsTab(Vertical):
    gains: var[messages.Gains | None] = var(None, init=False)
    """The latest proposal heard."""
    report: var[messages.GainsReport | None] = var(None, init=False)
    """What became of the autopilot's gains last."""

    def __init__(self, station: GroundStation, send: Callable, **kwargs):
        super().__init__(**kwargs)
        self.station, self.send = station, send

    def compose(self) -> ComposeResult:
        with Horizontal(id="gains-row"):
            yield Button("Propose G", id="propose", compact=True)
            yield Button("Apply A", id="apply", variant="primary", compact=True)
            yield Button("Revert V", id="revert-gains", variant="warning", compact=True)
        yield Static(id="gains-table")
        yield Static(id="gains-loops")
        yield Static(id="gains-report")

    def on_mount(self) -> None:
        self.watch_gains()
        self.watch_report()

    def watch_gains(self) -> None:
        table = self.query_one("#gains-table", Static)
        loops = self.query_one("#gains-loops", Static)
        g = self.gains
        if g is None:
            table.update(Text("no proposal: G asks for gains designed from the nominal model"))
            loops.update("")
            return
        t = Table(title=f"{g.proposal} from {g.model_id}", title_justify="left", expand=False)
        for column in ("parameter", "autopilot", "designed", "proposed"):
            t.add_column(column, justify="left" if column == "parameter" else "right")
        for r in g.rows:
            changed = r.proposed is not None and r.current is not None
            style = "bold" if changed and abs(r.proposed - r.current) > 1e-6 else ""
            t.add_row(
                r.name,
                num(r.current, "{:.4g}"),
                f"{r.designed:.4g}",
                Text(num(r.proposed, "{:.4g}"), style),
            )
        table.update(t)
        lp = Table(expand=False)
        for column in (
            "axis",
            "gains",
            "crossover rad/s",
            "phase margin",
            "gain margin",
            "delay margin",
            "rejection rad/s",
            "rise",
            "overshoot",
        ):
            lp.add_column(column, justify="left" if column in ("axis", "gains") else "right")
        for p in g.loops:
            if not p.stable:
                lp.add_row(p.axis, p.gains, Text("UNSTABLE with these gains", "bold red"))
                continue
            style = "" if p.sound else "yellow"
            lp.add_row(
                p.axis,
                p.gains,
                num(p.crossover_rad_s, "{:.2f}"),
                Text(num(p.phase_margin_deg, "{:.0f}°"), style),
                Text("∞" if p.gain_margin_db is None else f"{p.gain_margin_db:.1f} dB", style),
                num(p.delay_margin_s, "{:.3f} s"),
                num(p.rejection_rad_s, "{:.2f}"),
                _each_way(p.rise_s, p.rise_down_s, "{:.2f} s"),
                _each_way(p.overshoot_pct, p.overshoot_down_pct, "{:.1f} %"),
            )
        text = Text()
        for axis, share in g.share.items():
            text.append(f"{axis}: {share:.0%} of the way to the design\n")
        for line in g.refused:
            text.append(f"not proposed: {line}\n", "yellow")
        for line in g.notes:
            text.append(f"note: {line}\n")
        loops.update(_stacked(lp, text))

    def watch_report(self) -> None:
        panel = self.query_one("#gains-report", Static)
        r = self.report
        if r is None:
            panel.update("")
            return
        style = {"applied": "green", "reverted": "yellow", "failed": "bold red"}[r.action]
        text = Text(f"{r.action.upper()} {r.proposal or ''}: {r.reason}\n", style)
        if r.values:
            text.append(", ".join(f"{k} {v:g}" for k, v in r.values.items()) + " (read back)")
        panel.update(text)

    def propose(self) -> None:
        self.send(self.station.propose_gains)

    def apply(self) -> None:
        g = self.gains
        if g is None:
            self.station.note("warning", "no gain proposal to apply: G asks for one")
            return
        self.app.push_screen(
            Confirm(f"APPLY {g.proposal} to the autopilot?"),
            lambda yes: yes and self.send(lambda: self.station.apply_gains(g.proposal)),
        )

    def revert(self) -> None:
        self.app.push_screen(
            Confirm("REVERT the autopilot's gains to the set the last apply replaced?"),
            lambda yes: yes and self.send(self.station.revert_gains),
        )

    @on(Button.Pressed, "#propose")
    def _propose_pressed(self) -> None:
        self.propose()

    @on(Button.Pressed, "#apply")
    def _apply_pressed(self) -> None:
        self.apply()

    @on(Button.Pressed, "#revert-gains")
    def _revert_pressed(self) -> None:
        self.revert()


def _stacked(table: Table, text: Text) -> Table:
    grid = Table.grid()
    grid.add_row(table)
    grid.add_row(text)
    return grid


def _each_way(value: float | None, down: float | None, fmt: str) -> str:
    """A predicted step's figure, and the other way's beside it where the linkage's travel
    differs each way ("+ … / − …")."""
    if down is None:
        return num(value, fmt)
    return f"+{num(value, fmt)} / −{num(down, fmt)}"
