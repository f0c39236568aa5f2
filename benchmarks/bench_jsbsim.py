"""The whole-aircraft benchmark: six JSBSim aircraft of different kinds, calm and in light and
moderate turbulence, the agent's own full preset and a flight-test engineer's card, each
sized to the aircraft by the agent, identified with the vanes and the INS's navigation
channels, with the vanes alone, and with the INS alone (no vanes), by suas-sysid and by the
peers, in one process.

    make bench-jsbsim                                    # every row, 10 seeds (~46 min here)
    .venv/bin/python benchmarks/bench_jsbsim.py --quick --aircraft c172r --turbulence 0 \
        --excitation card --nav ins                      # one row in about a minute
    .venv/bin/python benchmarks/bench_jsbsim.py --sizing nominal --aircraft pa28
    .venv/bin/python benchmarks/bench_jsbsim.py --no-peers --without alpha-products
    .venv/bin/python benchmarks/bench_jsbsim.py --no-peers --open-loop-prediction \
        --aircraft sgs126 --turbulence 1 --excitation card sweep   # not the default (below)
    .venv/bin/python benchmarks/bench_jsbsim.py --still --aircraft sgs126 --turbulence 1 \
        --excitation full                                # what the air alone does
    .venv/bin/python benchmarks/bench_jsbsim.py --quick --bound --aircraft sgs126 \
        --turbulence 1 --excitation card --nav ins       # what the record could resolve

The aircraft (`AIRCRAFT`): JSBSim's J-3 Cub at 60 kt, Cessna 182 and PA-28 at 90 kt (the three
the method was developed on), the Cessna 172R at 95 kt (a four-seat trainer), the T-6 Texan II
at 150 kt (a turbine's direct thrust, no propeller) and the Schempp-Hirth SGS 1-26 at 50 kt (a
glider: no throttle, trimmed in a steady glide, from 3000 ft); named on its own, an aircraft
the method was not developed on (`OFF_BENCHMARK`: the Cessna 310 twin at 100 kt, 2000 ft; the
PC-7 turboprop at 150 kt) checks what the rows claim. Turbulence: Dryden
(MIL-F-8785C), light W20 = 5 ft/s (`--turbulence 1`), moderate W20 = 15 ft/s (`3`). Seeds
start at 2, because JSBSim's seeds 0 and 1 give one turbulence sequence.

The excitations (`--excitation`): "full", the agent's full preset (an 80 s odd-harmonic
multisine on all four controls at once); "card", a classic flight-test card that is not ours:
a 3-2-1-1 on each surface in turn, a throttle doublet, then a doublet on each surface (`card`);
and "sweep", a frequency-sweep card: a logarithmic sweep from 0.1 to 2 Hz on each surface in
turn, no throttle (`sweeps`): the record's throttle column is then constant, and the method
leaves it out and says so.

Sizing (`--sizing auto`, agent/sizing.py): as the agent flies them. For each aircraft and
condition the full preset is first flown at the build-up share of its amplitudes; each run is
identified (with the INS), its surfaces' linkage measured, and the next sized from that
model, until the plan is sized by the model of a run that a model sized (not the build-up's)
and no amplitude is held back by the build-up's growth limit, or the next plan is one the
agent refuses (at most CALIBRATION_RUNS runs, seeds from CALIBRATION_SEED). The ten seeds
then fly the full preset as sized last, and the cards sized by the same model. `--sizing
nominal` flies each at its plan's own amplitudes.

Each seed is one offline flight (`agent.sim.offline.fly`: JSBSim trimmed as `sysid sim` trims
it, the emulated ArduPlane's servos, the sensors' noise, 100 Hz), 2 s before to 2 s after the
plan, identified as the agent does (the trim from the first 0.5 s): with the INS's heading and
velocities for the wind ("ins"), without them ("none"), and as an aircraft without vanes would
be ("novanes": α and β synthesised from the INS and an estimated steady wind, the gust's α
and β unmeasured; agent.ident.aircraft.airangles).

Truth: `agent.sim.truth.linear_truth`, JSBSim's validated small-amplitude linear model
(`benchmarks/truth_check.py` checks it). Printed per aircraft, condition, excitation,
navigation and method:
- each named mode's error |λ − λ_true| / |λ_true| (median / worst over seeds; "miss" when a
  seed did not find it);
- the seeds with every named mode within 10 %;
- for suas-sysid, the seeds whose spiral holds the truth within 3 standard errors;
- the validation TIC: the model simulated on separate records, its own seed each: an elevator
  doublet judged on V, α, q, θ, and an aileron then a rudder doublet judged on β, p, r, φ
  (the mean of the two means; median / worst over seeds), the doublets sized to the
  atmosphere (`validation_scale`); `--quick` leaves it out;
- the median seconds per identification;
- with `--bound` (`make bench-jsbsim` gives it), for suas-sysid's rows, the validated truth's
  Cramér–Rao bound on the row's records (`truth_bound`): what an efficient estimator of the
  method's structure would do there, each mode's median error and its expected number of
  seeds with every mode within 10 %. A row whose bound misses the 10 % target on 9 of 10
  seeds cannot meet it with any unbiased estimator of that structure.
Below each excitation, what the flights did: the amplitudes flown, the largest bank and
airspeed change, and the lowest height above the ground over the seeds.

The peers get the same records (inputs and outputs less the trim) and the truth's order
without engine, altitude and heading (8 aircraft states + 1); python-control and SIPPY are the
`bench` extra (`pip install -e '.[bench]'`, which `make bench-jsbsim` does). The "validated
truth" row gives the truth's own validation TIC: the best a linear model can score there.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse
import dataclasses
import importlib.util
import time
import warnings
from dataclasses import dataclass

import numpy as np

from agent import sizing
from agent.channels import OUTPUT_ROLES
from agent.config import Channels, Envelope, Excitation
from agent.excitation.follow import following
from agent.excitation.plan import (
    DOUBLET_PULSE_S,
    PRESET_AMPLITUDE,
    Doublet,
    Plan,
    Segment,
    Sweep,
    ThreeTwoOneOne,
    Timeline,
    only,
    preset,
    render,
)
from agent.ident import Experiment, Settings, identify, refine
from agent.ident.aircraft import axes_present
from agent.ident.aircraft.airangles import synthesise
from agent.ident.aircraft.bound import bound
from agent.ident.aircraft.model import fitted_axes
from agent.ident.convert import StateSpace
from agent.ident.errors import DataError, IdentificationFailed
from agent.ident.fit import simulate
from agent.models import DIVERGENCE_LIMIT, Candidate, has_its_modes
from agent.runtime.identification import SIZING_TIC
from agent.sim.flight import ENVELOPE_HEIGHT_S
from agent.sim.offline import INPUT_CHANNELS, Record, fly
from agent.sim.plant import INPUTS, Plant
from agent.sim.truth import Truth, linear_truth, theil


@dataclass(frozen=True)
class Flight:
    """Where a benchmark aircraft flies: its trim airspeed and height above the ground."""

    speed_kts: float
    altitude_ft: float = 1000.0
    kind: str = ""


AIRCRAFT = {
    "J3Cub": Flight(60.0, kind="light piston, tailwheel"),
    "c182": Flight(90.0, kind="piston single"),
    "pa28": Flight(90.0, kind="piston single, low wing"),
    "c172r": Flight(95.0, kind="four-seat trainer"),
    "t6texan2": Flight(150.0, kind="turbine trainer, direct thrust"),
    "sgs126": Flight(50.0, altitude_ft=3000.0, kind="glider, unpowered"),
}
# Aircraft the method was not developed on, flown only when named (`--aircraft c310`): a check
# of what the benchmark's rows claim, not a row of its table. JSBSim trims its Cessna 310 at
# 100 kt (not at 120–160 kt) with its propellers at their pitch stop (benchmarks/README.md).
OFF_BENCHMARK = {
    "c310": Flight(100.0, altitude_ft=2000.0, kind="piston twin, constant-speed propellers"),
    # JSBSim's turboprop engine (FGTurboProp: a gas generator's N1 driving a governed
    # propeller), trimmed by the plant itself (JSBSim's own trim fails on it: agent.sim.plant).
    "pc7": Flight(150.0, kind="turboprop single, constant-speed propeller"),
}
MODES = ("short period", "phugoid", "Dutch roll", "roll")
EXCITATIONS = ("full", "card", "sweep")
# With the INS's navigation and the vanes; the vanes alone; the INS with α and β synthesised
# from it (no vanes).
NAVIGATION = ("ins", "none", "novanes")
TRIM_SAMPLES = 50  # 0.5 s at 100 Hz, as the agent's trim
PEER_ORDER = 9
TEXTBOOK_P = 4
FIRST_SEED = 2  # JSBSim's seeds 0 and 1 give one turbulence sequence
CALIBRATION_SEED = 500
CALIBRATION_RUNS = 5
VALIDATION_SEED = 1000
BOUND_DRAWS = 1000  # draws from the truth's Cramér–Rao bound per record (`truth_bound`)
QUIET_SEED = 1500
SNR_REQUIRED = 3.0
MAX_VALIDATION_SCALE = 2.0
COMMAND_HZ = 50.0  # `fly`'s command rate
# The envelope the benchmark holds its flights to: bank within 30°, airspeed within 10 %.
ENVELOPE_BANK_DEG = 30.0
ENVELOPE_AIRSPEED = 0.10
M_PER_FT = 0.3048
# suas-sysid as the agent runs it on these records: the surfaces' positions are sampled by
# their potentiometers while they move, so the inputs are not held between samples.
OURS = Settings(held_inputs=False)
CONFIG = Excitation()


def card(controls: tuple[str, ...]) -> Plan:
    """A classic flight-test card at the presets' amplitudes: a 3-2-1-1 on each surface in turn
    (0.5 s pulses), a throttle doublet (5 s each way), then a doublet on each surface (the
    presets' pulse widths), each followed by free flight; controls the aircraft lacks are
    left out."""
    segments = []
    for c, free in (("elevator", 4.0), ("aileron", 4.0), ("rudder", 6.0)):
        signal = ThreeTwoOneOne(pulse_s=0.5, amplitude=PRESET_AMPLITUDE[c])
        segments.append(Segment(signals={c: signal}, free_s=free))
    if "throttle" in controls:
        signal = Doublet(pulse_s=5.0, amplitude=PRESET_AMPLITUDE["throttle"])
        segments.append(Segment(signals={"throttle": signal}, free_s=15.0))
    for c, free in (("elevator", 4.0), ("aileron", 4.0), ("rudder", 6.0)):
        signal = Doublet(pulse_s=DOUBLET_PULSE_S[c], amplitude=PRESET_AMPLITUDE[c])
        segments.append(Segment(signals={c: signal}, free_s=free))
    return Plan(id="card", axes="full", segments=tuple(segments))


# The sweep card: a logarithmic sine sweep on each surface in turn (ArduPilot SystemID's chirp
# law), one cycle at its first frequency, then up to its last, faded in and out, each followed
# by free flight. No throttle: sweeps move the surfaces.
SWEEP_HZ = (0.1, 2.0)
SWEEP_S = 40.0
SWEEP_FADE_S = 2.0


def sweeps() -> Plan:
    """A frequency-sweep card at the presets' amplitudes: a logarithmic sweep from
    SWEEP_HZ[0] to SWEEP_HZ[1] on the elevator, then the aileron, then the rudder."""
    segments = tuple(
        Segment(
            signals={
                c: Sweep(
                    f0_hz=SWEEP_HZ[0],
                    f1_hz=SWEEP_HZ[1],
                    duration_s=SWEEP_S,
                    law="log",
                    fade_s=SWEEP_FADE_S,
                    dwell_cycles=1,
                    amplitude=PRESET_AMPLITUDE[c],
                )
            },
            free_s=free,
        )
        for c, free in (("elevator", 5.0), ("aileron", 5.0), ("rudder", 8.0))
    )
    return Plan(id="sweep", axes="full", segments=segments)


@dataclass(frozen=True)
class Setup:
    """One aircraft in one condition: what it has and how it flies."""

    name: str
    flight: Flight
    turbulence: float
    controls: tuple[str, ...]  # the controls it has, in INPUT_CHANNELS order
    airspeed: float  # its true airspeed at the trim, m/s (what the air data measure)

    @property
    def surfaces(self) -> dict:
        return {c: s for c, s in CONFIG.surfaces.items() if c in self.controls}

    @property
    def envelope(self) -> Envelope:
        """The envelope the benchmark holds the flights to (ENVELOPE_BANK_DEG,
        ENVELOPE_AIRSPEED), given to the agent as a flight-test engineer sets the envelope of
        a test: the sizing aims inside it, less what the air alone moves. The height lost is
        `sysid sim`'s limit (agent.sim.flight)."""
        return Envelope(
            max_bank_deg=ENVELOPE_BANK_DEG,
            min_airspeed=(1 - ENVELOPE_AIRSPEED) * self.airspeed,
            max_airspeed=(1 + ENVELOPE_AIRSPEED) * self.airspeed,
            max_altitude_loss_m=max(40.0, ENVELOPE_HEIGHT_S * self.airspeed),
        )

    def fly(
        self, plan: Plan | Timeline, seed: int, noise: bool = True, fbwa: bool = False
    ) -> Record:
        return fly(
            plan,
            aircraft=self.name,
            speed_kts=self.flight.speed_kts,
            altitude_ft=self.flight.altitude_ft,
            turbulence=self.turbulence,
            seed=seed,
            noise=noise,
            fbwa=fbwa,
        )

    def truth(self) -> Truth:
        return linear_truth(self.name, self.flight.speed_kts, altitude_ft=self.flight.altitude_ft)


def columns(setup: Setup) -> list[int]:
    return [INPUT_CHANNELS.index(c) for c in setup.controls]


def experiment(rec: Record, setup: Setup, wind: bool = True, vanes: bool = True) -> Experiment:
    """The record as the agent identifies it: with the INS's navigation (`wind`) or not, and
    with the vanes' α and β or (`vanes` False) those synthesised from the INS and an
    estimated wind (agent.ident.aircraft.airangles), as an aircraft without vanes has them."""
    keep = columns(setup)
    y, made = rec.y, None
    if not vanes:
        outputs = list(Record.outputs)
        made = synthesise(
            y[:, outputs.index("Vt")],
            y[:, outputs.index("theta")],
            y[:, outputs.index("phi")],
            rec.ins,
        )
        y = y.copy()
        y[:, outputs.index("alpha")], y[:, outputs.index("beta")] = made.alpha, made.beta
    u0, y0 = rec.u[:TRIM_SAMPLES].mean(0), y[:TRIM_SAMPLES].mean(0)
    return Experiment(
        (rec.u - u0)[:, keep],
        y - y0,
        operating_point=y0,
        navigation=rec.ins if wind or not vanes else None,
        air_angles=made,
    )


def ours(exp: Experiment, dt: float, setup: Setup, settings: Settings = OURS):
    start = time.perf_counter()
    result = identify(
        exp,
        dt,
        input_names=setup.controls,
        output_names=Record.outputs,
        input_roles=setup.controls,
        output_roles=OUTPUT_ROLES,
        settings=settings,
    )
    seconds = time.perf_counter() - start
    found: dict[str, list[complex]] = {}
    spiral = None
    for mode in result.modes:
        if mode.name:
            found.setdefault(mode.name, []).append(complex(mode.eigenvalue))
        if mode.name == "spiral":
            spiral = mode
    return found, result, seconds, spiral


def on_controls(result, setup: Setup) -> StateSpace | None:
    """The identified model's discrete form with an input column per control of the aircraft,
    zero for one the method left out (a card without throttle: it has no identified effect);
    None when it left an axis's outputs out (nothing to validate it on)."""
    if tuple(result.output_names) != Record.outputs:
        return None
    columns = [setup.controls.index(c) for c in result.input_names]
    return _spread(result.discrete, columns, len(setup.controls))


def _spread(model: StateSpace, columns: list[int], r: int) -> StateSpace:
    """`model` with its input k as input columns[k] of r, the others without effect."""
    B, D = np.zeros((model.B.shape[0], r)), np.zeros((model.D.shape[0], r))
    B[:, columns], D[:, columns] = model.B, model.D
    return dataclasses.replace(model, B=B, D=D)


def followed(setup: Setup, rec: Record, played: Plan) -> list:
    """How each surface followed what `played` commanded, as the agent measures it on a
    finished run (agent.excitation.follow: its linkage and lag)."""
    timeline = render(played, COMMAND_HZ)
    measured = {c: rec.u[:, INPUT_CHANNELS.index(c)] for c in setup.controls}
    times = np.arange(len(rec.u)) * rec.dt
    # `fly` records from its margin (2 s) before the plan's first command.
    return following(timeline, 2.0, times, measured)


def _linkage(setup: Setup, rec: Record, played: Plan) -> dict:
    """Each surface's linkage (gain, even, knee) measured against what `played` commanded."""
    return {f.control: (f.gain, f.even, f.knee) for f in followed(setup, rec, played)}


def predictor_of(
    setup: Setup, result, rec: Record, exp: Experiment, played: Plan, others=(), earlier=()
):
    """The identified model as the agent's sizing sees it: its surfaces' linkage measured
    against what `played` commanded, its trim the record's, checked against `others` (the
    earlier calibration runs' records, as the agent's `Identifier.recent`) and `earlier`
    (their models, fitted records and what they flew: the linear range)."""
    linkage = _linkage(setup, rec, played)
    trim = dict(zip(Record.outputs, rec.y[:TRIM_SAMPLES].mean(0), strict=True))
    return sizing.predictor(
        result.document(),
        trim=trim,
        experiments=[(exp.u, exp.y)],
        channels=Channels(),
        surfaces=setup.surfaces,
        source="the previous run's model",
        linkage=linkage,
        others=others,
        fitted=result.fitted,
        earlier=earlier,
    )


def calibrate(setup: Setup, plan: Plan, settings: Settings = OURS):
    """The agent's amplitude build-up (module docstring): the sizing the seeds fly, the model
    that sized it (None: none could), each calibration run's (sizing, excursions), and with
    no model what the last run flew (the build-up grows from it). `settings`: the
    identification's of the calibration runs."""
    timeline = render(plan, CONFIG.rate_hz)
    sized = sizing.size(plan, timeline, None, CONFIG.sizing, setup.surfaces, setup.envelope)
    predictor, runs, flown, records, earlier = None, [], None, [], []
    for step in range(CALIBRATION_RUNS):
        rec = setup.fly(sized.plan, CALIBRATION_SEED + step)
        runs.append((sized, excursions(rec)))
        exp = experiment(rec, setup)
        try:
            _, result, _, _ = ours(exp, rec.dt, setup, settings)
        except (IdentificationFailed, DataError) as exc:
            print(f"  calibration run {step + 1} not identified: {exc}")
            break
        fastest = max(m.eigenvalue.real for m in result.modes)
        candidate = Candidate(
            model_id=f"calibration-{step + 1}",
            axes="full",
            record_dt=rec.dt,
            result=result.document(),
            experiments=((exp.u, exp.y),),
            record_s=len(exp.u) * rec.dt,
        )
        usable = (  # the agent's (agent.runtime.identification: `newest`)
            fastest < DIVERGENCE_LIMIT
            and result.fit.tic_avg < SIZING_TIC
            and has_its_modes(candidate)
        )
        predictor = (
            predictor_of(setup, result, rec, exp, sized.plan, others=records, earlier=earlier)
            if usable
            else None
        )
        records.append((exp.u, exp.y))
        document = result.document()
        linkage = _linkage(setup, rec, sized.plan)
        earlier.append(
            (
                document,
                result.fitted,
                sizing.deflections(document, [(exp.u, exp.y)], Channels(), setup.surfaces, linkage),
            )
        )
        flown = None
        if predictor is None:  # the build-up grows from what this run flew, as the agent's
            linkage = _linkage(setup, rec, sized.plan)
            document = result.document()
            flown = sizing.deflections(
                document, [(exp.u, exp.y)], Channels(), setup.surfaces, linkage
            )
        sized = sizing.size(
            plan, timeline, predictor, CONFIG.sizing, setup.surfaces, setup.envelope, flown=flown
        )
        if sized.refusals:  # the agent would not arm it: no further run to calibrate on
            break
        # Done when the plan is sized by a model of a run that a model sized itself (not the
        # build-up's small-amplitude run, whose model the sizing extrapolates furthest) and
        # no amplitude is held back by the build-up's growth limit: stopping on the growth
        # limit alone made the plan flown hinge on which limit bound first by a few tenths
        # of a degree after the build-up run.
        grown = f"{CONFIG.sizing.max_growth:g}× the"
        model_sized = not runs[-1][0].build_up
        if model_sized and not any(grown in why for why in sized.limited_by.values()):
            break
    return sized, predictor, runs, flown


def excursions(rec: Record) -> tuple[float, float, float]:
    """The largest bank (deg) and airspeed change (% of trim), and the lowest height above the
    ground (ft) of a flight."""
    v0 = rec.y[:TRIM_SAMPLES, 0].mean()
    bank = float(np.degrees(np.max(np.abs(rec.y[:, 7]))))
    speed = float(100 * np.max(np.abs(rec.y[:, 0] - v0)) / v0)
    lowest = float(np.min(rec.height) / M_PER_FT) if rec.height is not None else np.nan
    return bank, speed, lowest


# The validation records: each axis's doublets, judged on that axis's outputs. One record
# with every doublet would judge a linear model on what no linear model holds: the lateral
# doublets' sideslip drag and bank move V, α and θ by more than the elevator's doublet does
# (the validated truth itself scores TIC 0.25 there on the PA-28, 0.76 on V).
VALIDATION = {"longitudinal": (("elevator", 8.0),), "lateral": (("aileron", 6.0), ("rudder", 8.0))}
AXIS_OUTPUTS = {"longitudinal": (0, 1, 2, 3), "lateral": (4, 5, 6, 7)}


def doublets(axis: str, scale: float) -> Plan:
    """An axis's validation manoeuvre: its surfaces' doublets in turn (the presets' pulse
    widths, `scale` times their amplitudes), each followed by free flight."""
    segments = tuple(
        Segment(
            signals={c: Doublet(pulse_s=DOUBLET_PULSE_S[c], amplitude=scale * PRESET_AMPLITUDE[c])},
            free_s=free,
        )
        for c, free in VALIDATION[axis]
    )
    return Plan(id=f"{axis[:3]}-doublets", axes=axis, segments=segments)


def validation(
    setup: Setup, seed: int, model: StateSpace
) -> tuple[list[tuple[Experiment, tuple]], list[float]]:
    """Each axis's doublet record, flown from trim with its own seed (its own turbulence),
    and the outputs it is judged on, with the scale its doublets were flown at
    (`validation_scale`). Without sensor noise: a doublet at the presets' amplitude moves the
    airspeed and α of these aircraft by about their sensors' noise (0.1 m/s, 0.2°), so a noisy
    record would score the pitot and the vane, not the model (the validated truth scored TIC
    0.7 on the airspeed there)."""
    out, scales = [], []
    for k, axis in enumerate(VALIDATION):
        seeded = VALIDATION_SEED + 2 * seed + k
        rec = setup.fly(doublets(axis, 1.0), seeded, noise=False)
        exp = experiment(rec, setup, wind=False)
        quiet = setup.fly(_still(doublets(axis, 1.0)), QUIET_SEED + 2 * seed + k, noise=False)
        scale = validation_scale(
            model, exp, experiment(quiet, setup, wind=False), AXIS_OUTPUTS[axis]
        )
        if scale > 1.0:
            exp = experiment(setup.fly(doublets(axis, scale), seeded, noise=False), setup, False)
        scales.append(scale)
        out.append((Experiment(exp.u, exp.y), AXIS_OUTPUTS[axis]))
    return out, scales


def validation_scale(
    model: StateSpace, doublet: Experiment, quiet: Experiment, outputs: tuple[int, ...]
) -> float:
    """The doublets' scale on the presets' amplitudes: the smallest whose predicted response
    stands SNR_REQUIRED times above what the aircraft does with no input, capped at
    MAX_VALIDATION_SCALE (twice the presets' amplitude; beyond it these aircraft are no longer
    linear on a doublet).

    Chosen before it was run, from what is known in flight: the quiet record (as long as the
    validation record, trimmed flight with no input, its own turbulence seed) gives each
    output's RMS σ_w about its trim; the identified model driven by the 1× record's inputs
    gives each output's response RMS r. The ratio is the median over the axis's outputs of
    r / σ_w. A perfect linear model whose record carries an unmodelled response w uncorrelated
    with the doublet's s scores TIC = ‖w‖ / (‖s + w‖ + ‖s‖) ≈ σ_w / (2 σ_s), so a ratio of 3
    leaves the truth about 0.17, room under the 0.3 turbulence target for the model's own
    error. In calm air σ_w is the trim's own drift and the scale stays 1."""
    with np.errstate(all="ignore"):
        predicted = simulate(model, doublet.u, np.zeros(model.A.shape[0]))
    if not np.all(np.isfinite(predicted)):
        return 1.0
    cols = list(outputs)
    response = np.sqrt(np.mean(predicted[:, cols] ** 2, axis=0))
    still = np.sqrt(np.mean(quiet.y[:, cols] ** 2, axis=0))
    ratio = float(np.median(response / np.maximum(still, 1e-12)))
    return float(np.clip(SNR_REQUIRED / ratio, 1.0, MAX_VALIDATION_SCALE))


def _still(plan: Plan) -> Timeline:
    """`plan` rendered and then held at trim throughout: the quiet record's timeline."""
    timeline = render(plan, COMMAND_HZ)
    values = {c: np.zeros_like(v) for c, v in timeline.values.items()}
    return dataclasses.replace(timeline, values=values)


# A complex pair this damped (ζ) sits near its double root, where a pole moves much farther
# than ωn and ζ do: at ζ 0.9 a change of 0.01 in ζ moves the pole 2 % of ωn, at 0.997 13 %.
NEAR_DOUBLE = 0.9


def mode_errors(found: dict[str, list[complex]], truth: dict[str, list[complex]]) -> list[float]:
    """Each named mode's worst relative error (inf when it is not found): pole by pole, but a
    mode that is two real poles on either side (an overdamped short period) by its
    second-order polynomial's ωn and ζ, the handling-qualities parameters (MIL-STD-1797's
    ζ_sp and ω_sp), the larger of their relative errors. Near a double root the poles
    themselves are ill-conditioned: the J-3 Cub's −9.7 and −6.4 1/s (ωn 7.88, ζ 1.02) and an
    identified −7.5 ± 1.9j (ωn 7.73, ζ 0.97) are 34 % apart pole by pole though ωn and ζ are
    within 5 %. A pair near its double root (ζ of the reference's at least NEAR_DOUBLE) is
    ill-conditioned the same way and judged the same: a closed-loop model's short period
    against the open-loop one's on the J-3 Cub in light turbulence (ωn 7.70 and 7.92 rad/s, ζ
    0.912 and 0.997) is 34 % apart pole by pole, 2.8 % in ωn and 8.6 % in ζ
    (closed_loop_check.py). The validated truths' complex pairs are all below it (the
    C182's short period, ζ 0.786, the most damped)."""
    out = []
    for name in MODES:
        true, mine = truth.get(name, []), found.get(name, [])
        polynomial = _second_order(true), _second_order(mine)
        near_double = polynomial[0] is not None and polynomial[0][1] >= NEAR_DOUBLE
        if None not in polynomial and (len(true) == 2 or len(mine) == 2 or near_double):
            (wn, zeta), (wn_found, zeta_found) = polynomial
            out.append(max(abs(wn_found - wn) / wn, abs(zeta_found - zeta) / zeta))
            continue
        worst = 0.0
        for pole in true:
            near = min((abs(e - pole) for e in mine), default=np.inf)
            worst = max(worst, near / abs(pole))
        out.append(worst)
    return out


def mode_z(result, truth: dict[str, list[complex]]) -> dict[str, float]:
    """Each named mode's error over its reported standard error (the z-score), as the table
    judges it (`mode_errors`): "ωn" and "ζ" of a pair or of a mode of two real poles, the
    real part of a real pole (`mode_estimates`, against the truth's by the same names); the
    spiral has its own column. Over seeds, an rms near 1 says the reported σ are honest, far
    above 1 that they claim too much."""
    true = mode_estimates_of(truth)
    estimates = mode_estimates(result)
    return {k: (v - true[k]) / sigma for k, (v, sigma) in estimates.items() if k in true}


def mode_estimates(result) -> dict[str, tuple[float, float]]:
    """Each named mode's estimate with its reported standard error, as `mode_z` scores them:
    "ωn" and "ζ" of a pair or of a mode of two real poles, the real part of a real pole."""
    out: dict[str, tuple[float, float]] = {}
    orders = {o.name: o for o in result.second_order()}
    for name in MODES:
        mine = [m for m in result.modes if m.name == name]
        if not mine:
            continue
        if name in orders:
            o = orders[name]
            if o.frequency_std and o.damping_std:
                out[f"{name} ωn"] = (o.frequency, o.frequency_std)
                out[f"{name} ζ"] = (o.damping, o.damping_std)
            continue
        mode = mine[0]
        if mode.uncertainty is None:
            continue
        if mode.pair and mode.uncertainty.frequency > 0 and mode.uncertainty.damping > 0:
            out[f"{name} ωn"] = (mode.frequency, mode.uncertainty.frequency)
            out[f"{name} ζ"] = (mode.damping, mode.uncertainty.damping)
        elif not mode.pair and mode.uncertainty.real > 0:
            out[name] = (mode.eigenvalue.real, mode.uncertainty.real)
    return out


def mode_estimates_of(truth: dict[str, list[complex]]) -> dict[str, float]:
    """The truth's values under `mode_estimates`'s names: ωn and ζ of a pair or of two real
    poles, the real part of a single real pole."""
    out: dict[str, float] = {}
    for name in MODES:
        poles = truth.get(name, [])
        polynomial = _second_order(poles) if poles else None
        if polynomial is not None:
            out[f"{name} ωn"], out[f"{name} ζ"] = polynomial
        elif len(poles) == 1:
            out[name] = poles[0].real
    return out


def truth_bound(
    exp: Experiment, dt: float, setup: Setup, reference: Truth, settings: Settings = OURS
) -> tuple[float, list[float]]:
    """What an efficient estimator of the method's structure could do on this record were the
    validated truth the aircraft (`agent.ident.aircraft.bound`): the chance that every named
    mode comes out within 10 %, and each mode's median error, both by the table's measure
    (`mode_errors`) over BOUND_DRAWS draws of A from the bound's Gaussian about the truth.

    The truth enters as its eight aircraft states' block (the altitude and the engine's states
    are not the fit's), with the couplings the fit left out zeroed, so the modes are judged
    against that model's own; the throttle's gains are nuisance parameters (the fit's engine
    is not the truth's)."""
    inputs = tuple(setup.controls)
    fitted = fitted_axes(
        [exp],
        dt,
        inputs=inputs,
        outputs=Record.outputs,
        input_roles=inputs,
        output_roles=OUTPUT_ROLES,
        present=axes_present(inputs, OUTPUT_ROLES),
        settings=settings,
    )
    rows = [reference.states.index(o) for o in fitted.outputs]
    A = reference.A[np.ix_(rows, rows)]
    B = np.full((len(rows), len(fitted.inputs)), np.nan)
    for j, c in enumerate(fitted.inputs):
        if c != "throttle":
            B[:, j] = reference.B[rows, list(INPUTS).index(c)]
    covariance = bound(fitted, A, B)
    m = A.shape[0]
    structure = np.zeros((m, m), dtype=bool)
    width = fitted.sp.U.shape[1]
    for fit in fitted.fits:
        structure[np.ix_(fit.states, fit.states)] = True
        for j in fit.inputs:
            if j >= width:
                structure[list(fit.states), j - width] = True
    A = np.where(structure, A, 0.0)
    centre = named_by_truth(np.linalg.eigvals(A), reference.modes())
    values, vectors = np.linalg.eigh(covariance)
    root = vectors * np.sqrt(np.clip(values, 0.0, None))
    rng = np.random.default_rng(0)
    errors = []
    for _ in range(BOUND_DRAWS):
        drawn = A + (root @ rng.standard_normal(m * m)).reshape(m, m)
        errors.append(mode_errors(named_by_truth(np.linalg.eigvals(drawn), centre), centre))
    errors = np.array(errors)
    return float(np.mean(np.all(errors <= 0.10, axis=1))), list(np.median(errors, axis=0))


def _second_order(poles: list[complex]) -> tuple[float, float] | None:
    """ωn and ζ of a mode given as one complex pole (its pair's upper one) or two real ones;
    None for anything else."""
    if len(poles) == 1 and poles[0].imag > 0:
        pair = [poles[0], poles[0].conjugate()]
    elif len(poles) == 2 and all(abs(p.imag) < 1e-9 for p in poles):
        pair = list(poles)
    else:
        return None
    wn = float(np.sqrt(abs((pair[0] * pair[1]).real)))
    if wn <= 0:
        return None
    return wn, float(-(pair[0] + pair[1]).real / (2 * wn))


def named_by_truth(eigenvalues: np.ndarray, truth: dict[str, list[complex]]) -> dict:
    """A peer's modes named as the truth's nearest ones (peers name nothing themselves)."""
    pool = [complex(e) for e in eigenvalues if e.imag >= -1e-9]
    found: dict[str, list[complex]] = {}
    for name in MODES:
        for true in truth.get(name, []):
            if not pool:
                break
            j = int(np.argmin([abs(e - true) for e in pool]))
            found.setdefault(name, []).append(pool.pop(j))
    return found


def textbook(exp: Experiment, dt: float):
    start = time.perf_counter()
    result = identify(
        Experiment(exp.u, exp.y),
        dt,
        settings=Settings(
            method="time", markov=TEXTBOOK_P, order=PEER_ORDER, decimation=1, refine=False
        ),
    )
    return result.discrete, time.perf_counter() - start


def python_control(exp: Experiment, dt: float):
    import control

    start = time.perf_counter()
    H = control.markov(exp.y.T, exp.u.T, m=200, dt=True)
    sys_, _ = control.eigensys_realization(H, PEER_ORDER, dt=True)
    return StateSpace(sys_.A, sys_.B, sys_.C, sys_.D), time.perf_counter() - start


def sippy_n4sid(exp: Experiment, dt: float):
    import sippy_unipi

    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s = sippy_unipi.system_identification(
            exp.y.T, exp.u.T, "N4SID", SS_fixed_order=PEER_ORDER, SS_f=20, SS_p=20, tsample=dt
        )
    return StateSpace(s.A, s.B, s.C, s.D), time.perf_counter() - start


PEERS = {
    "textbook OKID/ERA": textbook,
    "python-control ERA": python_control,
    "SIPPY N4SID": sippy_n4sid,
}


def truth_tic(truth: Truth, records: list[tuple[Experiment, tuple]], setup: Setup, dt) -> float:
    """The validated truth's own validation TIC: the best a linear model can do there. Its
    inputs are the throttle's position (0–1; the record's µs / 1000) and the surfaces'; each
    sample acts over the interval it ends."""
    tics = []
    for exp, outputs in records:
        u = np.zeros((len(exp.u), len(INPUT_CHANNELS)))
        u[:, columns(setup)] = exp.u
        u[:, 0] /= 1000.0
        x = truth.simulate(np.vstack([u[1:], u[-1:]]), dt)[:, : exp.y.shape[1]]
        tics.append(np.mean(theil(exp.y, x)[list(outputs)]))
    return float(np.mean(tics))


def validation_tic(model: StateSpace, records: list[tuple[Experiment, tuple]]) -> float:
    """The mean over the validation records of the mean TIC over each one's axis outputs, the
    model simulated from the trim the records start in (x0 = 0, as the truth is). Estimating
    x0 instead lets a model's unobservable engine states take absurd values (−517 on the Cub)
    that bias its bank angle by 5°."""
    tics = []
    for exp, outputs in records:
        with np.errstate(all="ignore"):
            predicted = simulate(model, exp.u, np.zeros(model.A.shape[0]))
        if not np.all(np.isfinite(predicted)):
            tics.append(1.0)
            continue
        tics.append(np.mean(theil(exp.y, predicted)[list(outputs)]))
    return float(np.mean(tics))


# Terms of the whole-aircraft method that `--without` leaves out (docs/identification.md):
# the Settings field that holds each.
ABLATIONS = {
    "alpha-products": "alpha_products",
    "sideslip-drag": "sideslip_drag",
    "process-noise": "process_noise",
    "throttle-curve": "throttle_curve",
    "density": "density",
}


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.splitlines()[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--aircraft", nargs="*", choices=[*AIRCRAFT, *OFF_BENCHMARK], default=list(AIRCRAFT)
    )
    parser.add_argument(
        "--turbulence",
        type=float,
        nargs="*",
        default=[0.0, 1.0, 3.0],
        help="Dryden intensity: 1 light (W20 = 5 ft/s), 3 moderate (W20 = 15 ft/s)",
    )
    parser.add_argument("--excitation", nargs="*", choices=EXCITATIONS, default=EXCITATIONS)
    parser.add_argument("--nav", nargs="*", choices=NAVIGATION, default=NAVIGATION)
    parser.add_argument("--seeds", type=int, default=None, help=f"seeds from {FIRST_SEED}")
    parser.add_argument("--no-peers", action="store_true", help="suas-sysid alone")
    parser.add_argument("--no-validation", action="store_true", help="no validation records")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="3 seeds, no peers, no validation records: a row in about a minute",
    )
    parser.add_argument(
        "--sizing",
        choices=("auto", "nominal"),
        default="auto",
        help="auto: the agent's sizing (default); nominal: the plans' own amplitudes",
    )
    parser.add_argument(
        "--without",
        nargs="*",
        default=[],
        choices=sorted(ABLATIONS),
        help="leave out a term of the whole-aircraft method, to see what it does",
    )
    parser.add_argument(
        "--open-loop-prediction",
        action="store_true",
        help="refine the lateral axis by prediction error in open loop too, the calibration "
        "runs' included (the method does it for closed-loop records only): what it gains and "
        "costs (benchmarks/README.md)",
    )
    parser.add_argument(
        "--unwidened",
        action="store_true",
        help="the modes' standard errors as the sandwich gives them, without the widening for "
        "the few bins that carry a mode (agent.ident.refine.dof_factor): what it changes in "
        "the z-scores",
    )
    parser.add_argument(
        "--bound",
        action="store_true",
        help="with each row, the validated truth's Cramér–Rao bound on its records",
    )
    parser.add_argument(
        "--still",
        action="store_true",
        help="fly each excitation's length with no input: what the air alone does",
    )
    args = parser.parse_args()
    if args.unwidened:  # looked up at each call: every identification in this process
        refine.dof_factor = lambda g, spread: 1.0
    seeds = args.seeds if args.seeds is not None else 3 if args.quick else 10
    peers = not (args.no_peers or args.quick)
    validate = not (args.no_validation or args.quick)
    missing = [
        name
        for module, name in (("control", "python-control"), ("sippy_unipi", "SIPPY"))
        if peers and not importlib.util.find_spec(module)
    ]
    if missing:
        parser.error(
            f"{' and '.join(missing)} not installed: pip install -e '.[bench]' (make "
            "bench-jsbsim does), or --no-peers"
        )
    settings = dataclasses.replace(
        OURS,
        **{ABLATIONS[term]: False for term in args.without},
        closed_loop=args.open_loop_prediction,
    )
    print(
        "cells: median / worst over seeds; errors in %; ≤10 %: seeds with every named mode "
        "within 10 %; spiral: seeds with the truth within 3σ; TIC: validation record"
    )
    head = "  ".join(f"{m:>13}" for m in MODES)
    print(
        f"{'aircraft':8} {'turb':>4} {'exc.':4} {'nav':7} {'method':20} {head}  ≤10 %  spiral"
        f"  {'TIC':>11}   s/id"
    )
    for name in args.aircraft:
        for turbulence in args.turbulence:
            run(setup_for(name, turbulence), args, seeds, settings, peers, validate)


def setup_for(name: str, turbulence: float) -> Setup:
    """One benchmark aircraft (AIRCRAFT, or OFF_BENCHMARK) in `turbulence`, flown with every
    control it has (no throttle without an engine)."""
    flight = AIRCRAFT.get(name) or OFF_BENCHMARK[name]
    plant = Plant(
        name, airspeed_kts=flight.speed_kts, altitude_ft=flight.altitude_ft, linearise=False
    )
    controls = tuple(c for c in INPUT_CHANNELS if c != "throttle" or plant.kind != "none")
    return Setup(name, flight, turbulence, controls, plant.true_airspeed)


def sized_plans(
    setup: Setup, auto: bool = True, settings: Settings = OURS
) -> tuple[dict, dict, list]:
    """The benchmark's manoeuvres for `setup` (EXCITATIONS), sized as the agent sizes them
    when `auto` (the full preset by its calibration runs, identified with `settings`, the
    others by the model those runs identified): the plans, each one's envelope refusals, and
    the calibration runs."""
    full = preset("full", controls=setup.controls)
    plans = {
        "full": full,
        "card": only(card(setup.controls), setup.controls),
        "sweep": only(sweeps(), setup.controls),
    }
    refused: dict[str, tuple] = dict.fromkeys(plans, ())
    if not auto:
        return plans, refused, []
    sized, predictor, runs, flown = calibrate(setup, full, settings)
    plans["full"], refused["full"] = sized.plan, sized.refusals
    for other in ("card", "sweep"):
        card_sized = sizing.size(
            plans[other],
            render(plans[other], CONFIG.rate_hz),
            predictor,
            CONFIG.sizing,
            setup.surfaces,
            setup.envelope,
            flown=flown,
        )
        plans[other], refused[other] = card_sized.plan, card_sized.refusals
    return plans, refused, runs


def run(setup: Setup, args, seeds: int, settings: Settings, peers: bool, validate: bool):
    """Every row of one aircraft in one condition."""
    if args.still:
        still(setup, args.excitation, seeds)
        return
    reference = setup.truth()
    truth = reference.modes()
    # The calibration runs identified as the agent would (their model sizes the plans): with
    # the method's terms, whatever `--without` leaves out of the rows, but with the open-loop
    # prediction error when it is asked for, whose model sizes differently.
    calibration = dataclasses.replace(OURS, closed_loop=settings.closed_loop)
    plans, refused, runs = sized_plans(setup, auto=args.sizing == "auto", settings=calibration)
    for k, (step, (bank, speed, lowest)) in enumerate(runs):
        print(
            f"{setup.name:8} {setup.turbulence:4.1f} calibration run {k + 1}: "
            f"{_amplitudes(step)}; bank {bank:.0f}°, airspeed ±{speed:.1f} %, "
            f"lowest {lowest:.0f} ft",
            flush=True,
        )
    for excitation in args.excitation:
        plan = plans[excitation]
        if args.sizing == "auto" and refused[excitation]:  # the agent would not arm it
            print(
                f"{setup.name:8} {setup.turbulence:4.1f} {excitation:4} refused by the agent "
                f"at {_amplitudes(plan)}: {'; '.join(refused[excitation])}",
                flush=True,
            )
            continue
        rows: dict[tuple[str, str], list] = {}
        bounds: dict[str, list[tuple[float, list[float]]]] = {}
        flown = []
        for seed in range(FIRST_SEED, FIRST_SEED + seeds):
            rec = setup.fly(plan, seed)
            flown.append(excursions(rec))
            check = None
            for nav in args.nav:
                exp = experiment(rec, setup, wind=nav == "ins", vanes=nav != "novanes")
                try:
                    found, result, seconds, spiral = ours(exp, rec.dt, setup, settings)
                    model, errors = on_controls(result, setup), mode_errors(found, truth)
                except (IdentificationFailed, DataError):
                    model, errors, seconds, spiral = None, [np.inf] * len(MODES), np.nan, None
                if validate and check is None and model is not None:
                    check, _ = validation(setup, seed, model)
                    rows.setdefault(("–", "validated truth"), []).append(
                        (
                            [0.0] * len(MODES),
                            truth_tic(reference, check, setup, rec.dt),
                            np.nan,
                            None,
                            None,
                            None,
                        )
                    )
                tic = validation_tic(model, check) if check and model is not None else np.nan
                scores = mode_z(result, truth) if model is not None else {}
                estimates = mode_estimates(result) if model is not None else {}
                rows.setdefault((nav, "suas-sysid"), []).append(
                    (errors, tic, seconds, _spiral_z(spiral, truth), scores, estimates)
                )
                if args.bound:
                    bounds.setdefault(nav, []).append(
                        truth_bound(exp, rec.dt, setup, reference, settings)
                    )
            if not peers:
                continue
            exp = experiment(rec, setup, wind=False)
            moved = list(np.flatnonzero(np.ptp(exp.u, axis=0) > 0))  # sweeps leave the throttle
            for peer, method in PEERS.items():
                try:
                    model, seconds = method(Experiment(exp.u[:, moved], exp.y), rec.dt)
                    model = _spread(model, moved, exp.u.shape[1])
                    eig = np.log(np.linalg.eigvals(model.A).astype(complex)) / rec.dt
                    errs = mode_errors(named_by_truth(eig, truth), truth)
                    tic = validation_tic(model, check) if check else np.nan
                except (IdentificationFailed, DataError, np.linalg.LinAlgError, ValueError):
                    errs, tic, seconds = [np.inf] * len(MODES), 1.0, np.nan
                rows.setdefault(("–", peer), []).append((errs, tic, seconds, None, None, None))
        for (nav, method), results in rows.items():
            _print(setup, excitation, nav, method, results)
            if method == "suas-sysid":
                _print_scatter(excitation, nav, results, mode_estimates_of(truth))
            if method == "suas-sysid" and nav in bounds:
                _print_bound(excitation, nav, bounds[nav])
        bank, speed, lowest = (
            np.max([f[0] for f in flown]),
            np.max([f[1] for f in flown]),
            min(f[2] for f in flown),
        )
        print(
            f"{'':8} {'':4} {excitation:4} flown at {_amplitudes(plan)}: bank ≤ {bank:.0f}°, "
            f"airspeed within ±{speed:.1f} %, lowest {lowest:.0f} ft above the ground",
            flush=True,
        )


def still(setup: Setup, excitations, seeds: int) -> None:
    """Each excitation's length flown with no input, seed by seed: how far the air alone
    takes the aircraft (`--still`), against which the envelope's room is judged."""
    plans = {
        "full": preset("full", controls=setup.controls),
        "card": only(card(setup.controls), setup.controls),
        "sweep": only(sweeps(), setup.controls),
    }
    for excitation in excitations:
        quiet = _still(plans[excitation])
        for seed in range(FIRST_SEED, FIRST_SEED + seeds):
            rec = setup.fly(quiet, seed)
            bank, speed, lowest = excursions(rec)
            print(
                f"{setup.name:8} {setup.turbulence:4.1f} {excitation:4} still, seed {seed}: "
                f"{len(rec.y) * rec.dt:.0f} s, bank {bank:.1f}°, airspeed ±{speed:.1f} %, "
                f"lowest {lowest:.0f} ft",
                flush=True,
            )


def _amplitudes(item) -> str:
    """A plan's (or a sizing's) largest amplitude per control."""
    plan = item.plan if isinstance(item, sizing.Sizing) else item
    peak: dict[str, float] = {}
    for segment in plan.segments:
        for c, sig in segment.signals.items():
            peak[c] = max(peak.get(c, 0.0), abs(sig.amplitude))
    units = {"throttle": "%"}
    return ", ".join(f"{c} {a:.2g}{units.get(c, '°')}" for c, a in peak.items())


def _spiral_z(spiral, truth) -> float | None:
    """The identified spiral's offset from the truth's in its standard errors (inf when none
    was identified or it has no standard error; None when the truth has no spiral)."""
    if not truth.get("spiral"):
        return None
    if spiral is None or spiral.uncertainty is None or spiral.uncertainty.real <= 0:
        return np.inf
    true = truth["spiral"][0].real
    return float((spiral.eigenvalue.real - true) / spiral.uncertainty.real)


def _print(setup: Setup, excitation: str, nav: str, method: str, results: list) -> None:
    e = 100 * np.array([r[0] for r in results], dtype=float)
    cells = "  ".join(_pair(np.median(c), np.max(c)) for c in e.T)
    ok = int(np.sum(np.all(e <= 10, axis=1)))
    tics = np.array([r[1] for r in results], dtype=float)
    z = np.array([r[3] for r in results if r[3] is not None])
    spiral_cell = f"{int(np.sum(np.abs(z) <= 3)):2d}/{len(z):<2d}" if z.size else "  –  "
    times = [r[2] for r in results if np.isfinite(r[2])]
    seconds = f"{np.median(times):5.2f}" if times else "    –"
    tic = f"{np.median(tics):5.3f}/{np.max(tics):5.3f}" if np.all(np.isfinite(tics)) else "–"
    print(
        f"{setup.name:8} {setup.turbulence:4.1f} {excitation:4} {nav:7} {method:20} {cells}  "
        f"{ok:2d}/{len(e):<2d}  {spiral_cell}  {tic:>11}  {seconds}",
        flush=True,
    )
    scores: dict[str, list[float]] = {}
    for r in results:
        for k, v in (r[4] or {}).items():
            scores.setdefault(k, []).append(v)
    if scores:
        rms = ", ".join(f"{k} {np.sqrt(np.mean(np.square(v))):.1f}" for k, v in scores.items())
        print(f"{'':8} {'':4} {excitation:4} {nav:7} z-scores' rms (error / reported σ): {rms}")


def _print_scatter(excitation: str, nav: str, results: list, true: dict) -> None:
    """Each mode's z-scores split in two over the row's seeds: the scatter about the seeds' own
    mean over the reported σ (the rms with n − 1 degrees of freedom: near 1 when σ describes
    the scatter that the noise and the turbulence cause), and that mean's distance from the
    truth over the median σ (a bias every seed shares, which no standard error holds: the
    aircraft's nonlinearity at the flown amplitude, the model's structure, the truth's own
    error). The z against the truth is about the root of the sum of their squares."""
    values: dict[str, list[tuple[float, float]]] = {}
    for r in results:
        for k, v in (r[5] or {}).items():
            values.setdefault(k, []).append(v)
    scatter, bias = [], []
    for k, v in values.items():
        if len(v) < 3:
            continue
        x, sigma = np.array(v).T
        z = (x - x.mean()) / sigma
        scatter.append(f"{k} {np.sqrt(np.sum(z**2) / (len(z) - 1)):.1f}")
        if k in true:
            bias.append(f"{k} {(x.mean() - true[k]) / np.median(sigma):+.1f}")
    print(
        f"{'':8} {'':4} {excitation:4} {nav:7} scatter over σ (rms about the seeds' mean): "
        f"{', '.join(scatter) or '–'}; the mean's bias over σ: {', '.join(bias) or '–'}",
        flush=True,
    )


def _print_bound(excitation: str, nav: str, bounds: list[tuple[float, list[float]]]) -> None:
    """The truth's bound over a row's records (`truth_bound`): each mode's median error and
    the seeds an efficient estimator would have with every named mode within 10 %."""
    median = np.median([b[1] for b in bounds], axis=0)
    cells = ", ".join(f"{m} {100 * e:.1f}" for m, e in zip(MODES, median, strict=True))
    expected = sum(b[0] for b in bounds)
    print(
        f"{'':8} {'':4} {excitation:4} {nav:7} the truth's Cramér–Rao bound: median error (%) "
        f"{cells}; ≤10 % on {expected:.1f} of {len(bounds)} seeds at best",
        flush=True,
    )


def _pair(median: float, worst: float) -> str:
    def cell(x: float) -> str:
        return "miss" if not np.isfinite(x) else f"{x:.1f}" if x < 100 else f"{x:.0f}"

    return f"{cell(median):>6}/{cell(worst):<6}"


if __name__ == "__main__":
    main()
