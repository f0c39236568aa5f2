"""Commands from the ground: each carried out in order and acknowledged, or refused with the
reason.

An abort acts at once, in the link's callback (and cancels any arm or start still waiting its
turn); the others wait in a bounded queue for the command task, which keeps plan rendering and
model-store files off the link's path. `Commands` is the link session's guard: the session
hands an abort on the moment it arrives, whatever the disk does, and refuses through it a
command whose replay state could not be saved or that arrived too late. Each message type
has one handler (`Commands.handlers`): it returns "" when done, or the reason it was not; a
refusal the handler raises (`PlanRefused`, no such model, no previous nominal) is a reason
too. A plan whose run cannot be identified on its axes (an input of them it does not move)
is armed all the same, and the ground told why in a notice. A size request is answered with
the plan's sizing (agent/runtime/sizer.py); an arm whose predicted response leaves the
envelope is refused with what the prediction says. Gain proposals, applies and reverts go to
agent/runtime/gains.py.
"""

from __future__ import annotations

import asyncio
import logging
from collections import Counter
from collections.abc import Awaitable, Callable

from agent.channels import AXIS_SETS
from agent.excitation.plan import Plan, PlanRefused
from agent.excitation.scheduler import Scheduler
from agent.link import messages
from agent.runtime.downlink import Downlink
from agent.runtime.gains import GainTuner
from agent.runtime.identification import Identifier
from agent.runtime.sizer import Sizer, sizing_message

log = logging.getLogger(__name__)

# Ground commands waiting to be handled (more are refused as busy).
COMMAND_QUEUE = 16

Handler = Callable[[messages.Message], Awaitable[str]]


class Commands:
    def __init__(
        self,
        *,
        scheduler: Scheduler,
        identification: Identifier,
        sizer: Sizer,
        gains: GainTuner,
        downlink: Downlink,
        counters: Counter[str],
    ):
        self.scheduler, self.identification, self.sizer = scheduler, identification, sizer
        self.gains = gains
        self.downlink, self.counters = downlink, counters
        self._queue: asyncio.Queue[tuple[messages.Message, int | None]] = asyncio.Queue(
            COMMAND_QUEUE
        )
        self.handlers: dict[type[messages.Message], Handler] = {
            messages.Arm: self._arm,
            messages.SizeRequest: self._size,
            messages.Start: self._start,
            messages.Abort: self._abort,
            messages.IdentSettings: self._settings,
            messages.Decision: self._decision,
            messages.Revert: self._revert,
            messages.FrfRequest: self._frf,
            messages.GainsRequest: self.gains.propose,
            messages.GainsApply: self.gains.apply,
            messages.GainsRevert: self._gains_revert,
        }

    def receive(self, message: messages.Message, seq: int | None) -> None:
        """A command from the link (`seq`: its sequence number to acknowledge, None when sent
        unreliably). An abort acts here; the others are queued for `run`."""
        if isinstance(message, messages.Abort):
            self.scheduler.abort(message.reason)
            self._cancel_queued_runs()
            self._ack(seq, "")
            return
        try:
            self._queue.put_nowait((message, seq))
        except asyncio.QueueFull:
            self.counters["commands_dropped"] += 1
            self._ack(seq, "busy: too many commands waiting; send it again")

    # -- the link session's guard (agent.link.session.Guard) --------------------------------

    def changes_state(self, message: messages.Message) -> bool:
        """Everything but an abort: an abort only makes the aircraft safer."""
        return not isinstance(message, messages.Abort)

    def refuse(self, message: messages.Message, seq: int, reason: str) -> None:
        """The session could not let this command act (its replay state is not on disk, or
        it came too late): the ground is told why."""
        self.counters["commands_refused_by_link"] += 1
        log.warning("%s refused: %s", type(message).__name__, reason)
        self._ack(seq, reason)

    def overtaken(self, message: messages.Message, seq: int) -> None:
        """A command sent before an abort that has already acted: an arm or start is
        cancelled, as one waiting in the queue would be; anything else is carried out."""
        if isinstance(message, messages.Arm | messages.Start):
            self.counters["commands_cancelled"] += 1
            self._ack(seq, "cancelled by an abort that arrived before it was carried out")
        else:
            self.receive(message, seq)

    def _cancel_queued_runs(self) -> None:
        """An abort also cancels an arm or start still waiting its turn (else a plan armed a
        moment before the abort would be armed after it)."""
        kept = []
        while not self._queue.empty():
            message, seq = self._queue.get_nowait()
            if isinstance(message, messages.Arm | messages.Start):
                self.counters["commands_cancelled"] += 1
                self._ack(seq, "cancelled by an abort that arrived before it was carried out")
            else:
                kept.append((message, seq))
        for item in kept:
            self._queue.put_nowait(item)

    async def run(self) -> None:
        """The command task: each queued command in turn."""
        while True:
            message, seq = await self._queue.get()
            await self.handle(message, seq)

    async def handle(self, message: messages.Message, seq: int | None) -> None:
        """Carry out one ground command and acknowledge it (or say why not)."""
        handler = self.handlers.get(type(message))
        if handler is None:  # a message the ground has no business sending up
            self.counters["commands_unknown"] += 1
            self._ack(seq, f"not a command: {type(message).__name__}")
            return
        try:
            reason = await handler(message)
        except (PlanRefused, KeyError, LookupError) as exc:
            reason = str(exc).strip("'")
        self._ack(seq, reason)

    def _ack(self, seq: int | None, reason: str) -> None:
        if seq is not None:
            self.downlink.send(messages.Ack(ref=seq, ok=not reason, reason=reason))

    # -- the handlers: "" when done, else the reason -----------------------------------------

    async def _size(self, message: messages.SizeRequest) -> str:
        sized = await self.sizer.size(message.plan)
        self.downlink.send(sizing_message(sized, self.sizer.config.excitation.surfaces))
        return ""

    async def _arm(self, message: messages.Arm) -> str:
        # The agent never flies a plan its own prediction takes out of the envelope.
        refusals = await self.sizer.refusals(message.plan)
        if refusals:
            self.counters["refused_by_prediction"] += 1
            raise PlanRefused(f"plan {message.plan.id!r} refused: " + "; ".join(refusals))
        await self.scheduler.arm_checked(message.plan)
        unmoved = _unmoved_inputs(
            message.plan,
            self.identification.settings.axes,
            self.sizer.config.excitation.surfaces,
        )
        if unmoved:  # armed all the same: the excitation is the operator's to fly
            self.downlink.send(messages.Notice(text=unmoved))
        return ""

    async def _start(self, message: messages.Start) -> str:
        return self.scheduler.request_start()

    async def _abort(self, message: messages.Abort) -> str:
        self.scheduler.abort(message.reason)
        return ""

    async def _settings(self, message: messages.IdentSettings) -> str:
        return self.identification.apply(message)

    async def _decision(self, message: messages.Decision) -> str:
        await self.identification.decide(message)
        return ""

    async def _revert(self, message: messages.Revert) -> str:
        await self.identification.revert()
        return ""

    async def _frf(self, message: messages.FrfRequest) -> str:
        return await self.identification.request_frf(message)

    async def _gains_revert(self, message: messages.GainsRevert) -> str:
        return await self.gains.revert()


def _unmoved_inputs(plan: Plan, chosen: str | None, controls) -> str:
    """Why the run of `plan` will not identify ("" when it can): an input of the axes it is
    identified on (the operator's `chosen`, else the plan's own) that the aircraft has
    (`controls`) and the plan does not move is constant in the record, and the
    identification fails on it after the flight."""
    axes = chosen or plan.axes
    unmoved = [c for c in AXIS_SETS[axes][0] if c in controls and c not in plan.controls()]
    if not unmoved:
        return ""
    whose = "the ground's settings" if chosen else "the plan's axes"
    text = (
        f"{plan.id}: identified as {axes} ({whose}), which needs {', '.join(unmoved)} "
        f"moved; the plan does not move {'it' if len(unmoved) == 1 else 'them'}"
    )
    if chosen:
        text += ": send settings with each plan's own axes, or arm a plan that moves them"
    return text[:200]
