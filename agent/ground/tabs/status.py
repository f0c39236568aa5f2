"""Status (1): the vehicle as last heard — flight state, the sensors' health, the recorder;
and how old that is (STALE past `stale_s`)."""

from __future__ import annotations

from rich.text import Text
from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical
from textual.reactive import var
from textual.widgets import DataTable, Static

from agent.ground.widgets import num
from agent.link import messages

DEG = 57.29577951308232


class StatusTab(Horizontal):
    status: var[messages.Status | None] = var(None)
    """The status last heard."""
    age: var[float | None] = var(None)
    """Its age in seconds, to a tenth (set when one is heard, then by the app's ticker)."""
    stale: var[bool] = var(False)
    """Older than `stale_s`: the whole panel says so."""

    def __init__(self, stale_s: float, **kwargs):
        super().__init__(**kwargs)
        self.stale_s = stale_s

    def compose(self) -> ComposeResult:
        # Kept as attributes: the watchers (first called once mounted) draw into them.
        self.age_line = Static(id="status-age")
        self.flight = Static(id="flight")
        self.sensors = DataTable(id="sensors", cursor_type="none", zebra_stripes=True)
        self.health = Static(id="health")
        with Vertical(id="flight-panel"):
            yield self.age_line
            yield self.flight
        with Vertical():
            yield self.sensors
            yield self.health

    def on_mount(self) -> None:
        self.sensors.add_columns("sensor", "state", "Hz", "gaps", "CRC", "age s")

    def watch_age(self) -> None:
        age = self.age
        if self.status is None or age is None:
            self.age_line.update("no status heard yet")
            return
        self.stale = stale = age > self.stale_s
        self.age_line.update(
            Text(f"STALE: {age:.0f} s old" if stale else f"status {age:.1f} s old", _style(stale))
        )

    def watch_stale(self) -> None:
        for widget in (self.age_line, self.flight):
            widget.set_class(self.stale, "stale")
        self._flight()

    def watch_status(self) -> None:
        s = self.status
        if s is None:
            return
        self._flight()
        self._sensors(s)
        r = s.recorder
        # Each number is what its label says: frames recorded (of them, assembled after a
        # late wake-up; and how often assembling waited for a live sensor's late sample),
        # samples dropped as stamped before one already held, log lines lost.
        self.health.update(
            f"frames     {int(r.get('frames', 0))} ({int(r.get('catch_up_frames', 0))} late, "
            f"{int(r.get('waited_frames', 0))} waited)\n"
            f"dropped    {int(r.get('late_samples', 0))} late samples\n"
            f"log lost   {int(r.get('log_lost_lines', 0))} lines"
        )

    def _flight(self) -> None:
        """The flight state, in the colour of its freshness."""
        s = self.status
        if s is None:
            return

        def angle(value: float | None) -> str:
            return num(None if value is None else value * DEG, "{:+.1f}°")

        rows = [
            ("mode", s.flight_mode or "?"),
            ("airspeed", num(s.airspeed, "{:.1f} m/s")),
            ("altitude", num(s.altitude, "{:.0f} m")),
            ("α / β", f"{num(s.alpha, '{:+.1f}°')} / {num(s.beta, '{:+.1f}°')}"),
            ("roll/pitch", f"{angle(s.roll)} / {angle(s.pitch)}"),
            ("yaw", angle(s.yaw)),
            ("excitation", s.excitation),
            ("identifying", "yes" if s.identifying else "no"),
            ("loop lag", num(s.loop_lag_ms, "{:.1f} ms, worst of 1 s")),
        ]
        text = Text("\n".join(f"{k:<11} {v}" for k, v in rows), _style(self.stale))
        if s.link_fault:  # commands other than an abort are refused until this clears
            text.append(f"\nLINK: {s.link_fault}", "bold red")
        self.flight.update(text)

    def _sensors(self, s: messages.Status) -> None:
        self.sensors.clear()
        for name, h in s.sensors.items():
            state = str(h.get("state", "?"))
            self.sensors.add_row(
                name,
                Text(state, "green" if state == "open" else "bold red"),
                num(h.get("rate_hz"), "{:.0f}"),
                str(int(h.get("gaps") or 0)),
                str(int(h.get("crc_errors") or 0)),
                num(h.get("age_s"), "{:.2f}"),
            )


def _style(stale: bool) -> str:
    return "bold red" if stale else "green"
