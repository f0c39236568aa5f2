"""Live (5): while a plan plays and its window is identified — the plan's progress, the
identification's stage and progress, and strip charts of the last STRIP_S seconds as lines
(`agent.ground.strip`): each surface as measured (cyan) with its command (yellow, from trim)
on the same chart, then the responses the plan's axis identifies, each with its latest values
and the chart's range."""

from __future__ import annotations

from rich.text import Text
from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.reactive import var
from textual.widgets import Label, ProgressBar, Static

from agent.channels import UNITS
from agent.ground.station import STRIP_S, GroundStation
from agent.ground.strip import Strip, scale_of
from agent.link import messages

COMMANDED, MEASURED = "yellow", "cyan"
# Display units of the live view (`messages.Live`): angles in degrees.
DISPLAY_UNITS = {"rad": "°", "deg": "°", "rad/s": "°/s"}


class LiveTab(Vertical):
    live: var[messages.Live | None] = var(None, always_update=True)
    """The latest frame of the run (None: none playing or being identified); each frame's
    samples are already in the station's strips, so every frame redraws the charts."""

    def __init__(self, station: GroundStation, **kwargs):
        super().__init__(**kwargs)
        self.station = station
        self._rows: dict[str, tuple[Strip, Static]] = {}  # the charts shown, in order

    def compose(self) -> ComposeResult:
        # Kept as attributes: the watcher (first called once mounted) draws into them.
        self.plan_bar = ProgressBar(total=100, show_eta=False, id="plan-progress")
        self.plan_text = Static(id="plan-text")
        self.ident_bar = ProgressBar(total=100, show_eta=False, id="ident-progress")
        self.ident_text = Static(id="ident-text")
        self.strips = VerticalScroll(id="strips")
        with Horizontal(classes="progress-row"):
            yield Label("plan", classes="progress-label")
            yield self.plan_bar
            yield self.plan_text
        with Horizontal(classes="progress-row"):
            yield Label("identification", classes="progress-label")
            yield self.ident_bar
            yield self.ident_text
        yield self.strips

    def watch_live(self) -> None:
        live = self.live
        if live is None or live.plan_fraction is None:
            self.plan_bar.update(progress=0 if live is None else 100)
            self.plan_text.update("no plan playing" if live is None else "played")
        else:
            self.plan_bar.update(progress=100 * live.plan_fraction)
            self.plan_text.update(
                f"{live.plan_id}: {live.plan_fraction * live.plan_s:.0f} of {live.plan_s:.0f} s"
            )
        self.ident_bar.update(progress=self._ident_progress(live))
        self.ident_text.update(self._ident_text(live))
        self._strips()

    def _ident_progress(self, live) -> float:
        """The stage's time against what the aircraft expects it to take (at most 99 %: an
        expectation, not a measure of the work done)."""
        if live is None or not live.stage or not live.stage_expected_s:
            return 0.0
        return min(99.0, 100 * (live.stage_s or 0.0) / max(live.stage_expected_s, 0.1))

    def _ident_text(self, live) -> Text:
        if live is None or not live.stage:
            return Text("idle", "grey50")
        text = Text(f"{live.stage} {live.stage_s or 0:.1f} s", "bold cyan")
        if live.stage_expected_s:
            text.append(f" of about {live.stage_expected_s:.1f} s", "grey70")
        return text

    def _strips(self) -> None:
        strips = self.station.heard.strips
        names = sorted({n.removesuffix("_cmd") for n in strips}, key=_order)
        if names != list(self._rows):
            self.strips.remove_children()
            self._rows = {
                name: (
                    Strip(STRIP_S, id=f"strip-{name}", classes="strip"),
                    Static(id=f"value-{name}", classes="strip-value"),
                )
                for name in names
            }
            self.strips.mount_all(
                Horizontal(Label(name, classes="strip-label"), strip, value, classes="strip-row")
                for name, (strip, value) in self._rows.items()
            )
        for name, (strip, value) in self._rows.items():
            strip.show(
                [
                    (strips[key], colour)
                    for key, colour in ((f"{name}_cmd", COMMANDED), (name, MEASURED))
                    if key in strips
                ]
            )
            value.update(_values(name, strips))


def _values(name: str, strips) -> Text:
    """The latest commanded (yellow) and measured (cyan) values, and the chart's range."""
    unit = _unit(name)
    text = Text()
    for key, colour in ((f"{name}_cmd", COMMANDED), (name, MEASURED)):
        if key in strips:
            latest = next((v for _, v in reversed(strips[key]) if v is not None), None)
            text.append("–" if latest is None else f"{latest:+.1f}", colour)
            text.append(" ")
    text.append(unit)
    scale = scale_of([(strips[k], "") for k in (f"{name}_cmd", name) if k in strips])
    if scale is not None:
        text.append(f"\n{scale[0]:+.1f} … {scale[1]:+.1f}", "grey50")
    return text


def _order(name: str) -> tuple[int, str]:
    """The surfaces first (each with its command on the same chart), then the responses."""
    return (0 if name in ("throttle", "elevator", "aileron", "rudder") else 1, name)


def _unit(name: str) -> str:
    unit = UNITS.get(name.removesuffix("_cmd"), "")
    return DISPLAY_UNITS.get(unit, unit)
