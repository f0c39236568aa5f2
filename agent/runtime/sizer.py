"""The plans' sizing onboard (agent/sizing.py): the ground asks how a plan would fly, the agent
answers with each control's amplitude and why, the predicted response and the envelope's
refusals; an armed plan whose predicted response leaves the envelope is refused.

The model is the one `Identifier.sizing_model` names (the nominal, else this flight's newest
good candidate), checked against this flight's other records of its axes (`Identifier.recent`);
each surface's linkage (its measured position per commanded degree, per |commanded degree|
from its knee, and the knee: agent.excitation.follow) is the last finished run's, measured
where the agent checks that the surfaces followed their commands. Rendering and prediction
take seconds for the full preset: they run on a thread, never on the event loop.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable

from agent import sizing
from agent.config import Config
from agent.excitation.plan import Plan, check
from agent.link import messages
from agent.runtime.identification import Identifier
from drivers.values import FlightState


class Sizer:
    def __init__(
        self,
        *,
        config: Config,
        identification: Identifier,
        flight: Callable[[], FlightState | None],
    ):
        self.config, self.identification, self._flight = config, identification, flight
        self.linkage: dict[str, tuple[float, float, float]] = {}
        """Control → (gain, even) of the last finished run (agent.excitation.follow)."""

    def flight(self) -> dict[str, float]:
        """The flight state now by output role, SI (empty: none yet)."""
        s = self._flight()
        if s is None:
            return {}
        return {
            "airspeed": s.airspeed,
            "alpha": math.radians(s.alpha_deg),
            "theta": math.radians(s.pitch_deg),
            "phi": math.radians(s.bank_deg),
        }

    async def predictor(self, plan: Plan) -> sizing.Predictor | None:
        found = await self.identification.sizing_model(plan.axes)
        if found is None:
            return None
        candidate, source = found
        # Off the event loop: the model is checked on its records, and the linear range
        # refits the records' nuisance parameters (seconds on a flight computer).
        return await asyncio.to_thread(
            sizing.predictor_from,
            candidate,
            self.config.identification.channels,
            self.config.excitation.surfaces,
            source,
            flight=self.flight(),
            linkage=dict(self.linkage),
            others=tuple(self.identification.recent.get(candidate.axes, ())),
        )

    def flown(self, plan: Plan) -> dict[str, float] | None:
        """What the last run of these axes flew, by control (plan units), for a plan no model
        sizes: the build-up grows from there (None: no run yet)."""
        ident = self.identification
        last = ident.latest.get(plan.axes) or ident.latest.get("full")
        if last is None:
            return None
        return sizing.deflections(
            last.result,
            last.experiments,
            self.config.identification.channels,
            self.config.excitation.surfaces,
            self.linkage,
        )

    async def size(self, plan: Plan) -> sizing.Sizing:
        """`plan` sized to the aircraft; PlanRefused, with every reason, for a plan that
        arming would refuse on its own (a control not configured, a frequency above Nyquist,
        too long)."""
        ex = self.config.excitation
        predictor = await self.predictor(plan)
        flown = None if predictor is not None else self.flown(plan)
        trim = self.flight()

        def work() -> sizing.Sizing:
            # Checked as an arm checks it (PlanRefused with every reason): a plan from the
            # radio with a harmonic of 1e6 is refused from its parameters, never rendered.
            timeline = check(plan, ex.rate_hz, ex.surfaces, ex.envelope)
            return sizing.size(
                plan,
                timeline,
                predictor,
                ex.sizing,
                ex.surfaces,
                ex.envelope,
                trim=trim,
                flown=flown,
            )

        return await asyncio.to_thread(work)

    async def refusals(self, plan: Plan) -> list[str]:
        """Where the plan's predicted response leaves the envelope (empty: it stays in, or no
        model predicts it)."""
        ex = self.config.excitation
        predictor = await self.predictor(plan)
        if predictor is None:
            return []
        trim = self.flight()

        def work() -> list[str]:
            peaks = sizing.predict(predictor, check(plan, ex.rate_hz, ex.surfaces, ex.envelope))
            return sizing.envelope_refusals(peaks, ex.envelope, predictor.airspeed, trim)

        return await asyncio.to_thread(work)


def sizing_message(sized: sizing.Sizing, surfaces) -> messages.Sizing:
    """A sizing as the ground sees it."""
    return messages.Sizing(
        plan=sized.plan,
        source=sized.source[:120],
        build_up=sized.build_up,
        controls=[
            messages.SizedControl(
                control=c,
                amplitude=round(a, 4),
                unit="%" if surfaces[c].unit == "percent" else "deg",
                factor=round(sized.factors[c], 4),
                limited_by=sized.limited_by[c][:80],
            )
            for c, a in sized.amplitudes.items()
        ],
        predicted={q: round(v, 3) for q, v in sized.predicted.items()},
        corrections={q: round(v, 3) for q, v in sized.corrections.items()},
        unexplained={q: round(v, 3) for q, v in sized.unexplained.items()},
        refusals=[r[:200] for r in sized.refusals],
    )
