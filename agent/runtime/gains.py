"""ArduPlane's FBWA gains from the nominal model, through the operator (docs/tuning.md).

The ground asks for a proposal (GainsRequest): the roll and pitch gains designed from the
model (agent.tune.design, on a thread: a design takes about a second) with the surfaces'
linkage and lag the last finished run measured, beside the gains the autopilot holds now
(read over MAVLink), each set's predicted loops, and — where a gain would change by more than
[tuning] max_step times — a step toward the design that keeps the margins
(agent.tune.toward). The operator applies it by its id (GainsApply): the agent sets the gains
with MAVSDK's param plugin, reads them back, logs both, and keeps the set it replaced. It
reverts to that set on command (GainsRevert), or by itself when the attitude tracking in
stabilised flight is worse after the apply than before it (`Tracking`).

Never while a plan is armed or playing: the gains shape how the aircraft answers the
excitation, and an excitation overrides the surfaces the tracking is judged on. The commands
are carried out one at a time (agent/runtime/commands.py), so no arm interleaves with an
apply; the tracking's own revert waits for the run to end.
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections import Counter, deque
from collections.abc import Callable, Mapping

import numpy as np

from agent import tune
from agent.config import Config
from agent.link import messages
from agent.logs import Logbook
from agent.models import Candidate
from agent.runtime.downlink import Downlink
from agent.runtime.identification import Identifier
from drivers.autopilot.driver import AutopilotError

log = logging.getLogger(__name__)

# ArduPlane's custom mode numbers whose roll and pitch are its attitude loops (the tracking is
# judged in them): FBWA and STABILIZE-like modes whose demand NAV_CONTROLLER_OUTPUT carries.
STABILISED = {5: "FBWA"}
# How often the tracking looks at the newest attitude and demand (s).
TRACK_PERIOD_S = 0.1
# A window is judged when it holds this share of its samples (the rest: gaps, MANUAL).
TRACK_FULL = 0.8


# The tracked quantities: the roll and pitch attitude errors (deg) and the roll and pitch
# rates (deg/s), whose rms grows with a limit cycle the attitude hardly shows (a fast
# oscillation of the rate loop moves the bank by little).
TRACKED = ("roll error", "pitch error", "roll rate", "pitch rate")


class Tracking:
    """The attitude tracking in stabilised flight, sampled from the autopilot's newest
    ATTITUDE and NAV_CONTROLLER_OUTPUT (the demanded roll and pitch) while no plan plays: the
    rms of each of TRACKED over a window of `window_s`."""

    def __init__(self, window_s: float):
        self.window_s = window_s
        size = math.ceil(window_s / TRACK_PERIOD_S)
        self.samples: deque[tuple[float, float, float, float]] = deque(maxlen=size)
        self._last: tuple[int, int] | None = None

    def sample(self, telemetry: Mapping[str, dict], quiet: bool) -> None:
        """One look at the newest messages: kept when both are new since the last look, the
        mode is stabilised and `quiet` (no plan armed or playing)."""
        attitude = telemetry.get("ATTITUDE")
        demand = telemetry.get("NAV_CONTROLLER_OUTPUT")
        heartbeat = telemetry.get("HEARTBEAT") or {}
        if attitude is None or demand is None:
            return
        seen = (id(attitude), id(demand))
        if seen == self._last:
            return
        self._last = seen
        if not quiet or heartbeat.get("custom_mode") not in STABILISED:
            return
        try:
            row = (
                math.degrees(float(attitude["roll"])) - float(demand["nav_roll"]),
                math.degrees(float(attitude["pitch"])) - float(demand["nav_pitch"]),
                math.degrees(float(attitude["rollspeed"])),
                math.degrees(float(attitude["pitchspeed"])),
            )
        except (KeyError, TypeError, ValueError):
            return
        if all(math.isfinite(v) for v in row):
            self.samples.append(row)

    def rms(self) -> tuple[float, ...] | None:
        """Each of TRACKED's rms over the window; None until it is full enough."""
        if len(self.samples) < TRACK_FULL * (self.samples.maxlen or 1):
            return None
        return tuple(float(v) for v in np.sqrt(np.mean(np.square(self.samples), axis=0)))

    def clear(self) -> None:
        self.samples.clear()


class GainTuner:
    def __init__(
        self,
        *,
        config: Config,
        identification: Identifier,
        autopilot,
        status: Callable[[], str],
        downlink: Downlink,
        logbook: Logbook,
        counters: Counter[str],
    ):
        self.config, self.identification, self.autopilot = config, identification, autopilot
        self._status, self.downlink, self.logbook = status, downlink, logbook
        self.counters = counters
        self.linkage: dict[str, dict[str, float]] = {}
        """Surface → {"gain", "lag_s"} of the last finished run (agent.excitation.follow)."""
        self.proposal: tuple[str, dict[str, float]] | None = None  # (id, gains to set)
        self.replaced: dict[str, float] | None = None  # what the last apply replaced
        self.applied: str | None = None  # the proposal applied (judged by the tracking)
        self.tracking = Tracking(config.tuning.track_window_s)
        self.before: tuple[float, ...] | None = None  # the tracking before the apply
        self._checks_left = 0  # windows still to judge after the apply
        self._count = 0

    # -- the ground's commands ------------------------------------------------------------

    async def propose(self, message: messages.GainsRequest) -> str:
        """Design from the model, read the autopilot's gains, send the proposal down."""
        candidate = await self._model(message.model_id)
        model = _as_tune_model(candidate)
        cfg = self.config
        options = tune.Options(measured=dict(self.linkage))

        def work() -> tune.Design:
            return tune.design(model, cfg.identification.channels, cfg.excitation.surfaces, options)

        try:
            designed = await asyncio.to_thread(work)
        except tune.TuneError as exc:
            return f"no gains from {candidate.model_id}: {exc}"[:200]
        names = list(designed.params())
        try:
            current = await self.autopilot.parameters(names)
        except AutopilotError as exc:
            return f"the autopilot's gains could not be read: {exc}"[:200]
        proposal, refused = await asyncio.to_thread(self._steps, designed, current)
        self._count += 1
        ident = f"{candidate.model_id}-g{self._count}"
        self.proposal = (ident, {n: v for n, v in proposal[1].items()})
        self.downlink.send(
            messages.Gains(
                proposal=ident,
                model_id=candidate.model_id,
                rows=proposal[0],
                loops=proposal[2],
                share=proposal[3],
                refused=[r[:200] for r in (*designed.refused, *refused)],
                notes=[n[:200] for n in (*designed.notes, *_yaw_notes(designed.yaw))],
            )
        )
        return ""

    async def apply(self, message: messages.GainsApply) -> str:
        """Set the proposal's gains (read back), keeping the set they replace."""
        if self.proposal is None or self.proposal[0] != message.proposal:
            latest = self.proposal[0] if self.proposal else "none"
            return f"no proposal {message.proposal} (the latest is {latest}): ask again"
        busy = self._status()
        if busy != "idle":
            return f"a plan is {busy}: gains are never changed while one is armed or playing"
        ident, values = self.proposal
        if not values:
            return f"{ident} sets nothing (every axis refused)"
        try:
            replaced = await self.autopilot.parameters(list(values))
        except AutopilotError as exc:
            return f"the autopilot's gains could not be read: {exc}"[:200]
        before = self.tracking.rms()
        try:
            read = await self.autopilot.set_parameters(values)
        except AutopilotError as exc:
            self.counters["gains_failed"] += 1
            held = await self._restore(replaced)
            self._report("failed", ident, held, f"{exc}; the set before restored"[:200])
            return str(exc)[:200]
        self.replaced, self.applied = replaced, ident
        self.before = before
        self._checks_left = self.config.tuning.track_checks
        self.tracking.clear()
        self.counters["gains_applied"] += 1
        self._report("applied", ident, read, f"replacing {_listed(replaced)}"[:200])
        return ""

    async def revert(self, reason: str = "operator's command") -> str:
        """Set back the gains the last apply replaced."""
        if self.replaced is None:
            return "no applied gains to revert"
        busy = self._status()
        if busy != "idle":
            return f"a plan is {busy}: gains are never changed while one is armed or playing"
        try:
            read = await self.autopilot.set_parameters(self.replaced)
        except AutopilotError as exc:
            self.counters["gains_revert_failed"] += 1
            self._report("failed", self.applied, {}, f"revert: {exc}"[:200])
            return str(exc)[:200]
        self.counters["gains_reverted"] += 1
        self._report("reverted", self.applied, read, reason)
        self.replaced = self.applied = self.before = None
        return ""

    # -- the tracking self-check ----------------------------------------------------------

    async def run(self) -> None:
        """Sample the tracking; after an apply, judge each full window, [tuning] track_checks
        of them (a limit cycle can take a while to build)."""
        while True:
            await asyncio.sleep(TRACK_PERIOD_S)
            quiet = self._status() == "idle"
            self.tracking.sample(getattr(self.autopilot, "telemetry", {}), quiet)
            if self.applied is None:
                continue
            after = self.tracking.rms()
            if after is None:
                continue
            self.tracking.clear()
            self._checks_left -= 1
            verdict = self._degraded(after)
            if verdict:
                log.warning("%s: %s", self.applied, verdict)
                self.downlink.send(messages.Notice(text=f"{self.applied}: {verdict}"[:200]))
                await self.revert(verdict)
                self.applied = None
            elif self._checks_left <= 0:
                self.logbook.event("agent.gains", f"{self.applied}: tracking kept ({_rms(after)})")
                self.applied = None

    def _degraded(self, after: tuple[float, ...]) -> str:
        """Why the tracking after the apply is a degradation ("" when it is not)."""
        cfg = self.config.tuning
        before = self.before
        for k, what in enumerate(TRACKED):
            floor = cfg.track_floor_deg if k < 2 else cfg.track_rate_floor_dps
            unit = "°" if k < 2 else "°/s"
            base = max(floor, before[k] if before is not None else 0.0)
            if after[k] > cfg.track_degrade * base:
                was = f"{before[k]:.2f}{unit}" if before is not None else "not measured"
                return (
                    f"{what} rms {after[k]:.2f}{unit} after the apply, {was} before (more "
                    f"than ×{cfg.track_degrade:g} of {base:.2f}{unit}): reverted"
                )
        return ""

    # -- helpers ------------------------------------------------------------------------

    async def _model(self, model_id: str | None) -> Candidate:
        return await self.identification.tuning_model(model_id)

    def _steps(self, designed: tune.Design, current: Mapping[str, float]):
        """Each axis's step toward the design (agent.tune.toward) with both sets' loops."""
        rows, values, loops, share, refused = [], {}, [], {}, []
        cfg = self.config.tuning
        scaling = designed.scaling_speed
        for t in designed.tunes:
            plant, actuator = designed.loops[t.axis]
            kw = {"eas": designed.eas, "scaling_speed": scaling}
            now = tune.assess(t.axis, plant, actuator, current, **kw)
            loops.append(_loop(t.axis, "current", now))
            step = tune.toward(
                t.axis, plant, actuator, current, t.params, max_step=cfg.max_step, **kw
            )
            if step.assessed is None:
                refused.append(step.why)
            else:
                loops.append(_loop(t.axis, "proposed", step.assessed))
                share[t.axis] = round(step.share, 3)
                values.update(step.params)
            for name, value in t.params.items():
                rows.append(
                    messages.GainRow(
                        name=name,
                        current=current.get(name),
                        designed=value,
                        proposed=step.params.get(name),
                    )
                )
        if designed.yaw is not None:
            name = "YAW2SRV_DAMP"
            d, c = designed.yaw.params[name], current.get(name)
            # From off (0) the damper is switched on at its design; else a step of at most
            # max_step either way, as the other gains.
            step = (
                d if not c or not d else c * float(np.clip(d / c, 1 / cfg.max_step, cfg.max_step))
            )
            values[name] = round(step, 4)
            rows.append(messages.GainRow(name=name, current=c, designed=d, proposed=values[name]))
        if values:  # one speed scaler for both axes: set with the gains designed at it
            values["SCALING_SPEED"] = round(scaling, 1)
        rows.append(
            messages.GainRow(
                name="SCALING_SPEED",
                current=current.get("SCALING_SPEED"),
                designed=round(scaling, 1),
                proposed=values.get("SCALING_SPEED"),
            )
        )
        return (rows, values, loops, share), refused

    async def _restore(self, replaced: Mapping[str, float]) -> dict[str, float]:
        """After a failed apply: the set before put back, as far as the autopilot takes it;
        what it holds then (read back, empty where not even a read answers)."""
        try:
            return await self.autopilot.set_parameters(replaced)
        except AutopilotError as exc:
            self.counters["gains_restore_failed"] += 1
            log.error("gains: the set before could not be restored: %s", exc)
            try:
                return await self.autopilot.parameters(list(replaced))
            except AutopilotError:
                return {}

    def _report(self, action: str, proposal: str | None, values, reason: str) -> None:
        self.logbook.gains(action, proposal, dict(values), reason)
        (log.warning if action == "failed" else log.info)(
            "gains %s %s: %s (%s)", action, proposal, _listed(values), reason
        )
        self.downlink.send(
            messages.GainsReport(
                action=action, proposal=proposal, values=dict(values), reason=reason[:200]
            )
        )


def _as_tune_model(candidate: Candidate) -> tune.Model:
    """A stored model as the design takes it (agent.tune.Model)."""
    cont = candidate.result.continuous
    if cont is None or candidate.result.coordinates != "outputs":
        raise LookupError(f"{candidate.model_id} has no continuous model in output coordinates")
    return tune.Model(
        id=candidate.model_id,
        inputs=list(candidate.result.inputs),
        outputs=list(candidate.result.outputs),
        A=np.asarray(cont.A, dtype=float),
        B=np.asarray(cont.B, dtype=float),
        C=np.asarray(cont.C, dtype=float),
        trim=dict((candidate.trim or {}).get("outputs", {})),
    )


def _loop(axis: str, which: str, a: tune.Assessed) -> messages.LoopPrediction:
    def finite(v):
        return None if v is None or not math.isfinite(v) else round(float(v), 4)

    m = a.attitude_loop
    if m.gain_db == -math.inf:  # the closed loop is unstable (agent.tune.loop_margins)
        return messages.LoopPrediction(axis=axis, gains=which, stable=False)
    return messages.LoopPrediction(
        axis=axis,
        gains=which,
        crossover_rad_s=finite(m.crossover_rad_s),
        phase_margin_deg=finite(m.phase_deg),
        gain_margin_db=finite(m.gain_db),
        delay_margin_s=finite(m.delay_margin_s),
        rejection_rad_s=finite(m.rejection_rad_s),
        rise_s=finite(a.rise_s),
        overshoot_pct=finite(a.overshoot_pct),
        rise_down_s=None if a.down is None else finite(a.down[0]),
        overshoot_down_pct=None if a.down is None else finite(a.down[1]),
        sound=a.sound(),
    )


def _yaw_notes(yaw: tune.YawTune | None) -> list[str]:
    """The yaw damper's prediction for the operator."""
    if yaw is None:
        return []
    before, after = yaw.before, yaw.after
    margin = "∞" if math.isinf(yaw.gain_margin_db) else f"{yaw.gain_margin_db:.1f} dB"
    line = (
        f"yaw damper (designed): Dutch roll ζ {yaw.zeta(before):.2f} → {yaw.zeta(after):.2f} at "
        f"{abs(after):.2f} rad/s with the roll loop closed, the damper's gain margin {margin}"
    )
    return [line, *yaw.notes]


def _listed(values: Mapping[str, float]) -> str:
    return ", ".join(f"{k} {v:g}" for k, v in values.items()) or "nothing"


def _rms(after: tuple[float, ...]) -> str:
    return ", ".join(f"{what} rms {v:.2f}" for what, v in zip(TRACKED, after, strict=True))
