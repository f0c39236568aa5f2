"""Excitation sized to the aircraft: amplitudes chosen from the response they will cause, not
from degrees, and a plan refused when its predicted response leaves the envelope.

The same ±4° of aileron banks a J-3 Cub at 60 kt to 11° and a four-seat trainer at 95 kt to
36°; the same full preset took a turboprop trainer into the ground (JSBSim, docs/excitation.md).
A flight-test engineer sizes inputs to the response: enough to stand above turbulence and
sensor noise, small enough to stay linear and inside the envelope. Here:

1. The prediction is a linear model of the aircraft (`Predictor`): the axes' nominal model,
   or the newest identified candidate that fits its own data, driven by the plan's commands
   in the record's units (surface degrees as the potentiometers measure them; the throttle's
   servo output in µs, `us_per_unit` per percent). It predicts each response the run cares
   about (`QUANTITIES`): bank, airspeed, angle of attack, sideslip, pitch attitude, load
   factor (V₀(q − α̇)/g) and the height lost (V₀∫(θ − α)dt, wings level), over the plan and
   `TAIL_S` after it.
2. Each sweep and multisine is shaped to its response (`shape`): the frequencies where it
   moves the aircraft most play less, so its one amplitude is not set by its worst band.
   Then each control is sized alone: the factor on its plan amplitude that brings its own
   largest predicted response to its target ([excitation.sizing]). Then the controls play
   together: while a quantity exceeds its target, every control contributing at least
   `CONTRIBUTION` of it is scaled down by the excess.
3. Limits: a control never exceeds its `max_amplitude`, nor `max_factor` times the plan's own
   amplitude (1 by default: the targets only take amplitude away), nor `max_growth` times the
   largest deflection in the data its model was identified from (a model is trusted near what
   it has seen; amplitude build-up, as in flight test), nor the linear range the flight's
   records at other amplitudes show (`linear_range`: the larger record's model priced on the
   smaller record, agent.ident.aircraft.linearity).
4. With no model, the plan flies at `build_up` of its amplitudes: the first run is the
   calibration, and its identification sizes the next.
5. The targets never reach past the envelope ([excitation.envelope], from the flight state
   now: `within`), and whatever sized it, a plan whose predicted response (trim plus the
   peaks) leaves the envelope is refused before it is armed (`envelope_refusals`); the
   envelope monitor still ends a run that leaves it in flight.

No I/O and no event loop: the agent calls it on a thread (a render of the full preset takes
seconds).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from agent.channels import AXIS_SETS, OUTPUT_ROLES
from agent.config import Channels, Envelope, Surface
from agent.config import Sizing as SizingConfig
from agent.excitation import follow
from agent.excitation.plan import MAX_BREAKPOINTS, Multisine, Plan, Sweep, Timeline, render
from agent.excitation.signals import shaped
from agent.ident.aircraft import linearity
from agent.ident.aircraft.kinematics import KINEMATIC_STATES, kinematic_jacobian, kinematics
from agent.ident.convert import StateSpace
from agent.ident.document import ResultDocument
from agent.ident.fit import simulate
from agent.link import messages
from agent.models import Candidate

G = 9.80665
# Predicted after the plan ends (s): the free response still moves the aircraft (a phugoid's
# airspeed swing peaks a quarter period later), though the run has ended by then.
TAIL_S = 10.0
# A control takes part in a quantity's excess when its own response in that quantity is at
# least this share of the combined one.
CONTRIBUTION = 0.1
# Rounds of step 2: each scales the controls behind every quantity still above its target, on
# the linear responses (ROUNDS) and then with the full kinematics (FULL_ROUNDS, a simulation
# each); a quantity within SLACK of its target is on it.
ROUNDS, FULL_ROUNDS = 20, 5
SLACK = 1.01
# The quantities whose prediction is checked on the model's own data (`checked`), the
# smoothing that keeps sensor noise out of their measured peaks (s), and the largest
# correction applied (a gain beyond it says more about the record, a drift or a gust, than
# about the model's scale; what the corrected prediction leaves is the unexplained part).
CORRECTED = ("bank_deg", "airspeed_pct", "alpha_deg", "beta_deg", "pitch_deg")
SMOOTH_S = 0.5
MAX_CORRECTION = 4.0
# The attitudes are the integrals of the rates: a model's small error in a rate's slowest
# response (a spiral a little more stable than the aircraft's, a trim) grows without bound over
# a long run and follows the predicted attitude's own slow part, so a gain fitted on the whole
# run takes that drift for a scale error, and the plan it sizes flies well short of its
# targets (docs/excitation.md, *Checked on its own data*). Their gain is fitted on both sides
# less their mean over DRIFT_S about each sample; what the corrected prediction leaves, the
# drift included, is still the unexplained part. That gain is taken only where it explains
# the attitude's drift-free part (what it leaves there at most UNKNOWN_SHARE of that part's
# peak): a bank the gusts dominate shows nothing of the model's scale, and the whole run's
# gain, when larger, is kept (the side that flies the smaller plan).
INTEGRATED = ("bank_deg", "pitch_deg")
DRIFT_S = 10.0
# A quantity whose unexplained excursion is more than this share of its data's own excursion
# is one the model does not know: it is predicted from the data instead, its measured peak
# grown as its controls grow (`Predictor.extrapolated`).
UNKNOWN_SHARE = 0.5
# Another record of the same axes tells the gusts' excursion from a drift the model misses when
# its controls played at least this many times larger or smaller (`_air`): a gust response's
# peak over one record varies from record to record by tens of percent, so the square root of
# the inputs' growth must stand above that (√2 ≈ 1.41); nearer 1, a drift that grows with the
# inputs passes as the air's and the plan is sized past the envelope (benchmarks/README.md).
AIR_GROWTH = 2.0
# The linear range (`linear_range`): two records whose axis's controls played at least
# AMPLITUDES_APART times apart; a named mode of the axis apart between their models by more than
# LINEARITY_SHARE of it (pole distance over |λ|); and the larger record's model leaving more than
# LINEARITY_EXCESS more of the smaller record's weighted cost unexplained than that record's own
# model (agent.ident.aircraft.linearity): the aircraft is not linear over the span, and the
# controls that grew play no more than the smaller record did. JSBSim's PC-7 at 150 kt, calm,
# its full preset at 1, ½ and ¼ of a sized 2.1° of elevator (short period 10.5, 3.7 and 1.0 %
# off the truth): the larger model's excess on its longitudinal axis 1.23 (1 on ½) and 2.16
# (1 on ¼); the SGS 1-26 glider, whose short period moves by 1 % between the same scales, at
# most 0.18. Nearer than AMPLITUDES_APART, a difference is a repeat's (the fit step's).
AMPLITUDES_APART = 1.25
LINEARITY_SHARE = 0.05
LINEARITY_EXCESS = 0.5
# Each axis's controls, the named modes that tell its linearity, and each mode's controls: those
# that excite it, the ones held where it moves with the amplitude. A short period that moves is
# no reason to take the throttle away: the PC-7 with both held (2.4 % of throttle for 4.9 %) had
# its full preset's phugoid 9.3 % off in median (3.9 % before) and its card's 13.4 % (5.4 %).
AXIS_CONTROLS = {"longitudinal": ("elevator", "throttle"), "lateral": ("aileron", "rudder")}
AXIS_MODES = {"longitudinal": ("short period", "phugoid"), "lateral": ("Dutch roll", "roll")}
MODE_CONTROLS = {
    "short period": ("elevator",),
    "phugoid": ("elevator", "throttle"),
    "Dutch roll": ("rudder", "aileron"),
    "roll": ("aileron",),
}
# Each checked quantity's axis: its controls are the ones grown from the data's peak.
AXIS_OF = {
    "bank_deg": "lateral",
    "beta_deg": "lateral",
    "airspeed_pct": "longitudinal",
    "alpha_deg": "longitudinal",
    "pitch_deg": "longitudinal",
}
# The share of the envelope's room (from the trim, less what no input explains) the targets
# may take: the rest is left to the prediction's error.
ENVELOPE_SHARE = 0.9
# Shaping (`shape`): a sweep is split into BANDS_PER_DECADE bands per decade of its
# frequencies, a multisine into its lines (`_breakpoints`). No part plays less than MIN_GAIN
# of the signal's amplitude: the record keeps some power in every band it was meant to
# cover, whatever the model says of it. A shape within FLAT of 1 everywhere is left out: the
# signal is played as written.
BANDS_PER_DECADE = 5
# Shaping and sizing alternate (`size`) at most SHAPE_PASSES times.
SHAPE_PASSES = 3
MIN_GAIN = 0.1
FLAT = 0.95
# The quantities predicted, with their unit for the operator.
QUANTITIES = {
    "bank_deg": "°",
    "airspeed_pct": "%",
    "alpha_deg": "°",
    "beta_deg": "°",
    "pitch_deg": "°",
    "load_factor": "g",
    "height_loss_m": "m",
}
# The operator's names of the quantities, for the lines shown before arming.
LABELS = {
    "bank_deg": "bank",
    "airspeed_pct": "airspeed",
    "alpha_deg": "α",
    "beta_deg": "β",
    "pitch_deg": "pitch",
    "load_factor": "load factor",
    "height_loss_m": "height loss",
}


@dataclass(frozen=True, kw_only=True)
class Kinematic:
    """A model whose states are aircraft states, predicted with the rigid body's kinematics
    and gravity in full: the identified model holds their linear part at the trim, and what
    it leaves out (the remainder: a bank's lost lift, the pitch attitude's change in a turn)
    is added as a forcing of each state present. The aerodynamic forces stay linear."""

    A: np.ndarray  # continuous, its first states the model's outputs
    B: np.ndarray
    dt: float
    state: Mapping[int, int]  # KINEMATIC_STATES index → the model's state
    output: Mapping[int, int]  # the model's output → its state
    trim: np.ndarray  # the trim in KINEMATIC_STATES order, absolute, SI
    drag: tuple[int, float] | None = None  # (the airspeed's state, V̇'s gain on β²)

    def simulate(self, u: np.ndarray) -> np.ndarray:
        """The outputs (deviations from trim) driven by u, each sample held over dt."""
        n, r = self.B.shape
        k = len(KINEMATIC_STATES)
        block = np.zeros((n + r + k, n + r + k))
        block[:n, :n], block[:n, n : n + r] = self.A, self.B
        for i, j in self.state.items():
            block[j, n + r + i] = 1.0  # the remainder's row i forces state j
        phi = scipy.linalg.expm(block * self.dt)
        Ad, Bd, Ed = phi[:n, :n], phi[:n, n : n + r], phi[:n, n + r :]
        jacobian = kinematic_jacobian(self.trim)
        at_trim = kinematics(self.trim)
        which = np.array(list(self.state)), np.array(list(self.state.values()))
        beta = KINEMATIC_STATES.index("beta")
        x, out = np.zeros(n), np.empty((len(u), len(self.output)))
        deviation = np.zeros(k)
        for step, row in enumerate(u):
            out[step] = x[list(self.output.values())]
            deviation[which[0]] = x[which[1]]
            forcing = kinematics(self.trim + deviation) - at_trim - jacobian @ deviation
            x = Ad @ x + Bd @ row + Ed @ forcing
            if self.drag is not None:
                x[self.drag[0]] += self.drag[1] * deviation[beta] ** 2 * self.dt
        return out


@dataclass(frozen=True, kw_only=True)
class Predictor:
    """A linear model of the aircraft that predicts a plan's response."""

    model: StateSpace  # discrete, at dt, inputs and outputs deviations from trim
    dt: float
    inputs: Mapping[str, int]  # control role → the model's input column
    outputs: Mapping[str, int]  # output role (agent.channels) → the model's output column
    per_unit: Mapping[str, float]  # control → the record's units per plan unit
    airspeed: float | None  # the trim airspeed (m/s); None: unknown (no airspeed, load
    # factor or height predicted)
    flown: Mapping[str, float] = field(default_factory=dict)
    """Control → the largest deflection (plan units) in the data the model came from."""
    source: str = "model"
    kinematic: Kinematic | None = None
    """The model's states as aircraft states, for a prediction with the rigid body's full
    kinematics (None: the linear model alone)."""
    correction: Mapping[str, float] = field(default_factory=dict)
    """Quantity → how much more its data moved with the inputs than the model predicts on
    them (≥ 1; `checked`)."""
    unexplained: Mapping[str, float] = field(default_factory=dict)
    """Quantity → the largest excursion of its data that no input explains (`checked`)."""
    extrapolated: Mapping[str, float] = field(default_factory=dict)
    """Quantity → its data's peak excursion, where the model explains less than UNKNOWN_SHARE
    of it (`checked`): predicted as that peak times the growth of its axis's controls over
    what the data flew (`flown`), when that is more than the model predicts: a response the
    model does not hold (a drift that grows with the inputs) must not be sized by the model
    alone (docs/excitation.md, *Sizing*)."""
    linear: Mapping[str, tuple[float, str]] = field(default_factory=dict)
    """Control → (the largest amplitude in plan units at which its axis showed itself linear,
    why), where a record at a smaller amplitude showed the aircraft not linear beyond it
    (`linear_range`)."""
    linkage: Mapping[str, tuple[float, ...]] = field(default_factory=dict)
    """Control → (gain, even, knee): its recorded position per commanded deflection, per
    |commanded − knee| deflection, and the knee, measured on the last run
    (agent.excitation.follow; `moved`); without it the record follows the command at
    `per_unit`."""

    def commands(self, timeline: Timeline, factors: Mapping[str, float]) -> np.ndarray:
        """The model's inputs (record units, at dt) for the timeline's controls, each times its
        factor (a control absent from `factors` is left out), over the plan and TAIL_S."""
        n = math.ceil((timeline.duration + TAIL_S) / self.dt)
        index = np.minimum((np.arange(n) * self.dt / timeline.dt).astype(int), timeline.count)
        u = np.zeros((n, self.model.B.shape[1]))
        for control, factor in factors.items():
            if control in self.inputs and control in timeline.values:
                values = np.append(timeline.values[control], 0.0)[index]
                link = self.linkage.get(control, (self.per_unit[control], 0.0))
                u[:, self.inputs[control]] += factor * moved(link, values)
        return u

    def response(self, timeline: Timeline, control: str) -> dict[str, np.ndarray]:
        """Each quantity's predicted time history for `control`'s part of the timeline alone,
        by the linear model (an empty dict when the model does not take the control)."""
        if control not in self.inputs or control not in timeline.values:
            return {}
        with np.errstate(all="ignore"):
            y = simulate(self.model, self.commands(timeline, {control: 1.0}))
        if not np.all(np.isfinite(y)):
            return {}
        return self._quantities(y)

    def nonlinear(self, timeline: Timeline, factors: Mapping[str, float]) -> dict[str, np.ndarray]:
        """Each quantity's predicted time history with every control playing at its factor, by
        the model with the rigid body's full kinematics (the linear model's without them)."""
        u = self.commands(timeline, factors)
        with np.errstate(all="ignore"):
            y = simulate(self.model, u) if self.kinematic is None else self.kinematic.simulate(u)
        if not np.all(np.isfinite(y)):
            return {}
        return self._quantities(y)

    def gains(self, control: str, hz: np.ndarray) -> dict[str, np.ndarray]:
        """Each quantity's steady amplitude per plan unit of `control` played as a sine at each
        frequency in `hz`, by the linear model (an empty dict when the model does not take the
        control or does not settle; the height lost, which no target bounds, is left out)."""
        if control not in self.inputs:
            return {}
        A, B, C, D = self.model.A, self.model.B, self.model.C, self.model.D
        j = self.inputs[control]
        gain, even, *_ = self.linkage.get(control, (self.per_unit[control], 0.0))
        hz = np.asarray(hz, dtype=float)
        eye = np.eye(A.shape[0])
        with np.errstate(all="ignore"):
            y = np.array(
                [
                    C @ np.linalg.solve(np.exp(2j * np.pi * f * self.dt) * eye - A, B[:, j])
                    for f in hz
                ]
            ).reshape(hz.size, C.shape[0])
            y = (y + D[:, j]) * (abs(gain) + abs(even))
        if not np.all(np.isfinite(y)):
            return {}
        col, out = self.outputs, {}
        for role, q in (
            ("phi", "bank_deg"),
            ("alpha", "alpha_deg"),
            ("beta", "beta_deg"),
            ("theta", "pitch_deg"),
        ):
            if role in col:
                out[q] = np.degrees(np.abs(y[:, col[role]]))
        if "airspeed" in col and self.airspeed:
            out["airspeed_pct"] = 100 * np.abs(y[:, col["airspeed"]]) / self.airspeed
        if "q" in col and "alpha" in col and self.airspeed:
            normal = y[:, col["q"]] - 2j * np.pi * hz * y[:, col["alpha"]]
            out["load_factor"] = self.airspeed * np.abs(normal) / G
        return out

    def _quantities(self, y: np.ndarray) -> dict[str, np.ndarray]:
        out = {}
        col = self.outputs

        def has(*roles: str) -> bool:
            return all(r in col for r in roles)

        if has("phi"):
            out["bank_deg"] = np.degrees(y[:, col["phi"]])
        if has("airspeed") and self.airspeed:
            out["airspeed_pct"] = 100 * y[:, col["airspeed"]] / self.airspeed
        if has("alpha"):
            out["alpha_deg"] = np.degrees(y[:, col["alpha"]])
        if has("beta"):
            out["beta_deg"] = np.degrees(y[:, col["beta"]])
        if has("theta"):
            out["pitch_deg"] = np.degrees(y[:, col["theta"]])
        if has("q", "alpha") and self.airspeed:
            alpha_rate = np.gradient(y[:, col["alpha"]], self.dt)
            out["load_factor"] = self.airspeed * (y[:, col["q"]] - alpha_rate) / G
        if has("theta", "alpha") and self.airspeed:
            climb = self.airspeed * (y[:, col["theta"]] - y[:, col["alpha"]])
            out["height_loss_m"] = -np.cumsum(climb) * self.dt  # positive: height lost
        return out


@dataclass(frozen=True, kw_only=True)
class Sizing:
    """What the agent will fly: the sized plan, why each amplitude, and what it predicts."""

    plan: Plan
    factors: dict[str, float]  # control → the factor on the plan's amplitudes
    amplitudes: dict[str, float]  # control → its largest deflection (plan units)
    limited_by: dict[str, str]  # control → what set its amplitude
    predicted: dict[str, float]  # quantity → its predicted peak (None: no model)
    source: str
    refusals: list[str] = field(default_factory=list)  # the envelope's, from the prediction
    corrections: dict[str, float] = field(default_factory=dict)  # the predictor's (≥ 1)
    build_up: bool = False  # no model sized it: the build-up share of the plan
    unexplained: dict[str, float] = field(default_factory=dict)  # the predictor's
    held: frozenset[str] = frozenset()
    """Controls held below their signals' shaping by a limit no shape relieves (`size`)."""

    def lines(self, units: Mapping[str, str] | None = None) -> list[str]:
        """The sizing as lines for the operator."""
        units = units or {}
        return describe(
            source=self.source,
            controls=[
                (c, a, units.get(c, ""), self.factors[c], self.limited_by[c])
                for c, a in self.amplitudes.items()
            ],
            predicted=self.predicted,
            corrections=self.corrections,
            unexplained=self.unexplained,
            refusals=self.refusals,
            shaped=shape_lines(self.plan),
        )


def describe(
    *,
    source: str,
    controls: Sequence[tuple[str, float, str, float, str]],
    predicted: Mapping[str, float],
    corrections: Mapping[str, float],
    unexplained: Mapping[str, float],
    refusals: Sequence[str],
    shaped: Sequence[str] = (),
) -> list[str]:
    """A sizing as lines for the operator; `controls`: (control, amplitude, unit, factor,
    what limited it); `shaped`: the signals shaped to their response (`shape_lines`)."""

    def each(values: Mapping[str, float], form: str) -> str:
        return ", ".join(
            form.format(label=LABELS.get(q, q), v=v, unit=QUANTITIES.get(q, ""))
            for q, v in values.items()
        )

    out = [f"amplitudes sized by {source}"]
    out += [f"  {c} {a:.3g} {unit} (×{f:.2f}: {why})" for c, a, unit, f, why in controls]
    out += shaped
    if predicted:
        out.append("  predicted: " + each(predicted, "{label} {v:.3g}{unit}"))
    if corrections:
        out.append(
            "  its data moved more than it predicts: " + each(corrections, "{label} ×{v:.2f}")
        )
    if unexplained:
        out.append(
            "  its data moved besides the inputs (turbulence, drift; checked against the "
            "envelope): " + each(unexplained, "{label} {v:.3g}{unit}")
        )
    out += [f"REFUSED: {r}" for r in refusals]
    return out


def message_lines(sized: messages.Sizing) -> list[str]:
    """A sizing as the ground hears it, as lines for the operator."""
    return describe(
        source=sized.source,
        controls=[(c.control, c.amplitude, c.unit, c.factor, c.limited_by) for c in sized.controls],
        predicted=sized.predicted,
        corrections=sized.corrections,
        unexplained=sized.unexplained,
        refusals=sized.refusals,
        shaped=shape_lines(sized.plan),
    )


def peaks(responses: Mapping[str, np.ndarray]) -> dict[str, float]:
    """Each quantity's largest magnitude (the height lost: its largest positive value)."""
    out = {}
    for q, v in responses.items():
        out[q] = float(max(np.max(v), 0.0)) if q == "height_loss_m" else float(np.max(np.abs(v)))
    return out


def targets(config: SizingConfig) -> dict[str, float]:
    """The configured target of each quantity (the height lost has none: the envelope's)."""
    return {
        "bank_deg": config.bank_deg,
        "airspeed_pct": config.airspeed_pct,
        "alpha_deg": config.alpha_deg,
        "beta_deg": config.beta_deg,
        "pitch_deg": config.pitch_deg,
        "load_factor": config.load_factor,
    }


def within(
    goal: Mapping[str, float],
    envelope: Envelope,
    airspeed: float | None,
    trim: Mapping[str, float] | None = None,
    unexplained: Mapping[str, float] | None = None,
) -> dict[str, float]:
    """The targets, each within ENVELOPE_SHARE of the room the envelope leaves from the trim
    (`trim`: the flight state now by output role, SI) once what no input explains is taken
    off: a sizing aims inside the limits the run is held to."""
    trim, unexplained = trim or {}, unexplained or {}
    out = dict(goal)
    room = {
        "bank_deg": envelope.max_bank_deg - abs(math.degrees(trim.get("phi", 0.0))),
        "pitch_deg": envelope.max_pitch_deg - abs(math.degrees(trim.get("theta", 0.0))),
        "alpha_deg": envelope.max_alpha_deg - math.degrees(trim.get("alpha", 0.0)),
    }
    v0 = trim.get("airspeed", airspeed)
    if v0:
        room["airspeed_pct"] = (
            100 * min(v0 - envelope.min_airspeed, envelope.max_airspeed - v0) / v0
        )
    for q, limit in room.items():
        limit = ENVELOPE_SHARE * (limit - unexplained.get(q, 0.0))
        if q in out and limit > 0:
            out[q] = min(out[q], limit)
    return out


def scaled(plan: Plan, factors: Mapping[str, float]) -> Plan:
    """`plan` with each control's signals' amplitudes times its factor."""
    segments = tuple(
        segment.model_copy(
            update={
                "signals": {
                    c: sig.model_copy(update={"amplitude": sig.amplitude * factors.get(c, 1.0)})
                    for c, sig in segment.signals.items()
                }
            }
        )
        for segment in plan.segments
    )
    return plan.model_copy(update={"segments": segments})


def size(
    plan: Plan,
    timeline: Timeline,
    predictor: Predictor | None,
    config: SizingConfig,
    surfaces: Mapping[str, Surface],
    envelope: Envelope,
    trim: Mapping[str, float] | None = None,
    flown: Mapping[str, float] | None = None,
) -> Sizing:
    """The plan's amplitudes sized to the aircraft (module docstring); `timeline` is the plan
    rendered, `trim` the flight state now (output roles, SI) for the envelope check. With no
    predictor, `flown` (control → the largest deflection of the last run, plan units:
    `deflections`) grows the build-up from there: a run whose model sized nothing (its
    response did not stand above the turbulence) calibrates nothing either.

    With a predictor, the plan is sized as written, then each sweep and multisine shaped to
    its response (`shape`) at the largest level it may reach, and the plan sized again. No
    frequency plays less than the plan as written would there: the band that limits a
    signal is the one whose mode it moves most, and a shape must add where there is room,
    not take the information about that mode away (a phugoid's throttle lines). A control
    held lower by what its shape cannot relieve (a quantity the model does not know, grown
    from what its data flew) is shaped again at the level it got; each pass keeps the floor
    at the level the last one reached (SHAPE_PASSES at most)."""
    if predictor is None:
        return _build_up(plan, timeline, config, surfaces, flown)
    goal = within(targets(config), envelope, predictor.airspeed, trim, predictor.unexplained)
    written = _sized(plan, timeline, predictor, config, surfaces, envelope, trim, goal)
    sized, last, levels, expected = written, plan, {}, {}
    for _ in range(SHAPE_PASSES):
        # Each frequency keeps at least what the plan as written would play there: over the
        # level each control is expected at (first the largest it may reach, then the last
        # pass's), the level the written plan got.
        floors = {
            c: written.factors[c] / expected.get(c, _largest(c, plan, predictor, config, surfaces))
            for c in written.factors
        }
        shaped_plan = shape(plan, predictor, goal, config, surfaces, timeline.dt, levels, floors)
        if shaped_plan == last:
            break
        rendered = render(shaped_plan, 1 / timeline.dt)
        sized = _sized(shaped_plan, rendered, predictor, config, surfaces, envelope, trim, goal)
        last = shaped_plan
        levels = {c: sized.factors[c] for c in sized.held}
        expected = dict(sized.factors)
    return sized


def _build_up(
    plan: Plan,
    timeline: Timeline,
    config: SizingConfig,
    surfaces: Mapping[str, Surface],
    flown: Mapping[str, float] | None,
) -> Sizing:
    """With no model: the build-up share of the plan, or `max_growth` times what the last run
    flew (`size`)."""
    controls = list(timeline.values)
    peak = {c: float(np.max(np.abs(timeline.values[c]))) for c in controls}
    ceiling = {c: surfaces[c].max_amplitude / peak[c] if peak[c] > 0 else 1.0 for c in controls}
    factors, limited_by = {}, {}
    for c in controls:
        limits = {
            "max_amplitude": ceiling[c],
            f"the plan's amplitude ×{config.max_factor:g}": config.max_factor,
        }
        last = (flown or {}).get(c, 0.0)
        if last > 0 and peak[c] > 0:
            limits[f"build-up: {config.max_growth:g}× the {last:.3g} the last run flew"] = (
                config.max_growth * last / peak[c]
            )
        else:
            limits[f"build-up: {config.build_up:g} of the plan"] = config.build_up
        limited_by[c] = min(limits, key=limits.get)
        factors[c] = limits[limited_by[c]]
    source = (
        "build-up from the last run (its model sizes nothing: this run calibrates the next)"
        if flown
        else "build-up (no model of the aircraft yet: this run calibrates the next)"
    )
    return Sizing(
        plan=scaled(plan, factors),
        factors=factors,
        amplitudes={c: factors[c] * peak[c] for c in controls},
        limited_by=limited_by,
        predicted={},
        source=source,
        build_up=True,
    )


def _sized(
    plan: Plan,
    timeline: Timeline,
    predictor: Predictor,
    config: SizingConfig,
    surfaces: Mapping[str, Surface],
    envelope: Envelope,
    trim: Mapping[str, float] | None,
    goal: Mapping[str, float],
) -> Sizing:
    """The plan (shaped as it is) sized by the predictor to `goal` (`size`, steps 2–4 of the
    module docstring)."""
    controls = list(timeline.values)
    peak = {c: float(np.max(np.abs(timeline.values[c]))) for c in controls}
    ceiling = {c: surfaces[c].max_amplitude / peak[c] if peak[c] > 0 else 1.0 for c in controls}
    alone = {c: predictor.response(timeline, c) for c in controls}
    factors, limited_by = {}, {}
    unrelieved = set()  # the limits a shape cannot relieve
    for c in controls:
        own = peaks(alone[c])
        limits = {"max_amplitude": ceiling[c]}
        limits[f"the plan's amplitude ×{config.max_factor:g}"] = config.max_factor
        flown = predictor.flown.get(c, 0.0)
        if flown > 0 and peak[c] > 0:
            limits[f"{config.max_growth:g}× the {flown:.3g} its model saw"] = (
                config.max_growth * flown / peak[c]
            )
        if c in predictor.linear and peak[c] > 0:
            amplitude, why = predictor.linear[c]
            limits[why] = amplitude / peak[c]
        for q, target in goal.items():
            if own.get(q, 0.0) > 0:
                limits[f"{LABELS[q]} {target:.3g}{QUANTITIES[q]}"] = target / own[q]
            known = predictor.extrapolated.get(q, 0.0)
            if known > 0 and _axis_controls(q, (c,)) and flown > 0 and peak[c] > 0:
                why = f"{LABELS[q]} {target:.3g}{QUANTITIES[q]}: {known:.3g}{QUANTITIES[q]} flown"
                limits[f"{why}, not in the model"] = target / known * flown / peak[c]
                unrelieved.add(f"{why}, not in the model")
        if not alone[c]:
            limits = {"build-up: its model does not take it": min(config.build_up, ceiling[c])}
        limited_by[c] = min(limits, key=limits.get)
        factors[c] = limits[limited_by[c]]
    first = {c: (factors[c], limited_by[c]) for c in controls}
    own = {c: peaks(alone[c]) for c in controls}
    # Cheap rounds on the linear responses first, then the kinematics in full (a bank's lost
    # lift costs height and gains speed, which no superposition of linear responses shows).
    for full in (False, True):
        for _ in range(ROUNDS if not full else FULL_ROUNDS):
            total = _estimate(predictor, timeline, alone, own, factors, full)
            over = {q: goal[q] / total[q] for q in goal if total.get(q, 0.0) > goal[q] * SLACK}
            if not over:
                break
            for q, ratio in over.items():
                share = {c: factors[c] * own[c].get(q, 0.0) for c in controls}
                for c in controls:
                    if share[c] >= CONTRIBUTION * max(share.values()):
                        factors[c] *= ratio
                        limited_by[c] = f"{LABELS[q]} {goal[q]:.3g}{QUANTITIES[q]} with the others"
    _grown_back(
        lambda now: _estimate(predictor, timeline, alone, own, now, True),
        factors,
        first,
        limited_by,
        goal,
    )
    predicted = _estimate(predictor, timeline, alone, own, factors, True)
    sized = scaled(plan, factors)
    return Sizing(
        plan=sized,
        held=frozenset(c for c in controls if limited_by[c] in unrelieved),
        factors=factors,
        amplitudes={c: factors[c] * peak[c] for c in controls},
        limited_by=limited_by,
        predicted=predicted,
        source=predictor.source,
        refusals=envelope_refusals(
            with_unexplained(predicted, predictor), envelope, predictor.airspeed, trim
        ),
        corrections=dict(predictor.correction),
        unexplained=dict(predictor.unexplained),
    )


def shape(
    plan: Plan,
    predictor: Predictor,
    goal: Mapping[str, float],
    config: SizingConfig,
    surfaces: Mapping[str, Surface],
    dt: float,
    levels: Mapping[str, float] | None = None,
    floors: Mapping[str, float] | None = None,
) -> Plan:
    """`plan` with each sweep's and multisine's amplitude shaped to the response it causes:
    the parts of its frequencies that move the aircraft most play less (`_breakpoints`), so
    the low end of a glider's elevator sweep, which swings the airspeed, no longer holds the
    whole sweep to a fraction of a degree. The level is then sized as every signal's
    (`size`). Signals of a control the model does not take, and pulses, are left as they
    are; a shape the sizing computed before is replaced. `levels` (control → a factor on its
    plan amplitudes) shapes a control's signals at that level rather than at the largest
    they may reach; `floors` (control → a share) keeps each frequency at least at that share
    of what the plan as written plays there (`size`).
    """
    segments = []
    for segment in plan.segments:
        signals = {}
        for c, sig in segment.signals.items():
            if isinstance(sig, Sweep | Multisine) and c in predictor.inputs:
                cap = _cap(c, sig, predictor, config, surfaces)
                if levels and c in levels:
                    cap = min(cap, levels[c] * abs(sig.amplitude))
                floor = min(1.0, (floors or {}).get(c, 0.0))
                breakpoints = _breakpoints(plan, c, sig, predictor, goal, cap, dt, floor)
                sig = sig.model_copy(update={"shape": breakpoints})
            signals[c] = sig
        segments.append(segment.model_copy(update={"signals": signals}))
    return plan.model_copy(update={"segments": tuple(segments)})


def _breakpoints(
    plan: Plan,
    control: str,
    sig: Sweep | Multisine,
    predictor: Predictor,
    goal: Mapping[str, float],
    cap: float,
    dt: float,
    floor: float = 0.0,
) -> tuple[tuple[float, float], ...]:
    """A signal's shape (`shape`): breakpoints (Hz, gain), or () where it is flat; no gain
    below `floor` times the signal's own shape (as written) at its frequency.

    A multisine's lines play together and repeat: each is judged by the model's steady
    response (`Predictor.gains`), its gain the largest share of the cap that keeps every
    quantity within its target, relative to the largest. Judged alone, N lines of equal
    response sum to a peak about √N times each line's, and each line's share of the
    signal's peak is about 1/√N of it: the two cancel, so a line is judged against the
    signal's whole cap. (Lines alone in the time domain would not do: each starts off trim
    where together they start at it, and those starts dwarf what each line moves.)

    A sweep plays its frequencies in turn, and a lightly damped mode it passed keeps ringing
    (a glider's phugoid swings the airspeed after the sweep has left its band), from every
    band that passes near it. The sweep is split into bands, BANDS_PER_DECADE per decade,
    that sum to it, each faded in and out along the sweep (`signals.split_by_frequency`), and
    each band's response predicted by the linear model in the time domain. At the cap, while
    a quantity's sum over the bands exceeds its target, the bands that make its peak (at
    least CONTRIBUTION of the largest share, at the peak's time and with its sign) are turned
    down by the excess, as `size` turns down controls; the shape is the bands' gains relative
    to the largest, at their centres."""
    factor = cap / abs(sig.amplitude)  # the cap as a factor on the signal's amplitude
    if isinstance(sig, Multisine):
        centres = np.sort(sig.hz)
        allowance = np.full(centres.size, np.inf)
        for q, v in predictor.gains(control, centres).items():
            if q in goal:
                with np.errstate(divide="ignore"):
                    v = v * predictor.correction.get(q, 1.0) * abs(sig.amplitude)
                    allowance = np.minimum(allowance, goal[q] / v)
        if centres.size < 2 or factor <= 0 or not np.any(np.isfinite(allowance)):
            return ()
        gain = np.minimum(allowance, factor) / min(factor, float(np.max(allowance)))
        return _breakpoints_of(centres, np.maximum(gain, floor * shaped(sig.shape, centres)))
    lo, hi = sorted((sig.f0_hz, sig.f1_hz))
    if hi <= lo or factor <= 0:
        return ()
    count = math.ceil(math.log10(hi / lo) * BANDS_PER_DECADE)
    centres = np.geomspace(lo, hi, min(MAX_BREAKPOINTS, max(2, count)))
    responses: dict[str, list[np.ndarray]] = {}
    for part in sig.bands(dt, centres):
        values = np.append(part, 0.0)
        timeline = Timeline(plan, dt, {control: values}, {control: values != 0})
        alone = predictor.response(timeline, control)
        if not alone:
            return ()
        for q in goal:
            if q in alone:
                scale = factor * predictor.correction.get(q, 1.0)
                responses.setdefault(q, []).append(scale * alone[q])
    if not responses:
        return ()
    stacked = {q: np.array(r) for q, r in responses.items()}
    gain = np.ones(centres.size)
    for _ in range(ROUNDS):
        over = False
        for q, r in stacked.items():
            total = gain @ r
            at = int(np.argmax(np.abs(total)))
            peak = abs(float(total[at]))
            if peak <= goal[q] * SLACK:
                continue
            over = True
            share = gain * r[:, at] * np.sign(total[at])
            gain[share >= CONTRIBUTION * share.max()] *= goal[q] / peak
        if not over:
            break
    gain = np.maximum(gain / np.max(gain), floor * shaped(sig.shape, centres))
    return _breakpoints_of(centres, gain)


def _breakpoints_of(hz: np.ndarray, gain: np.ndarray) -> tuple[tuple[float, float], ...]:
    """Gains at frequencies as a shape: each at least MIN_GAIN, () when all are within FLAT
    of 1 (rounded: the shape goes over the radio)."""
    gain = np.clip(gain, MIN_GAIN, 1.0)
    if np.min(gain) >= FLAT:
        return ()
    return tuple((float(f"{f:.6g}"), round(float(g), 3)) for f, g in zip(hz, gain, strict=True))


def _largest(
    control: str,
    plan: Plan,
    predictor: Predictor,
    config: SizingConfig,
    surfaces: Mapping[str, Surface],
) -> float:
    """The largest factor on its plan amplitudes a control's signals may reach (`_cap`)."""
    caps = [
        _cap(control, sig, predictor, config, surfaces) / abs(sig.amplitude)
        for segment in plan.segments
        for c, sig in segment.signals.items()
        if c == control
    ]
    return min(caps, default=1.0)


def _cap(
    control: str,
    sig: Sweep | Multisine,
    predictor: Predictor,
    config: SizingConfig,
    surfaces: Mapping[str, Surface],
) -> float:
    """The largest amplitude a signal may reach whatever its response: the plan's times
    max_factor, the control's max_amplitude, max_growth times what its model saw."""
    caps = [abs(sig.amplitude) * config.max_factor, surfaces[control].max_amplitude]
    if predictor.flown.get(control, 0.0) > 0:
        caps.append(config.max_growth * predictor.flown[control])
    return min(caps)


def shape_lines(plan: Plan) -> list[str]:
    """Each shaped signal as a line for the operator: its lowest gain and where, and where it
    plays its full amplitude."""
    out = []
    for segment in plan.segments:
        for c, sig in segment.signals.items():
            breakpoints = getattr(sig, "shape", ())
            if not breakpoints:
                continue
            hz = np.array([f for f, _ in breakpoints])
            gain = np.array([g for _, g in breakpoints])
            low = int(np.argmin(gain))
            full = hz[gain >= 0.99]
            at = f"full from {full.min():.3g} to {full.max():.3g} Hz" if full.size else ""
            out.append(
                f"  {c} {sig.kind} shaped to its response: ×{gain[low]:.2f} at {hz[low]:.3g} Hz"
                + (f", {at}" if at else "")
            )
    return out


def _grown_back(
    estimate: Callable[[Mapping[str, float]], dict[str, float]],
    factors: dict[str, float],
    first: Mapping[str, tuple[float, str]],
    limited_by: dict[str, str],
    goal: Mapping[str, float],
) -> None:
    """The controls scaled down "with the others" grown back, together, while the full
    prediction (`estimate` of the factors) leaves every quantity below its target, up to each
    one's own limit (`first`): the linear rounds can take more than the kinematics in full
    then show (docs/excitation.md, *Sizing*)."""
    for _ in range(FULL_ROUNDS):
        low = [c for c in factors if factors[c] < first[c][0] / SLACK]
        if not low:
            return
        total = estimate(factors)
        room = min((goal[q] / total[q] for q in goal if total.get(q, 0.0) > 0), default=1.0)
        if room <= SLACK:
            return
        for c in low:
            factors[c] = min(first[c][0], factors[c] * room)
            if factors[c] >= first[c][0] / SLACK:
                limited_by[c] = first[c][1]


def predict(predictor: Predictor, timeline: Timeline) -> dict[str, float]:
    """The peaks of the plan's predicted response, every control playing as rendered (times
    the predictor's corrections), with what no input explains added: the peaks the
    envelope is checked against."""
    factors = dict.fromkeys(timeline.values, 1.0)
    found = peaks(predictor.nonlinear(timeline, factors))
    corrected = {q: v * predictor.correction.get(q, 1.0) for q, v in found.items()}
    for q, v in _extrapolated(predictor, timeline, factors).items():
        corrected[q] = max(corrected.get(q, 0.0), v)
    return with_unexplained(corrected, predictor)


def with_unexplained(predicted: Mapping[str, float], predictor: Predictor) -> dict[str, float]:
    """The predicted peaks with the model's unexplained excursions added (`checked`)."""
    return {q: v + predictor.unexplained.get(q, 0.0) for q, v in predicted.items()}


def _estimate(
    predictor: Predictor,
    timeline: Timeline,
    alone: Mapping[str, dict],
    own: Mapping[str, dict[str, float]],
    factors: Mapping[str, float],
    full: bool,
) -> dict[str, float]:
    """The peaks a run is sized by: each quantity's larger of the controls' responses together
    (with the kinematics in full when `full` and the model allows) and the root-sum-square of
    each control's own peak. No credit is taken for one control's response cancelling
    another's: on the C172R the throttle's roll (the propeller's torque) cancelled half the
    ailerons' bank in the prediction, and the aircraft flown banked twice as far."""
    together = predictor.nonlinear(timeline, factors) if full else {}
    together = peaks(together or _combined(alone, factors))
    out = {}
    for q in {*together, *(q for p in own.values() for q in p)}:
        rss = math.sqrt(sum((factors[c] * p.get(q, 0.0)) ** 2 for c, p in own.items()))
        out[q] = max(together.get(q, 0.0), rss) * predictor.correction.get(q, 1.0)
    for q, v in _extrapolated(predictor, timeline, factors).items():
        out[q] = max(out.get(q, 0.0), v)
    return out


def _extrapolated(
    predictor: Predictor, timeline: Timeline, factors: Mapping[str, float]
) -> dict[str, float]:
    """The quantities the model does not know (`Predictor.extrapolated`), each its data's
    peak times the largest growth over what the data flew of its axis's controls
    (`AXIS_OF`): what the model misses of the other axis's controls' reach, their linear
    coupling, the model's coupling tests would have found."""
    out = {}
    for q, peak in predictor.extrapolated.items():
        growth = [
            factors[c] * float(np.max(np.abs(timeline.values[c]))) / predictor.flown[c]
            for c in _axis_controls(q, factors)
            if c in timeline.values and predictor.flown.get(c, 0.0) > 0
        ]
        if growth:
            out[q] = peak * max(growth)
    return out


def _axis_controls(quantity: str, controls) -> list[str]:
    """The controls of the quantity's axis among `controls` (none for a quantity of no one
    axis: only the checked ones are extrapolated)."""
    if quantity not in AXIS_OF:
        return []
    mine = AXIS_SETS[AXIS_OF[quantity]][0]
    return [c for c in controls if c in mine]


def _combined(alone: Mapping[str, dict], factors: Mapping[str, float]) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    for c, responses in alone.items():
        for q, v in responses.items():
            out[q] = out.get(q, 0.0) + factors.get(c, 1.0) * v
    return out


def envelope_refusals(
    predicted: Mapping[str, float],
    envelope: Envelope,
    airspeed: float | None,
    trim: Mapping[str, float] | None = None,
) -> list[str]:
    """Where the predicted response, from the trim, leaves the envelope (empty: it stays in).
    `trim` holds the flight state now by output role (SI); without it the trim is wings
    level at `airspeed`, α and θ unknown (their limits checked on the excursion alone)."""
    trim = trim or {}
    v0 = trim.get("airspeed", airspeed)
    reasons = []

    def check(quantity: str, start: float, limit: float, what: str, unit: str) -> None:
        if quantity in predicted and abs(start) + predicted[quantity] > limit:
            reasons.append(
                f"predicted {what} {abs(start) + predicted[quantity]:.3g}{unit} exceeds the "
                f"envelope's {limit:g}{unit}"
            )

    check("bank_deg", math.degrees(trim.get("phi", 0.0)), envelope.max_bank_deg, "bank", "°")
    check("pitch_deg", math.degrees(trim.get("theta", 0.0)), envelope.max_pitch_deg, "pitch", "°")
    check("alpha_deg", math.degrees(trim.get("alpha", 0.0)), envelope.max_alpha_deg, "α", "°")
    check("height_loss_m", 0.0, envelope.max_altitude_loss_m, "height loss", " m")
    if "airspeed_pct" in predicted and v0:
        swing = v0 * predicted["airspeed_pct"] / 100
        if v0 - swing < envelope.min_airspeed:
            reasons.append(
                f"predicted airspeed {v0 - swing:.3g} m/s is below the envelope's "
                f"{envelope.min_airspeed:g} m/s"
            )
        if v0 + swing > envelope.max_airspeed:
            reasons.append(
                f"predicted airspeed {v0 + swing:.3g} m/s is above the envelope's "
                f"{envelope.max_airspeed:g} m/s"
            )
    return reasons


def per_unit(surface: Surface) -> float:
    """The record's units per plan unit of a control: a throttle's plan is in percent and its
    record the servo output (µs, `us_per_unit` per percent, in the control's direction); a
    surface's plan and its potentiometer are both degrees of the surface."""
    return surface.direction * surface.us_per_unit if surface.unit == "percent" else 1.0


def predictor_from(
    candidate: Candidate,
    channels: Channels,
    surfaces: Mapping[str, Surface],
    source: str,
    flight: Mapping[str, float] | None = None,
    linkage: Mapping[str, tuple[float, ...]] | None = None,
    others: Sequence[Candidate] = (),
) -> Predictor | None:
    """A stored model as a predictor of the plans' response (None: see `predictor`);
    `others`: other candidates of its axes, whose records tell the gusts from what the model
    misses (`checked`), and whose records and models at other amplitudes the linear range
    (`linear_range`)."""
    alike = [
        c
        for c in others
        if c.model_id != candidate.model_id
        and (c.result.inputs, c.result.outputs)
        == (candidate.result.inputs, candidate.result.outputs)
    ]
    return predictor(
        candidate.result,
        trim=(candidate.trim or {}).get("outputs", {}),
        experiments=candidate.experiments,
        channels=channels,
        surfaces=surfaces,
        source=source,
        flight=flight,
        linkage=linkage,
        others=[e for c in alike for e in c.experiments],
        fitted=candidate.fitted,
        earlier=[
            (c.result, c.fitted, deflections(c.result, c.experiments, channels, surfaces, linkage))
            for c in alike
            if c.fitted is not None
        ],
    )


def predictor(
    result: ResultDocument,
    *,
    trim: Mapping[str, float],
    experiments: Sequence[tuple[np.ndarray, np.ndarray]],
    channels: Channels,
    surfaces: Mapping[str, Surface],
    source: str,
    flight: Mapping[str, float] | None = None,
    linkage: Mapping[str, tuple[float, ...]] | None = None,
    others: Sequence[tuple[np.ndarray, np.ndarray]] = (),
    fitted: object | None = None,
    earlier: Sequence[tuple[ResultDocument, object, Mapping[str, float]]] = (),
) -> Predictor | None:
    """An identified model as a predictor of the plans' response: `trim` is its record's trim
    outputs by channel, `experiments` its data (u, y), trim removed, `flight` the flight
    state now by output role (the trim of what the model does not hold), `others` other
    records of its axes in the same form (`checked`: the gusts told from what the model
    misses), `fitted` its record as the whole-aircraft method fitted it and `earlier` other
    models of its axes with their records so fitted and what they flew (`deflections`): the
    linear range (`linear_range`). None when it
    predicts nothing a sizing uses: no configured control among its inputs or no output of a
    quantity. Without a known airspeed (a lateral model, flown with no flight state yet) the
    airspeed, load factor and height are not predicted."""
    inputs = {
        role: result.inputs.index(name)
        for role in surfaces
        if (name := getattr(channels, role, None)) in result.inputs
    }
    outputs = {
        role: result.outputs.index(getattr(channels, role))
        for role in OUTPUT_ROLES
        if getattr(channels, role) in result.outputs
    }
    known = {
        role: trim[getattr(channels, role)]
        for role in OUTPUT_ROLES
        if getattr(channels, role) in trim
    }
    state = {**(flight or {}), **known}  # the model's own trim first, else the flight's now
    airspeed = state.get("airspeed")
    airspeed = float(airspeed) if airspeed and airspeed > 0 else None
    if not inputs or not outputs:
        return None
    scale = {c: per_unit(surfaces[c]) for c in inputs}
    linkage = {c: v for c, v in (linkage or {}).items() if c in inputs}
    flown = deflections(result, experiments, channels, surfaces, linkage)
    matrices = (result.A, result.B, result.C, result.D)
    model = StateSpace(*(np.asarray(m, dtype=float) for m in matrices))
    unchecked = Predictor(
        model=model,
        dt=result.dt,
        inputs=inputs,
        outputs=outputs,
        per_unit=scale,
        airspeed=airspeed,
    )
    correction, unexplained, extrapolated = checked(unchecked, experiments, others)
    return Predictor(
        model=model,
        dt=result.dt,
        inputs=inputs,
        outputs=outputs,
        per_unit=scale,
        airspeed=airspeed,
        flown=flown,
        source=source,
        kinematic=_kinematic(result, outputs, state),
        correction=correction,
        unexplained=unexplained,
        extrapolated=extrapolated,
        linear=linear_range(result, fitted, flown, earlier),
        linkage=linkage,
    )


def linear_range(
    result: ResultDocument,
    fitted: object | None,
    flown: Mapping[str, float],
    earlier: Sequence[tuple[ResultDocument, object, Mapping[str, float]]],
) -> dict[str, tuple[float, str]]:
    """Control → (the largest amplitude, plan units, at which its axis showed itself linear,
    why): over this model (its record `fitted`, which flew `flown`) and each of `earlier`,
    per axis, where one record's controls of the axis all played at least as large as the
    other's and some at least AMPLITUDES_APART larger, a named mode of the axis is more than
    LINEARITY_SHARE apart between the two models, and the larger record's model leaves more
    than LINEARITY_EXCESS more of the smaller record's weighted cost unexplained than its own
    (agent.ident.aircraft.linearity), the controls that grew and excite a mode that moved
    (MODE_CONTROLS) play no more than the smaller record did. The tightest over the pairs is
    kept."""
    out: dict[str, tuple[float, str]] = {}
    if fitted is None:
        return out
    mine = (result, fitted, flown)
    for theirs in earlier:
        for axis, controls in AXIS_CONTROLS.items():
            both = [c for c in controls if flown.get(c, 0.0) > 0 and theirs[2].get(c, 0.0) > 0]
            up = all(flown[c] >= theirs[2][c] for c in both)
            down = all(flown[c] <= theirs[2][c] for c in both)
            if not both or up == down:  # the same amplitudes, or one up and another down
                continue
            big, small = (mine, theirs) if up else (theirs, mine)
            grown = [c for c in both if big[2][c] >= AMPLITUDES_APART * small[2][c]]
            if not grown:
                continue
            apart = {
                name: d
                for name in AXIS_MODES[axis]
                if (d := _mode_apart(big[0], small[0], name)) is not None and d > LINEARITY_SHARE
            }
            held = [c for c in grown if any(c in MODE_CONTROLS[name] for name in apart)]
            if not held:
                continue
            try:
                share = linearity.excess(small[1], big[1]).get(axis)
            except (np.linalg.LinAlgError, ValueError, ArithmeticError):
                continue  # a refit that fails tells nothing: no limit from this pair
            # No evidence either where a model's dynamics are not numbers (a diverged fit).
            if share is None or not math.isfinite(share) or share <= LINEARITY_EXCESS:
                continue
            modes = ", ".join(f"{name} {100 * d:.0f} %" for name, d in apart.items())
            for c in held:
                if small[2][c] < out.get(c, (math.inf, ""))[0]:
                    out[c] = (
                        small[2][c],
                        f"linear range: {modes} apart at {big[2][c]:.3g} and "
                        f"{small[2][c]:.3g}, the larger's model leaving {100 * share:.0f} % "
                        "more of the smaller record unexplained",
                    )
    return out


def _mode_apart(a: ResultDocument, b: ResultDocument, name: str) -> float | None:
    """How far apart a named mode is between two models: the largest distance pole by pole
    over |λ| of `b`'s; None where it does not pair."""
    mine, theirs = _named(a, name), _named(b, name)
    if not mine or len(mine) != len(theirs):
        return None
    return max(
        abs(complex(*p.eigenvalue) - complex(*q.eigenvalue))
        / max(abs(complex(*q.eigenvalue)), 1e-12)
        for p, q in zip(mine, theirs, strict=True)
    )


def _named(result: ResultDocument, name: str) -> list:
    """The modes named `name` in the upper half plane, by real part."""
    found = [m for m in result.modes if m.name == name and m.eigenvalue[1] >= 0]
    return sorted(found, key=lambda m: m.eigenvalue[0])


def moved(link: Sequence[float], values: np.ndarray) -> np.ndarray:
    """A control's recorded change from trim for commanded `values` through its linkage
    (gain, even[, knee]): gain·u + even·(|u − knee| − |knee|) (agent.excitation.follow's
    `Following.moved`; a knee at trim where none is given)."""
    return follow.moved(values, *link)


def deflections(
    result: ResultDocument,
    experiments: Sequence[tuple[np.ndarray, np.ndarray]],
    channels: Channels,
    surfaces: Mapping[str, Surface],
    linkage: Mapping[str, tuple[float, ...]] | None = None,
) -> dict[str, float]:
    """Control → the largest deflection its data saw, in plan units: through the measured
    linkage when known (a surface that moves a third of its command saw three times its
    recorded deflection), else the control's record units per plan unit."""
    linkage = linkage or {}
    out = {}
    for role in surfaces:
        name = getattr(channels, role, None)
        if name not in result.inputs:
            continue
        j = result.inputs.index(name)
        gain = abs(linkage[role][0]) if role in linkage else abs(per_unit(surfaces[role]))
        if gain > 0:
            peak = max((float(np.max(np.abs(u[:, j]))) for u, _ in experiments), default=0.0)
            out[role] = peak / gain
    return out


def checked(
    predictor: Predictor,
    experiments,
    others=(),
) -> tuple[dict[str, float], dict[str, float], dict[str, float]]:
    """The model checked on its own data, quantity by quantity (CORRECTED; both sides
    smoothed over SMOOTH_S): the correction, the least-squares gain of the measured excursion
    on the one the model predicts from the same recorded inputs (an attitude's on both less
    their slow drift where that explains them, INTEGRATED), when above 1 (at most
    MAX_CORRECTION); the unexplained excursion, the largest of what the corrected prediction
    leaves (turbulence, an untrimmed drift); and the quantities the model does not know, with
    their data's peak excursion (`Predictor.extrapolated`). The correction scales
    the model's predictions of the response to the inputs. The unexplained excursion is added
    to the peaks the envelope is checked against, not to those the targets size (a plan sized
    smaller in turbulence would only stand less above it), unless it is most of what the data
    moved: the model does not know that quantity, and its data predict it instead — unless
    `others`, other records of the same axes, show that what it leaves does not follow the
    inputs (`_air`)."""
    gains: dict[str, float] = {}
    unexplained: dict[str, float] = {}
    measured_peak: dict[str, float] = {}
    for u, y in experiments:
        for q, (gain, peak, left) in _left(predictor, u, y).items():
            gains[q] = max(gains.get(q, 1.0), gain)
            unexplained[q] = max(unexplained.get(q, 0.0), left)
            measured_peak[q] = max(measured_peak.get(q, 0.0), peak)
    unknown = {
        q: peak
        for q, peak in measured_peak.items()
        if unexplained.get(q, 0.0) > UNKNOWN_SHARE * peak
    }
    if others and unknown:
        air = _air(predictor, list(experiments), list(others), set(unknown))
        unknown = {q: v for q, v in unknown.items() if q not in air}
    return {q: g for q, g in gains.items() if g > 1.0}, unexplained, unknown


def _left(predictor: Predictor, u, y) -> dict[str, tuple[float, float, float]]:
    """One record against the model (`checked`): per quantity, the correction, the measured
    peak excursion and what the corrected prediction leaves of it (empty: the record is
    shorter than the smoothing, or the model does not settle on it)."""
    window = max(1, round(SMOOTH_S / predictor.dt))
    drift = max(1, round(DRIFT_S / predictor.dt))
    if len(u) <= window:
        return {}
    with np.errstate(all="ignore"):
        model = simulate(predictor.model, np.asarray(u, dtype=float))
    if not np.all(np.isfinite(model)):
        return {}
    measured = _smoothed(predictor._quantities(np.asarray(y, dtype=float)), window)
    predicted = _smoothed(predictor._quantities(model), window)
    out = {}
    for q in CORRECTED:
        if q not in measured or q not in predicted:
            continue
        m, p = measured[q] - measured[q][0], predicted[q] - predicted[q][0]
        fm, fp = (_drift_free(m, drift), _drift_free(p, drift)) if q in INTEGRATED else (m, p)
        power = float(fp @ fp)
        if power <= 0:
            continue
        gain = float(np.clip((fm @ fp) / power, 1.0, MAX_CORRECTION))
        left = float(np.max(np.abs(m - gain * p)))
        fast = float(np.max(np.abs(fm - gain * fp)))
        if q in INTEGRATED and fast > UNKNOWN_SHARE * float(np.max(np.abs(fm))):
            # Not explained without the drift either (INTEGRATED): the larger gain.
            gain = max(gain, float(np.clip((m @ p) / (p @ p), 1.0, MAX_CORRECTION)))
            left = float(np.max(np.abs(m - gain * p)))
        out[q] = (gain, float(np.max(np.abs(m))), left)
    return out


def _air(predictor: Predictor, own: list, others: list, quantities: set[str]) -> set[str]:
    """The quantities among `quantities` whose unexplained excursion does not follow the
    inputs: a drift the model misses that the inputs cause grows with them (JSBSim's T-6:
    faster), the gusts' response does not. Over each pair of the model's own record and
    another of the same axes whose controls of the quantity's axis all played at least
    AIR_GROWTH times larger in one of the two (`_levels`), the excursion is the air's when it
    grew less than the square root of the smallest growth (√2 where the inputs grew 2×):
    half-way, on a log scale, between no growth and the inputs' own. It is taken as the air's
    only where some pair qualifies and every qualifying pair agrees (a gust's peak is random:
    where one pair shows growth, the quantity stays one the model does not know)."""
    mine = [(_levels(predictor, u), _left(predictor, u, y)) for u, y in own]
    theirs = [(_levels(predictor, u), _left(predictor, u, y)) for u, y in others]
    out = set()
    for q in quantities:
        controls = [c for c in _axis_controls(q, predictor.inputs)]
        verdicts = []
        for (la, ra), (lb, rb) in ((a, b) for a in mine for b in theirs):
            if q not in ra or q not in rb or not controls:
                continue
            for (hi, hi_left), (lo, lo_left) in (((la, ra), (lb, rb)), ((lb, rb), (la, ra))):
                if all(lo[c] > 0 and hi[c] >= AIR_GROWTH * lo[c] for c in controls):
                    growth = min(hi[c] / lo[c] for c in controls)
                    verdicts.append(hi_left[q][2] < math.sqrt(growth) * lo_left[q][2])
        if verdicts and all(verdicts):
            out.add(q)
    return out


def _levels(predictor: Predictor, u) -> dict[str, float]:
    """Control → its largest recorded deflection in a record (record units)."""
    u = np.asarray(u, dtype=float)
    return {
        c: float(np.max(np.abs(u[:, j]))) if len(u) else 0.0 for c, j in predictor.inputs.items()
    }


def _drift_free(signal: np.ndarray, window: int) -> np.ndarray:
    """`signal` less its mean over `window` samples about each one (the ends held)."""
    if window < 2 or signal.size < window:
        return signal - signal.mean()
    padded = np.pad(signal, (window // 2, window - 1 - window // 2), mode="edge")
    return signal - np.convolve(padded, np.ones(window) / window, mode="valid")


def _smoothed(responses: Mapping[str, np.ndarray], window: int) -> dict[str, np.ndarray]:
    kernel = np.ones(window) / window
    return {q: np.convolve(v, kernel, mode="valid") for q, v in responses.items()}


def _kinematic(
    result: ResultDocument, outputs: Mapping[str, int], state: Mapping[str, float]
) -> Kinematic | None:
    """The model as a Kinematic one, when its continuous form's states include its outputs
    and the trim of every aircraft state is known (None otherwise)."""
    cont = result.continuous
    if cont is None or result.coordinates != "outputs":
        return None
    # A steady trim has no rates and, the aircraft being symmetric, no sideslip: those may be
    # unknown; the airspeed, α and the attitude must be known.
    state = {"q": 0.0, "p": 0.0, "r": 0.0, "beta": 0.0, **state}
    if any(role not in state for role in KINEMATIC_STATES):
        return None
    C = np.asarray(cont.C, dtype=float)
    of_output = {}
    for i, row in enumerate(C):
        ones = np.flatnonzero(row)
        if len(ones) != 1 or row[ones[0]] != 1.0:
            return None  # an output that is not one state
        of_output[i] = int(ones[0])
    states = {
        KINEMATIC_STATES.index(role): of_output[column]
        for role, column in outputs.items()
        if role in KINEMATIC_STATES
    }
    drag = None
    aircraft = result.aircraft
    if aircraft is not None and aircraft.sideslip_drag is not None and "airspeed" in outputs:
        drag = (of_output[outputs["airspeed"]], aircraft.sideslip_drag.gain)
    return Kinematic(
        A=np.asarray(cont.A, dtype=float),
        B=np.asarray(cont.B, dtype=float),
        dt=result.dt,
        state=states,
        output=of_output,
        trim=np.array([state[role] for role in KINEMATIC_STATES], dtype=float),
        drag=drag,
    )
