"""The excitation player: arms a plan, starts it on the pilot's switch, plays it on the
controls against absolute deadlines, and ends every run with trim and then release.

Safety (DESIGN.md): the pilot's switch always wins; trim is captured before a run — the servo
outputs in MANUAL, the pilot's sticks in FBWA (an override stands in for the stick there), no
run in any other mode, and a run aborted if the mode changes; every end — finished, pilot,
operator, envelope, stale data, mode change, internal error, shutdown — commands trim and then
releases the override; the envelope is enforced onboard whatever the ground asks. The
scheduler talks to the autopilot only through `SurfaceSink`, so tests drive it with a fake sink
and the agent drives it with the MAVSDK driver unchanged.
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections import Counter, deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np

from agent.config import Envelope, Excitation
from agent.excitation import servo
from agent.excitation.plan import Plan, PlanRefused, Timeline, check
from drivers.values import Clock, FlightState, Window

log = logging.getLogger(__name__)

# Progress events per second of run: enough for a console, few enough for the radio.
PROGRESS_HZ = 1.0
# The flight modes a plan plays in: MANUAL, its overrides the surfaces; and the stabilised modes
# (ON_STICKS), its overrides the pilot's sticks, the autopilot's laws flying the surfaces
# (ArduPlane's FBWA: the roll and pitch sticks an attitude demand, the rudder's added to its
# yaw damper). A mode the sink does not report (None) is taken as MANUAL.
ON_STICKS = ("FBWA",)
PLAYS_IN = ("MANUAL", *ON_STICKS)
# Servo-output history kept for trim capture (samples); 10 s at 50 Hz telemetry.
SERVO_HISTORY = 500


class SurfaceSink(Protocol):
    """Where commands go: the autopilot's RC override (ArduPlane RC_CHANNELS_OVERRIDE)."""

    async def command(self, pwm: Mapping[int, int]) -> None:
        """Override these RC channels with these PWM values (µs)."""

    async def release(self, channels: Sequence[int]) -> None:
        """Give these channels back to the pilot."""


EventKind = Literal["armed", "disarmed", "refused", "started", "progress", "finished", "aborted"]


@dataclass(frozen=True)
class Event:
    """What the scheduler did, for the link, the console and the log."""

    kind: EventKind
    plan_id: str
    time: float
    detail: str = ""
    fraction: float | None = None


@dataclass(frozen=True)
class Playing:
    """The plan being played: how far it is, and what it commands now (for the live view)."""

    plan: Plan
    start: float
    timeline: Timeline
    on_sticks: bool = False
    """Played on the pilot's sticks (a stabilised mode, ON_STICKS): the autopilot's laws moved
    the surfaces, so they do not follow the plan's commands through their linkage."""

    def fraction(self, now: float) -> float:
        """The share of the plan played by `now` (0 to 1)."""
        return float(np.clip((now - self.start) / self.timeline.duration, 0.0, 1.0))

    def commanded(self, now: float) -> dict[str, float]:
        """Each control's commanded deflection from trim at `now` (its unit)."""
        i = int(np.clip((now - self.start) // self.timeline.dt, 0, self.timeline.count - 1))
        return {name: float(values[i]) for name, values in self.timeline.values.items()}


def envelope_violation(s: FlightState, env: Envelope, altitude_ref: float | None) -> str:
    """Which envelope limit the state is outside ("" when inside)."""
    if not all(np.isfinite([s.bank_deg, s.pitch_deg, s.airspeed, s.alpha_deg, s.altitude_m])):
        return "envelope: flight state is not finite"
    lost = 0.0 if altitude_ref is None else altitude_ref - s.altitude_m
    b, p, v, a, e = s.bank_deg, s.pitch_deg, s.airspeed, s.alpha_deg, env
    checks = [
        (abs(b) > e.max_bank_deg, f"bank {b:.1f}° beyond ±{e.max_bank_deg:g}°"),
        (abs(p) > e.max_pitch_deg, f"pitch {p:.1f}° beyond ±{e.max_pitch_deg:g}°"),
        (v < e.min_airspeed, f"airspeed {v:.1f} m/s below {e.min_airspeed:g} m/s"),
        (v > e.max_airspeed, f"airspeed {v:.1f} m/s above {e.max_airspeed:g} m/s"),
        (a > e.max_alpha_deg, f"angle of attack {a:.1f}° above {e.max_alpha_deg:g}°"),
        (
            lost > e.max_altitude_loss_m,
            f"lost {lost:.1f} m of height, limit {e.max_altitude_loss_m:g} m",
        ),
    ]
    return next((f"envelope: {text}" for failed, text in checks if failed), "")


class _Abort(Exception):
    """A run must end now; the message is the reason reported to the operator."""


class Scheduler:
    """Plays armed plans on the pilot's switch; see the module docstring for the rules."""

    def __init__(self, config: Excitation, sink: SurfaceSink, clock: Clock):
        self._config = config
        self._sink = sink
        self._clock = clock
        self._listeners: list[Callable[[Event | Window], None]] = []
        self._armed: tuple[Plan, Timeline] | None = None
        self._running: Plan | None = None
        self.playing: Playing | None = None  # the plan being played, with its timeline
        self.played: Playing | None = None  # the last plan played (kept for its window)
        self._seen_low = False
        self._switch: tuple[float, bool] | None = None
        self._state: FlightState | None = None
        self._servos: deque[tuple[float, Mapping[int, int]]] = deque(maxlen=SERVO_HISTORY)
        self._sticks: deque[tuple[float, Mapping[int, int]]] = deque(maxlen=SERVO_HISTORY)
        self._mode: str | None = None  # the flight mode the running plan started in
        self._abort_request: str | None = None
        self._start = asyncio.Event()
        self.counters: Counter[str] = Counter()

    # -- inputs -------------------------------------------------------------------------------

    def subscribe(self, listener: Callable[[Event | Window], None]) -> None:
        """Call listener with every Event and Window (it must not block)."""
        self._listeners.append(listener)

    @property
    def status(self) -> Literal["idle", "armed", "running"]:
        if self._running is not None:
            return "running"
        return "armed" if self._armed is not None else "idle"

    async def arm_checked(self, plan: Plan) -> Timeline:
        """arm(), with the plan rendered and checked on a thread first: a multisine's low-peak
        phases take 0.03 s for the thesis's four harmonics and about 3 s for the full preset's four
        controls (25 harmonics on a surface), far too long for the event loop."""
        c = self._config
        try:
            timeline = await asyncio.to_thread(check, plan, c.rate_hz, c.surfaces, c.envelope)
        except PlanRefused as exc:
            self.counters["refused"] += 1
            self._emit(Event("refused", plan.id, self._clock.now(), str(exc)))
            raise
        return self.arm(plan, timeline)

    def arm(self, plan: Plan, timeline: Timeline | None = None) -> Timeline:
        """Arm a plan (`timeline`: already checked); raise PlanRefused (and emit "refused")
        if it may not fly."""
        now = self._clock.now()
        try:
            if self._running is not None:
                raise PlanRefused(f"plan {plan.id!r} refused: plan {self._running.id!r} is running")
            if timeline is None:
                timeline = check(
                    plan, self._config.rate_hz, self._config.surfaces, self._config.envelope
                )
        except PlanRefused as exc:
            self.counters["refused"] += 1
            self._emit(Event("refused", plan.id, now, str(exc)))
            raise
        self._armed = (plan, timeline)
        # A start needs the pilot to flip the switch low → high after arming, so arming from
        # the ground never starts a run by itself.
        self._seen_low = self._switch is not None and not self._switch[1]
        self._emit(Event("armed", plan.id, now, f"{timeline.duration:.1f} s"))
        return timeline

    def disarm(self) -> None:
        """Forget the armed plan (a running one is not affected: use abort)."""
        if self._armed is not None:
            plan = self._armed[0]
            self._armed = None
            self._emit(Event("disarmed", plan.id, self._clock.now()))

    def abort(self, reason: str = "operator abort") -> None:
        """End a running plan (trim, then release) at the next command; disarm an armed one."""
        if self._running is not None:
            self._abort_request = reason
        else:
            self.disarm()

    def request_start(self) -> str:
        """The operator's start (thesis B.2 3.1): runs the armed plan if the pilot's switch is
        already high; "" when started, else why not (the switch still gates every run)."""
        if self._armed is None:
            return "no plan is armed"
        if self._running is not None:
            return "a plan is running"
        if self._switch is None or not self._switch[1]:
            return "the pilot's switch is low"
        self._seen_low = True
        self._start.set()
        return ""

    def update_switch(self, pwm: int, time: float) -> None:
        """The pilot's excitation switch (RC_CHANNELS of the switch channel)."""
        high = pwm >= self._config.switch_high_us
        self._switch = (time, high)
        if not high:
            self._seen_low = True
        elif self._armed is not None and self._seen_low and self._running is None:
            # One flip, one attempt: a start refused (the envelope, say) waits for the pilot to
            # cycle the switch, never retries on its own as the flight state drifts (it did,
            # 20 times a second, and started a plan seconds after the flip once in envelope).
            self._seen_low = False
            self._start.set()

    def update_state(self, state: FlightState) -> None:
        """The latest flight state (latest value wins)."""
        self._state = state

    @property
    def state(self) -> FlightState | None:
        """The latest flight state (None: none yet)."""
        return self._state

    def update_servos(self, time: float, pwm: Mapping[int, int]) -> None:
        """Servo outputs (SERVO_OUTPUT_RAW) by channel, for trim capture."""
        self._servos.append((time, dict(pwm)))

    def update_sticks(self, time: float, pwm: Mapping[int, int]) -> None:
        """The pilot's RC inputs (RC_CHANNELS) by channel, for trim capture in a stabilised
        mode, where an override stands in for the stick, not the servo."""
        self._sticks.append((time, dict(pwm)))

    def flight_mode(self) -> str | None:
        """The autopilot's flight mode as the sink reports it (None: unknown)."""
        return getattr(self._sink, "flight_mode", None)

    # -- the player ---------------------------------------------------------------------------

    async def run(self) -> None:
        """Serve forever: wait for an armed plan and a switch flip, then play it."""
        while True:
            await self._start.wait()
            self._start.clear()
            if self._armed is None:
                continue
            plan, timeline = self._armed
            try:
                trim = self._preflight(plan, timeline)
            except _Abort as exc:
                self.counters["refused"] += 1
                log.warning("plan %s not started: %s", plan.id, exc)
                self._emit(Event("refused", plan.id, self._clock.now(), str(exc)))
                continue
            self._armed = None
            await self._play(plan, timeline, trim)

    def _preflight(self, plan: Plan, timeline: Timeline) -> dict[str, float]:
        """Checks before the first command; the captured trim (µs) per control."""
        now = self._clock.now()
        self._mode = None
        reason = self._violation(now, altitude_ref=None)
        if reason:
            raise _Abort(f"not started: {reason}")
        mode = self.flight_mode()
        if mode is not None and mode not in PLAYS_IN:
            raise _Abort(
                f"not started: the autopilot is in {mode}; plans play in MANUAL (on the "
                f"surfaces) or {', '.join(m for m in PLAYS_IN if m != 'MANUAL')} (on the "
                "sticks, the autopilot's laws engaged)"
            )
        sticks = mode in ON_STICKS
        trim = self._capture_trim(now, plan.controls(), sticks)
        self._mode = mode
        for name in plan.controls():
            surface = self._config.surfaces[name]
            clamped = servo.pwm_clamped(timeline.values[name], trim[name], surface)
            if clamped:
                self.counters["clamped_samples"] += clamped
                log.warning(
                    "plan %s: %d %s samples clamped to %d–%d µs around trim %.0f µs",
                    plan.id,
                    clamped,
                    name,
                    surface.min_us,
                    surface.max_us,
                    trim[name],
                )
        return trim

    def _capture_trim(
        self, now: float, controls: Sequence[str], sticks: bool = False
    ) -> dict[str, float]:
        """Each control's trim (µs): the median of its servo output (MANUAL: an override
        stands in for the surface) or, `sticks`, of the pilot's RC input (a stabilised mode:
        an override stands in for the stick, and a servo's trim there would be an attitude
        demand) over the trim window."""
        history = self._sticks if sticks else self._servos
        recent = [pwm for t, pwm in history if now - t <= self._config.trim_window_s]
        what = "RC input" if sticks else "servo output"
        trim = {}
        for name in controls:
            channel = self._config.surfaces[name].channel
            values = [pwm[channel] for pwm in recent if channel in pwm]
            if not values:
                raise _Abort(
                    f"not started: no {what} on channel {channel} ({name}) in the last "
                    f"{self._config.trim_window_s:g} s to capture trim"
                )
            trim[name] = float(np.median(values))
        return trim

    async def _play(self, plan: Plan, timeline: Timeline, trim: dict[str, float]) -> None:
        surfaces = self._config.surfaces
        channels = [surfaces[n].channel for n in plan.controls()]
        pwm = servo.surface_pwm(timeline.values, trim, surfaces)
        trim_pwm = {surfaces[n].channel: round(trim[n]) for n in plan.controls()}
        self._running, self._abort_request = plan, None
        start = self._clock.now()
        self.playing = self.played = Playing(plan, start, timeline, self._mode in ON_STICKS)
        altitude_ref = self._state.altitude_m if self._state else None
        self.counters["runs"] += 1
        detail = ", ".join(f"{n} {trim[n]:.0f} µs" for n in plan.controls())
        if self._mode in ON_STICKS:
            detail += f" (the sticks': {self._mode})"
        self._emit(Event("started", plan.id, start, f"trim {detail}"))
        outcome, reason = "finished", ""
        cancelled: asyncio.CancelledError | None = None
        try:
            await self._ticks(plan, timeline, pwm, start, altitude_ref)
        except _Abort as exc:
            outcome, reason = "aborted", str(exc)
        except asyncio.CancelledError as exc:
            outcome, reason, cancelled = "aborted", "agent shutting down", exc
        except Exception as exc:  # any fault while playing must still end in trim + release
            log.exception("plan %s: internal error", plan.id)
            outcome, reason = "aborted", f"internal error: {exc!r}"
        try:
            await self._end_shielded(trim_pwm, channels)
        finally:
            self._finish(plan, start, outcome, reason)
        if cancelled is not None:
            raise cancelled

    async def _end_shielded(self, trim_pwm: Mapping[int, int], channels: Sequence[int]) -> None:
        """_end, carried through to release even if this task is cancelled meanwhile."""
        ending = asyncio.create_task(self._end(trim_pwm, channels), name="excitation-end")
        try:
            await asyncio.shield(ending)
        except asyncio.CancelledError:
            await ending  # trim and release complete before the cancellation goes on
            raise

    async def _ticks(self, plan, timeline: Timeline, pwm, start: float, altitude_ref) -> None:
        dt, count = timeline.dt, timeline.count
        progress_every = max(1, round(1 / (PROGRESS_HZ * dt)))
        i = 0
        while True:
            now = self._clock.now()
            due = math.floor((now - start) / dt + 1e-6)
            if due > i:  # woke late: skip to the sample that is due now, never catch up
                self.counters["late_samples"] += due - i
                i = due
            if i >= count:
                return
            reason = self._abort_request or self._violation(now, altitude_ref)
            if reason:
                raise _Abort(reason)
            await self._sink.command({ch: int(p[i]) for ch, p in pwm.items()})
            self.counters["commands"] += 1
            if i % progress_every == 0 and i:
                self._emit(Event("progress", plan.id, now, fraction=i / count))
            i += 1
            await self._clock.sleep_until(start + i * dt)

    def _violation(self, now: float, altitude_ref: float | None) -> str:
        """Why a run may not continue now ("" when it may)."""
        cfg = self._config
        if self._switch is None or now - self._switch[0] > cfg.stale_s:
            age = "never received" if self._switch is None else f"{now - self._switch[0]:.2f} s old"
            return f"stale RC switch data ({age})"
        if not self._switch[1]:
            return "pilot switch low"
        if self._mode is not None and self.flight_mode() != self._mode:
            # An override is a surface in MANUAL and a stick in FBWA: the plan's commands
            # mean another thing in the new mode.
            return f"flight mode changed from {self._mode} to {self.flight_mode()}"
        s = self._state
        if s is None or now - s.time > cfg.stale_s:
            age = "never received" if s is None else f"{now - s.time:.2f} s old"
            return f"stale flight state ({age})"
        return envelope_violation(s, self._config.envelope, altitude_ref)

    async def _end(self, trim_pwm: Mapping[int, int], channels: Sequence[int]) -> None:
        """Trim, then release; each step tried even if the other fails."""
        try:
            await self._sink.command(trim_pwm)
        except Exception:  # the release below must still be tried
            self.counters["sink_errors"] += 1
            log.exception("commanding trim failed")
        try:
            await self._sink.release(channels)
        except Exception:  # counted and logged; the autopilot's RC_OVERRIDE_TIME is the backstop
            self.counters["sink_errors"] += 1
            log.exception("releasing the override failed")

    def _finish(self, plan: Plan, start: float, outcome: str, reason: str) -> None:
        end = self._clock.now()
        self._running, self.playing = None, None
        self.counters[outcome] += 1
        if outcome == "aborted":
            log.warning("plan %s aborted: %s", plan.id, reason)
        self._emit(Event(outcome, plan.id, end, reason))
        closed = self.played is not None and self.played.plan is plan and self.played.on_sticks
        self._emit(Window(plan.id, plan.axes, start, end, outcome, reason, closed_loop=closed))

    def _emit(self, item: Event | Window) -> None:
        for listener in self._listeners:
            try:
                listener(item)
            except Exception:  # one faulty listener must not stop the run or the others
                self.counters["listener_errors"] += 1
                log.exception("excitation listener failed on %s", item)
