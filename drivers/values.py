"""The value types the layers share, held by the lowest one so that every layer above can
import them and none below imports upward (`tests/test_layers.py`): the clock's protocol,
the flight state the autopilot reports and the excitation envelope is checked against, and
an excitation window the scheduler hands the recorder."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Protocol


class Clock(Protocol):
    """Monotonic seconds and absolute-deadline sleeping (`agent.clock` has the two clocks)."""

    def now(self) -> float: ...

    async def sleep_until(self, deadline: float) -> None: ...


@dataclass(frozen=True)
class FlightState:
    """Latest aircraft state the envelope is checked against (from sensors or autopilot)."""

    time: float
    bank_deg: float
    pitch_deg: float
    airspeed: float
    alpha_deg: float
    altitude_m: float


@dataclass(frozen=True)
class Window:
    """An excitation window for the recorder: the data between start and end belong to it."""

    plan_id: str
    axes: str
    start: float
    end: float
    outcome: Literal["finished", "aborted"]
    reason: str = ""
    # Played on the pilot's sticks with the autopilot's loops closed (FBWA): its surfaces
    # answered the disturbances too, which the identification must know (closed loop); the
    # run's log says so (agent.logs).
    closed_loop: bool = False
