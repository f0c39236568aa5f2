"""Results (4): every identification heard, newest first; the selected one's TIC, suggestion,
modes, the nominal's modes, the s-plane, and a pair's measured frequency response with the
model's over it (asked of the aircraft); accept, reject, revert."""

from __future__ import annotations

from collections.abc import Callable

from rich.text import Text
from textual import on
from textual.app import ComposeResult
from textual.containers import Horizontal, VerticalScroll
from textual.reactive import var
from textual.widgets import Button, DataTable, Select, Static

from agent.ground.bode import Bode
from agent.ground.splane import Point, SPlane
from agent.ground.station import GroundStation
from agent.ground.widgets import MODE_COLUMNS, Confirm, mode_line, mode_row
from agent.link import messages


class ResultsTab(Horizontal):
    results: var[tuple[str, ...]] = var(())
    """The results heard (their ids, oldest first; the station holds them)."""
    selected: var[str | None] = var(None)
    """The result shown (None: none yet)."""
    nominal: var[tuple[tuple[str, str], ...]] = var(())
    """The aircraft's nominal model of each axes, as its status says."""
    frf: var[tuple[str, str, str] | None] = var(None, always_update=True)
    """The frequency response heard last: (model id, input, output)."""

    def __init__(self, station: GroundStation, send: Callable, **kwargs):
        super().__init__(**kwargs)
        self.station, self.send = station, send
        self._pairs: list[str] = []  # the input → output pairs offered

    def compose(self) -> ComposeResult:
        # Kept as attributes: the watchers (first called once mounted) draw into them.
        self.table = DataTable(id="results", cursor_type="row")
        self.summary = Static(id="summary")
        self.modes = DataTable(id="modes", cursor_type="row")
        self.nominal_title = Static(id="nominal-title")
        self.nominal_modes = DataTable(id="nominal-modes", cursor_type="none")
        self.splane = SPlane(id="splane")
        self.pair = Select([], prompt="input → output", id="frf-pair", compact=True)
        self.bode = Bode(id="bode")
        yield self.table
        with VerticalScroll(id="detail"):
            yield self.summary
            yield self.modes
            yield self.nominal_title
            yield self.nominal_modes
            yield self.splane
            with Horizontal(id="frf-row"):
                yield self.pair
                yield Button("Frequency response f", id="frf-ask", compact=True)
            yield self.bode
            with Horizontal(id="decision"):
                yield Button("Accept y", id="accept", variant="success", compact=True)
                yield Button("Reject n", id="reject", variant="warning", compact=True)
                yield Button("Revert r", id="revert", compact=True)

    def on_mount(self) -> None:
        for table in (self.modes, self.nominal_modes):
            table.add_columns(*MODE_COLUMNS)
        self.table.add_columns("model", "TIC", "sugg.")

    def heard(self, model_id: str | None) -> None:
        """A result was heard (None: those read back at start): list it, and show it."""
        self.results = tuple(self.station.heard.results)
        if model_id is not None or self.selected is None:
            self.selected = model_id or (self.results[-1] if self.results else None)

    def watch_results(self) -> None:
        results = self.station.heard.results
        self.table.clear()
        for model_id in reversed(self.results):
            r = results[model_id]
            self.table.add_row(
                model_id,
                f"{r.tic_avg:.3f}",
                Text("update", "green") if r.suggest_update else Text("no", "red"),
                key=model_id,
            )

    def watch_selected(self) -> None:
        self._detail()

    def watch_nominal(self) -> None:
        self._detail()

    def watch_frf(self) -> None:
        self._show_frf()

    def _detail(self) -> None:
        """The selected result, its nominal's modes and the s-plane (redrawn only when one of
        them changed, so the tables keep where the operator scrolled)."""
        result = self.station.heard.results.get(self.selected or "")
        if result is None:
            self.summary.update("no identification result yet")
            return
        nominal = self.station.nominal(result.axes)
        self.summary.update(_summary(result))
        self.modes.clear()
        for m in result.modes:
            self.modes.add_row(*mode_row(m))
        self.nominal_modes.clear()
        self.nominal_modes.display = nominal is not None
        if nominal is None:
            self.nominal_title.update(Text(f"nominal ({result.axes}): none known here", "grey70"))
        else:
            self.nominal_title.update(
                Text(f"nominal {nominal.model_id}: TIC {nominal.tic_avg:.3f}", "bold")
            )
            for m in nominal.modes:
                self.nominal_modes.add_row(*mode_row(m))
        points = [
            point
            for r in self.station.heard.results.values()
            if r.axes == result.axes and r.model_id != result.model_id
            for point in _points(r, "history")
        ]
        for kind, r in (("nominal", nominal), ("candidate", result)):
            if r is not None:
                points += _points(r, kind)
        self.splane.show(points)
        self.splane.select(None)
        pairs = [f"{i} → {o}" for i in result.inputs for o in result.outputs]
        if pairs != self._pairs:
            self.pair.set_options([(p, p) for p in pairs])
            self._pairs = pairs
        self._show_frf()

    def _pair(self) -> tuple[str, str] | None:
        value = self.pair.value
        if not isinstance(value, str):
            return None
        i, o = value.split(" → ")
        return i, o

    def _show_frf(self) -> None:
        result = self.station.heard.results.get(self.selected or "")
        pair = self._pair()
        report = None
        if result is not None and pair is not None:
            report = self.station.heard.frfs.get((result.model_id, *pair))
        self.bode.show(report, result)

    def ask_frf(self) -> None:
        """Ask the aircraft for the selected result's measured response of the chosen pair."""
        pair = self._pair()
        if self.selected is None or pair is None:
            self.station.note("warning", "pick a result and an input → output pair first")
            return
        model_id = self.selected
        self.send(lambda: self.station.frequency_response(model_id, *pair))
        self.bode.show(
            None, None, f"asked the aircraft for {model_id} {pair[0]} → {pair[1]}: waiting"
        )

    @on(Select.Changed, "#frf-pair")
    def _pair_changed(self) -> None:
        self._show_frf()

    @on(Button.Pressed, "#frf-ask")
    def _ask_pressed(self) -> None:
        self.ask_frf()

    @on(DataTable.RowHighlighted, "#modes")
    def _mode_picked(self, event: DataTable.RowHighlighted) -> None:
        self.splane.select(event.cursor_row)

    @on(DataTable.RowHighlighted, "#results")
    def _select(self, event: DataTable.RowHighlighted) -> None:
        if event.row_key is not None and event.row_key.value in self.station.heard.results:
            self.selected = event.row_key.value

    # -- decisions: each asks first --------------------------------------------------------

    def decide(self, accept: bool) -> None:
        model_id = self.selected
        if model_id is None:
            self.station.note("warning", "no result selected")
            return
        verb = "ACCEPT as nominal" if accept else "REJECT"
        self.app.push_screen(
            Confirm(f"{verb} {model_id}?"),
            lambda yes: yes and self.send(lambda: self.station.decide(model_id, accept)),
        )

    def revert(self) -> None:
        self.app.push_screen(
            Confirm("REVERT to the previous nominal model?"),
            lambda yes: yes and self.send(self.station.revert),
        )

    @on(Button.Pressed, "#accept")
    def _accept_pressed(self) -> None:
        self.decide(True)

    @on(Button.Pressed, "#reject")
    def _reject_pressed(self) -> None:
        self.decide(False)

    @on(Button.Pressed, "#revert")
    def _revert_pressed(self) -> None:
        self.revert()


def _summary(result: messages.Result) -> Text:
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
    return text


def _points(result: messages.Result, kind: str) -> list[Point]:
    """A result's poles on the s-plane (both of a complex pair), with their names, ellipses and
    rows."""
    points = []
    for k, m in enumerate(result.modes):
        std = None if m.real_std is None or m.imag_std is None else (m.real_std, m.imag_std)
        for sign in (1, -1) if m.imag else (1,):
            points.append(
                Point(
                    complex(m.real, sign * m.imag),
                    kind,
                    name=m.name,
                    std=std,
                    row=f"{result.model_id} {mode_line(m)}",
                    index=k,
                )
            )
    return points
