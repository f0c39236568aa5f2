"""Status (1): the vehicle as last heard — flight state, the sensors' health, the recorder."""

from __future__ import annotations

from rich.text import Text
from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical
from textual.widgets import DataTable, Static

from agent.ground.station import GroundStation
from agent.ground.widgets import num

DEG = 57.29577951308232


class StatusTab(Horizontal):
    def __init__(self, station: GroundStation, **kwargs):
        super().__init__(**kwargs)
        self.station = station

    def compose(self) -> ComposeResult:
        yield Static(id="flight")
        with Vertical():
            yield DataTable(id="sensors", cursor_type="none", zebra_stripes=True)
            yield Static(id="health")

    def on_mount(self) -> None:
        self.query_one("#sensors", DataTable).add_columns(
            "sensor", "state", "Hz", "gaps", "CRC", "age s"
        )

    def show(self) -> None:
        s, age = self.station.heard.status, self.station.status_age()
        flight = self.query_one("#flight", Static)
        if s is None:
            flight.update("no status heard yet")
            return
        stale = age is not None and age > self.station.config.stale_s
        flight.set_class(stale, "stale")

        def angle(value: float | None) -> str:
            return num(None if value is None else value * DEG, "{:+.1f}°")

        head = Text(
            f"STALE: {age:.0f} s old\n" if stale else f"status {age:.1f} s old\n",
            "bold red" if stale else "green",
        )
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
        head.append("\n".join(f"{k:<11} {v}" for k, v in rows))
        if s.link_fault:  # commands other than an abort are refused until this clears
            head.append(f"\nLINK: {s.link_fault}", "bold red")
        flight.update(head)
        table = self.query_one("#sensors", DataTable)
        table.clear()
        for name, h in s.sensors.items():
            state = str(h.get("state", "?"))
            table.add_row(
                name,
                Text(state, "green" if state == "open" else "bold red"),
                num(h.get("rate_hz"), "{:.0f}"),
                str(int(h.get("gaps") or 0)),
                str(int(h.get("crc_errors") or 0)),
                num(h.get("age_s"), "{:.2f}"),
            )
        r = s.recorder
        # Each number is what its label says: frames recorded (of them, assembled after a
        # late wake-up), samples dropped as stamped before one already held, log lines lost.
        self.query_one("#health", Static).update(
            f"frames     {int(r.get('frames', 0))} ({int(r.get('catch_up_frames', 0))} late)\n"
            f"dropped    {int(r.get('late_samples', 0))} late samples\n"
            f"log lost   {int(r.get('log_lost_lines', 0))} lines"
        )
