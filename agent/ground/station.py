"""The ground station without the screen: the link session with the aircraft, what it has
heard (status, events, results, refusals), the commands in flight and their answers, and the
ground log. The Textual app (`agent.ground.app`) only draws this and calls its commands, so
nothing the operator relies on depends on the screen: each thing heard or done is handed, as
it happens, to the station's subscribers as a typed event (`agent.ground.events`).

The ground log (`NNNN_ground_DATE.jsonl` in `log_dir`) has one JSON object per line: every
message received (`"dir": "rx"`, results in full), every command sent (`"tx"`, with its
sequence number) and every answer (`"ack"`), stamped with UTC and the monotonic time. At start
the results of earlier ground logs are read back, so a nominal model identified in an earlier
session can still be shown beside a new candidate.
"""

from __future__ import annotations

import asyncio
import datetime as dt
import json
import logging
from collections import OrderedDict, deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from agent.clock import Clock
from agent.ground import events
from agent.ground.config import GroundConfig
from agent.ground.events import Command, Line
from agent.link import messages
from agent.link.codec import GROUND
from agent.link.endpoint import build_endpoint
from agent.link.session import LinkSession
from agent.logs import LogWriter, log_name
from drivers.xbee.driver import XBeeRadio

log = logging.getLogger(__name__)

EVENTS_KEPT = 500
# The live view's strip charts keep this many seconds.
STRIP_S = 30.0


@dataclass
class Heard:
    status: messages.Status | None = None
    status_at: float | None = None
    events: deque[Line] = field(default_factory=lambda: deque(maxlen=EVENTS_KEPT))
    results: OrderedDict[str, messages.Result] = field(default_factory=OrderedDict)
    failures: list[messages.Failure] = field(default_factory=list)
    frfs: dict[tuple[str, str, str], messages.FrfReport] = field(default_factory=dict)
    """Frequency responses asked for, by (model id, input, output)."""
    live: messages.Live | None = None
    """The latest live view (progress, stage) of the run."""
    live_at: float | None = None
    strips: dict[str, deque[tuple[float, float | None]]] = field(default_factory=dict)
    """The run's strip charts: per channel, (time, value in display units), STRIP_S long."""
    excitation: messages.ExcitationEvent | None = None
    sizing: messages.Sizing | None = None
    """The aircraft's latest sizing of a plan (agent/sizing.py)."""
    gains: messages.Gains | None = None
    """The aircraft's latest gain proposal (agent/runtime/gains.py)."""
    gains_report: messages.GainsReport | None = None
    """What became of the autopilot's gains last (applied, reverted, failed)."""


class GroundStation:
    """Owns the radio and the session; `run()` serves until cancelled."""

    def __init__(self, config: GroundConfig, clock: Clock, base: Path = Path(".")):
        self.config, self.clock, self.base = config, clock, Path(base)
        self.heard = Heard()
        self.commands: dict[int, Command] = {}
        # The last settings the aircraft acknowledged (what its status reports is newer).
        self.settings_acknowledged: messages.IdentSettings | None = None
        self._subscribers: list[Callable[[events.Event], None]] = []
        self.session: LinkSession | None = None
        self.rssi_dbm: int | None = None
        self.rssi_errors = 0  # RSSI reads that failed (logged; the link goes on)
        self.radio: XBeeRadio | None = None
        self.writer = LogWriter(self.base / config.log_dir)
        self._reload_results()
        self._log: int | None = None  # the ground log, created when the radio opens

    # -- link -------------------------------------------------------------------------------

    async def open(self) -> None:
        """Open the radio and the session (raises OSError/ValueError/RadioError with the
        reason)."""
        cfg = self.config.link
        radio, session = build_endpoint(cfg, GROUND, self.base, self.clock, self.on_message)
        # Held before it opens: close() then ends an open cut short (the console quit while
        # digi-xbee still reads the module's parameters) and never leaves its reader on the port.
        self.radio = radio
        await radio.open()
        self.session = session
        self._log = self.writer.open(log_name(self.writer.next_number(), "ground", "jsonl"))
        self.note("info", f"radio open ({Path(cfg.port).name}); aircraft {cfg.peer}")

    async def run(self) -> None:
        if self.session is None:
            await self.open()
        assert self.session is not None
        async with asyncio.TaskGroup() as group:
            group.create_task(self.session.run(), name="ground-session")
            group.create_task(self.radio.watch(), name="ground-radio")
            group.create_task(self._rssi_loop(), name="ground-rssi")

    async def _rssi_loop(self) -> None:
        """The ground module's RSSI of the last frame heard (DB), every rssi_s."""
        while True:
            await asyncio.sleep(self.config.rssi_s)
            if self.radio is None or not self.link_up:
                continue
            try:
                self.rssi_dbm = await self.radio.rssi()
            except Exception as exc:  # a display value: never worth the link itself
                self.rssi_dbm = None
                self.rssi_errors += 1
                log.warning("RSSI not read: %r", exc)

    async def close(self) -> None:
        if self.radio is not None:
            await self.radio.close()
        self.writer.close()

    @property
    def link_up(self) -> bool:
        return self.session is not None and self.session.link_up

    def link_quality(self) -> dict:
        """Last heard (s ago), frames sent and failed, loss rate, retransmissions."""
        s = self.session
        if s is None:
            return {"up": False, "last_heard_s": None, "loss": None, "rssi_dbm": None}
        c = s.counters
        sent, failed = c["frames_sent"], c["frames_failed"]
        heard = s.last_heard
        return {
            "up": s.link_up,
            "last_heard_s": None if heard is None else self.clock.now() - heard,
            "loss": failed / (sent + failed) if sent + failed else None,
            "retransmissions": c["retransmissions"],
            "rssi_dbm": self.rssi_dbm,
            "rssi_errors": self.rssi_errors,
            "rejected": c["rejected_messages"],
        }

    # -- what the aircraft says -------------------------------------------------------------

    def on_message(self, message: messages.Message, seq: int | None) -> None:
        now = self.clock.now()
        self._write("rx", messages.to_dict(message), seq=seq)
        h = self.heard
        if isinstance(message, messages.Status):
            h.status, h.status_at = message, now
            self._tell(events.StatusHeard(message, now))
            return
        if isinstance(message, messages.Live):
            self._live(message, now)
            self._tell(events.LiveFrame(message))
            return
        if isinstance(message, messages.Ack):
            self._answered(message)
        elif isinstance(message, messages.ExcitationEvent):
            h.excitation = message
            level = "warning" if message.event in ("aborted", "refused") else "info"
            detail = f": {message.detail}" if message.detail else ""
            self.note(level, f"excitation {message.plan_id} {message.event}{detail}")
        elif isinstance(message, messages.Result):
            self._run_over()
            self._keep(message)
            verdict = "update suggested" if message.suggest_update else "no update suggested"
            self.note(
                "info",
                f"result {message.model_id} ({message.axes}): TIC {message.tic_avg:.3f}, {verdict}",
            )
            self._tell(events.ResultHeard(message))
        elif isinstance(message, messages.FrfReport):
            h.frfs[(message.model_id, message.input, message.output)] = message
            self.note(
                "info",
                f"frequency response {message.model_id} {message.input} → {message.output}: "
                f"{len(message.freq_hz)} frequencies",
            )
            self._tell(events.FrfHeard(message))
        elif isinstance(message, messages.Failure):
            self._run_over()
            h.failures.append(message)
            self.note("error", f"identification {message.model_id} failed: {message.reason}")
        elif isinstance(message, messages.Sizing):
            h.sizing = message
            amplitudes = ", ".join(
                f"{c.control} {c.amplitude:.3g}{'°' if c.unit == 'deg' else c.unit}"
                for c in message.controls
            )
            level = "error" if message.refusals else "info"
            refused = f"; REFUSED: {'; '.join(message.refusals)}" if message.refusals else ""
            self.note(level, f"sizing {message.plan.id} by {message.source}: {amplitudes}{refused}")
            self._tell(events.SizingHeard(message))
        elif isinstance(message, messages.Gains):
            h.gains = message
            steps = ", ".join(
                f"{axis} {share:.0%} of the way" for axis, share in message.share.items()
            )
            refused = f"; not proposed: {'; '.join(message.refused)}" if message.refused else ""
            self.note("info", f"gains {message.proposal} from {message.model_id}: {steps}{refused}")
            self._tell(events.GainsHeard(gains=message))
        elif isinstance(message, messages.GainsReport):
            h.gains_report = message
            level = (
                "error"
                if message.action == "failed"
                else "warning"
                if message.action == "reverted"
                else "info"
            )
            self.note(level, f"gains {message.action} {message.proposal or ''}: {message.reason}")
            self._tell(events.GainsHeard(report=message))
        elif isinstance(message, messages.Notice):
            self.note("warning", message.text)

    def _live(self, live: messages.Live, now: float) -> None:
        h = self.heard
        previous = h.live
        if live.plan_id is not None and (previous is None or previous.plan_id != live.plan_id):
            h.strips.clear()  # a new run: new charts
        h.live, h.live_at = live, now
        for name, values in live.tenths.items():
            strip = h.strips.setdefault(name, deque())
            for k, value in enumerate(values):
                strip.append((live.time + k * live.dt, None if value is None else value / 10))
            while strip and strip[-1][0] - strip[0][0] > STRIP_S:
                strip.popleft()

    def _run_over(self) -> None:
        """A result or failure ends the live view (its charts stay for a look back)."""
        self.heard.live = None
        self._tell(events.LiveFrame(None))

    def _answered(self, ack: messages.Ack) -> None:
        command = self.commands.get(ack.ref)
        if command is None:
            self.note("warning", f"answer to an unknown command #{ack.ref}")
            return
        command.ack = ack
        if ack.ok and isinstance(command.message, messages.IdentSettings):
            self.settings_acknowledged = command.message
        if ack.ok:
            self.note("info", f"{command.label}: acknowledged")
        else:
            self.note("error", f"{command.label}: REFUSED — {ack.reason}")
        self._tell(events.AckHeard(command))

    def _keep(self, result: messages.Result) -> None:
        results = self.heard.results
        results[result.model_id] = result
        results.move_to_end(result.model_id)
        while len(results) > self.config.results_kept:
            results.popitem(last=False)

    # -- commands ---------------------------------------------------------------------------

    def send(self, message: messages.Message, label: str) -> Command:
        """Send a command reliably; its answer arrives in `command.ack`."""
        if self.session is None:
            raise RuntimeError("the radio is not open")
        seq = self.session.send_reliable(message)
        command = Command(seq=seq, label=label, sent_at=self.clock.now(), message=message)
        self.commands[seq] = command
        self._write("tx", messages.to_dict(message), seq=seq)
        self.note("info", f"{label}: sent")
        return command

    def arm(self, plan) -> Command:
        return self.send(messages.Arm(plan=plan), f"arm {plan.id}")

    def size(self, plan) -> Command:
        """Ask the aircraft how it would fly `plan`; its answer is a Sizing (`heard.sizing`)."""
        return self.send(messages.SizeRequest(plan=plan), f"size {plan.id}")

    def abort(self) -> Command:
        return self.send(messages.Abort(reason="operator abort (ground)"), "abort")

    def settings(self, settings: messages.IdentSettings) -> Command:
        axes = settings.axes or "on each plan's axes"
        return self.send(settings, f"settings {axes}")

    def decide(self, model_id: str, accept: bool) -> Command:
        verb = "accept" if accept else "reject"
        return self.send(messages.Decision(model_id=model_id, accept=accept), f"{verb} {model_id}")

    def revert(self) -> Command:
        return self.send(messages.Revert(), "revert to the previous nominal")

    def propose_gains(self, model_id: str | None = None) -> Command:
        """Ask for autopilot gains designed from a model (the nominal by default); the answer
        is a Gains (`heard.gains`)."""
        return self.send(messages.GainsRequest(model_id=model_id), "propose gains")

    def apply_gains(self, proposal: str) -> Command:
        return self.send(messages.GainsApply(proposal=proposal), f"apply gains {proposal}")

    def revert_gains(self) -> Command:
        return self.send(messages.GainsRevert(), "revert the gains")

    def frequency_response(self, model_id: str, input_: str, output: str) -> Command:
        request = messages.FrfRequest(model_id=model_id, input=input_, output=output)
        return self.send(request, f"frequency response {model_id} {input_} → {output}")

    # -- views ------------------------------------------------------------------------------

    def nominal(self, axes: str) -> messages.Result | None:
        """The aircraft's nominal model of these axes, if its result is known here."""
        status = self.heard.status
        model_id = status.nominal.get(axes) if status is not None else None
        return self.heard.results.get(model_id) if model_id else None

    def status_age(self) -> float | None:
        at = self.heard.status_at
        return None if at is None else self.clock.now() - at

    # -- log --------------------------------------------------------------------------------

    def note(self, level: str, text: str) -> None:
        line = Line(self.clock.now(), level, text)
        self.heard.events.append(line)
        self._write("note", {"level": level, "text": text})
        self._tell(events.Noted(line))

    def subscribe(self, subscriber: Callable[[events.Event], None]) -> None:
        """Hand `subscriber` every event from now on (in order, as it happens)."""
        self._subscribers.append(subscriber)

    def unsubscribe(self, subscriber: Callable[[events.Event], None]) -> None:
        if subscriber in self._subscribers:
            self._subscribers.remove(subscriber)

    def _tell(self, event: events.Event) -> None:
        for subscriber in self._subscribers:
            subscriber(event)

    def _write(self, direction: str, data: dict, seq: int | None = None) -> None:
        if self._log is None:
            return
        record = {
            "utc": dt.datetime.now(dt.UTC).isoformat(),
            "t": self.clock.now(),
            "dir": direction,
            "seq": seq,
            "message": data,
        }
        self.writer.write(self._log, (json.dumps(record) + "\n").encode())

    def _reload_results(self) -> None:
        directory = self.writer.directory
        for path in sorted(directory.glob("*_ground_*.jsonl")):
            try:
                lines = path.read_text().splitlines()
            except OSError as exc:
                log.warning("%s: cannot read (%s)", path, exc)
                continue
            for line in lines:
                try:
                    record = json.loads(line)
                    if record.get("dir") == "rx" and record["message"].get("kind") == "result":
                        self._keep(messages.from_dict(record["message"]))
                except (ValueError, KeyError, TypeError, AttributeError):
                    continue  # a torn last line, or a record of another version: skipped
