"""The nominal model store and the thesis's update suggestion (section 5.3, figure 5.2).

A candidate is an identified model with the data set it was identified from. The operator
accepts one as nominal (the previous nominal is kept, for revert), or rejects it. The store
is files (JSON + NumPy) in a directory, so the nominal model survives restarts.

Update suggestion, in the thesis's order; any NO suggests not updating:
1. the candidate is stable (a mode doubling in 10 s or more is tolerated, see
DIVERGENCE_LIMIT); 2. its quality indexes hold (every named mode's EMAC ≥ 50 %);
2b. (ours, not the thesis's) it has the modes its axes must have (agent.ident.naming.
expected_modes; a missing spiral is reported, not judged: see NOT_JUDGED_WHEN_MISSING) and no
pole beyond what the record can show (POLE_BAND_FACTOR); 3. TIC_jj (its own data) averages
below 0.3; 4.–7. with a nominal model: TIC_jN (candidate on the nominal's data) no worse than
TIC_NN (nominal on its own), and TIC_jj + TIC_jN below TIC_NN + TIC_Nj (nominal on the
candidate's data).
"""

from __future__ import annotations

import json
import logging
import os
import re
import secrets
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from agent.channels import AXIS_SETS
from agent.ident.document import AxisDocument, ModeDocument, ResultDocument, SecondOrderMode
from agent.ident.naming import expected_modes

log = logging.getLogger(__name__)

TIC_LIMIT = 0.3
# Step 1 accepts a slowly divergent mode: many airframes have a spiral that doubles in tens of
# seconds (JSBSim's J-3 Cub: +0.004 1/s). Faster divergence (time to double < 10 s) fails.
DIVERGENCE_LIMIT = np.log(2) / 10.0
EMAC_MIN = 50.0
# A mode without EMAC (the whole-aircraft method's: no ERA realisation to measure it in) is
# judged by its Cramér–Rao bound instead: weak when the natural frequency's standard error is
# more than this share of it (CIFER's guideline for an identified parameter, CR ≤ 20 %:
# Tischler & Remple, Aircraft and Rotorcraft System Identification, 2nd ed., 2012, ch. 11).
CR_MAX = 0.2
# Step 2b: a pole faster than this many times the top of the band the record excites
# (preprocessing.band_hz: where the inputs' power ends, or the whole-aircraft fit's top bin) is
# no aircraft mode the record determined. A first-order pole a decade above the highest
# excited frequency changes the response inside the band by under 0.5 % in magnitude and 6° in
# phase, less than a flight record's noise resolves, so the data do not place it: the fit may
# put it anywhere above (candidates.BAND_MULTIPLE cuts ERA's modes at 5 × the band for the
# same reason; this bound is the looser one). Nor can it lie beyond the Nyquist frequency of
# the samples the model was fitted to (π/dt): they show nothing faster.
POLE_BAND_FACTOR = 10.0
# A missing spiral is reported but does not fail step 2b, nor a weak one step 2: its time
# constant can be minutes (JSBSim's J-3 Cub: about 4 min; its SGS 1-26 glider: over 8 min) and
# is unbounded when the spiral stability is neutral, so no record is sure to be long enough to
# resolve it (see _resolved); the stability step still judges it.
NOT_JUDGED_WHEN_MISSING = ("spiral",)
# Step 3's repeat test (`repeats`): two records' estimates of a mode differ by at most this
# many of their combined standard errors (3: a difference that honest bounds put beyond
# 99.7 % by chance; bounds too small make the test refuse, never accept).
REPEAT_Z = 3.0
# Self-check (requirement 6.3.1): a new nominal predicting the next excitation this much worse
# (TIC_avg ratio) than the model it replaced is rolled back.
SELF_CHECK_RATIO = 1.5


@dataclass(kw_only=True)
class Candidate:
    """An identified model with the data set it was identified from."""

    model_id: str
    axes: str
    record_dt: float
    result: ResultDocument
    experiments: tuple[tuple[np.ndarray, np.ndarray], ...]
    tic_nn: float | None = None  # as nominal: its TIC on its own data
    record_s: float | None = None  # the newest record's length (None: unknown)
    trim: dict[str, dict[str, float]] | None = None  # its trim, "inputs"/"outputs" by channel
    # Its one record as the whole-aircraft method fitted it (agent.ident.job.Outcome.fitted):
    # the sizing's linear range (agent.sizing.linear_range). None: not kept or not that method.
    fitted: object | None = field(default=None, compare=False, repr=False)

    @property
    def tic_jj(self) -> float:
        return float(self.result.tic_avg)


@dataclass(frozen=True, kw_only=True)
class Suggestion:
    update: bool
    steps: list[str]
    """Each step's outcome as a line for the operator."""
    checks: dict[str, bool]
    """Each step's outcome for a program: "stability", "quality", "modes" (step 2b), "fit"
    (TIC_jj), and with a nominal model "no worse" (TIC_jN against TIC_NN) and "combined"
    (steps 6–7)."""
    tic_jj: float
    tic_jn: float | None = None
    tic_nn: float | None = None
    tic_nj: float | None = None


def _weak(mode: ModeDocument, one: SecondOrderMode | None = None) -> bool:
    """A mode poorly identified: its EMAC below EMAC_MIN, or, without EMAC, its natural
    frequency's Cramér–Rao standard error above CR_MAX of it (no error either: weak). A pole
    of a mode of two real poles is judged by the mode (`one`, its ωn and its standard error):
    near a double root each pole alone is ill-determined where the mode is not."""
    if mode.emac is not None:
        return mode.emac < EMAC_MIN
    sigma, omega = mode.frequency_std_rad_s, mode.frequency_rad_s
    if one is not None and one.frequency_std_rad_s is not None:
        sigma, omega = one.frequency_std_rad_s, one.frequency_rad_s
    return sigma is None or not omega or sigma / omega > CR_MAX


def _resolved(mode: ModeDocument, span: float) -> bool:
    """Whether a record `span` s long resolves the mode: its time constant within half of it."""
    return bool(abs(mode.eigenvalue[0]) * span / 2 >= 1.0)


def pole_limit(result: ResultDocument) -> tuple[float, str]:
    """The fastest pole (|s|, rad/s) an aircraft mode identified from this record can have
    (POLE_BAND_FACTOR), and what bounds it, in words."""
    band_hz, dt = result.preprocessing.band_hz, result.dt
    by_band, nyquist = POLE_BAND_FACTOR * 2 * np.pi * band_hz, np.pi / dt
    if by_band <= nyquist:
        return by_band, f"{POLE_BAND_FACTOR:g} × the excited band's top, {band_hz:.3g} Hz"
    return nyquist, f"the Nyquist frequency of samples {dt:g} s apart"


def _pole(mode: ModeDocument) -> str:
    re, im = mode.eigenvalue
    return (
        f"{re:.4g} 1/s" if im == 0 else f"{re:.4g} ± {im:.4g}j 1/s (ωn {mode.frequency_rad_s:.4g})"
    )


def has_its_modes(candidate: Candidate) -> bool:
    """Whether the candidate passes step 2b: every mode its axes must have is there (a spiral
    aside) and no pole is beyond its record (what sizes plans needs it: agent.runtime)."""
    span = np.inf if candidate.record_s is None else candidate.record_s
    return _modes_step(candidate, span)[0]


def _modes_step(candidate: Candidate, span: float) -> tuple[bool, str]:
    """Step 2b: the modes the axes must have are there, and no pole is beyond the record."""
    have, named, missing = _expected(candidate, span)
    within, beyond = _in_range(candidate.result)
    if have and within:
        return True, "; ".join([f"{named or 'none'} named", *missing, *beyond])
    return False, "; ".join(missing + ([] if within else beyond))  # what failed, and why


def _expected(candidate: Candidate, span: float) -> tuple[bool, str, list[str]]:
    """Whether no mode the axes must have is missing (a spiral aside), those named, and a part
    of the line per missing one: the result's reason, or why it is not judged."""
    result = candidate.result
    roles = AXIS_SETS[candidate.axes][1] if candidate.axes in AXIS_SETS else ()
    expected = expected_modes(roles)
    named = {m.name for m in result.modes if m.name}
    why = {m.name: m.reason for m in result.missing_modes}
    missing = [n for n in expected if n not in named]
    judged = [n for n in missing if n not in NOT_JUDGED_WHEN_MISSING]
    parts = []
    if judged:
        parts.append(
            "MISSING " + "; ".join(f"{n} ({why.get(n, 'no mode is named so')})" for n in judged)
        )
    record = f", beyond what a {span:.0f} s record resolves" if np.isfinite(span) else ""
    parts += [
        f"{n} missing, not judged: its time constant can be minutes (unbounded when its "
        f"stability is neutral){record}"
        for n in missing
        if n in NOT_JUDGED_WHEN_MISSING
    ]
    return not judged, ", ".join(n for n in expected if n in named), parts


def _in_range(result: ResultDocument) -> tuple[bool, list[str]]:
    """Whether every pole is within `pole_limit`, and a part of the line saying so or naming
    the poles beyond it (those left out at z ≈ 0 too)."""
    limit, bound = pole_limit(result)
    fast = [m for m in result.modes if m.frequency_rad_s > limit]
    delays = len(result.poles_left_out)
    if not fast and not delays:
        return True, [f"every pole within {limit:.0f} rad/s ({bound})"]
    parts = []
    if fast:
        parts.append(
            f"OUT OF RANGE: pole {', '.join(_pole(m) for m in fast)} faster than {limit:.0f} "
            f"rad/s ({bound}): not an aircraft mode this record determined"
        )
    if delays:
        parts.append(
            f"OUT OF RANGE: {delays} pole(s) at z ≈ 0, a pure sample delay or faster than the "
            "samples show, with no continuous-time eigenvalue: not an aircraft mode"
        )
    return False, parts


def excited_tic(result: ResultDocument) -> dict[str, float]:
    """The whole-aircraft fit's TIC at the bins its controls excited, each axis's mean over its
    outputs (agent.ident.aircraft.fit.excited_tic); empty for a model without it (OKID/ERA's)."""
    axes = result.aircraft.axes if result.aircraft else []
    return {a.name: float(np.mean(list(a.tic_excited.values()))) for a in axes if a.tic_excited}


def excited_fit(result: ResultDocument) -> list[tuple[str, bool, str]]:
    """Each axis's fit where its controls put their power: (axis, passed, what it says).
    An axis fitted by output or filter error passes when its outputs' mean TIC there is
    below TIC_LIMIT. An axis refined by prediction error models the disturbance it does not
    measure (agent.ident.aircraft.predictor), whose response lies in the excited bins too
    (a rolling gust moves p there whatever the model): it is judged output by output
    (`_against_noise`)."""
    axes = result.aircraft.axes if result.aircraft else []
    out = []
    for a in axes:
        if not a.tic_excited:
            continue
        mean = float(np.mean(list(a.tic_excited.values())))
        text = f"{mean:.3f} at the excited bins ({a.name}"
        if a.noise_misfit:
            out.append((a.name, *_against_noise(a, text)))
        elif mean < TIC_LIMIT:
            out.append((a.name, True, text + ")"))
        else:
            out.append((a.name, False, f"{text}) ≥ {TIC_LIMIT}"))
    return out


def _against_noise(axis: AxisDocument, head: str) -> tuple[bool, str]:
    """An axis refined by prediction error: each output passes when its excited-bin TIC is
    below TIC_LIMIT or its misfit power there is no more than its noise model leaves
    (`NoiseMisfit`'s band's top). More is a misfit the model does not explain; less is not
    judged, since a noise model that claims too much at those bins is no misfit of the
    input model (measured on the glider's light-turbulence flights: benchmarks/README.md,
    `make sim`). A ratio of nan fails."""
    parts, failing = [], []
    for name, m in axis.noise_misfit.items():
        tic = axis.tic_excited[name]
        if not m.ratio <= m.high and not tic < TIC_LIMIT:
            failing.append(
                f"{name} TIC {tic:.3f}, misfit {m.ratio:.2f} × its noise model's, "
                f"above {m.high:.2f}"
            )
        parts.append(f"{name} {m.ratio:.2f} ≤ {m.high:.2f}")
    if failing:
        return False, f"{axis.name} at the excited bins: {'; '.join(failing)}"
    return True, (
        f"{head}, prediction error: each output's TIC < {TIC_LIMIT} or its misfit as its "
        f"noise model leaves it: {', '.join(parts)})"
    )


def _fit_step(
    candidate: Candidate, tic_jj: float, determined: list[str], earlier: Candidate | None
) -> tuple[bool, str]:
    """Step 3: the model fits its own data, TIC_jj < TIC_LIMIT over the whole record (the
    thesis's rule); or, where the record holds a response it does not measure, the model
    fits where the excitation put its power and an independent record repeats it.

    In turbulence the record does not measure (a glider's rolling gust: the validated truth's
    own TIC reaches 0.41–0.48 on such records), the whole record's TIC counts the response to
    it, which no model of the inputs predicts, so that rule refuses every model, the truth
    included. The fit is then judged at the bins the controls excited, on every axis, as
    frequency-domain methods judge theirs (CIFER's cost over the fitted band: Tischler &
    Remple, *Aircraft and Rotorcraft System Identification*, 2nd ed., 2012, ch. 10), and an
    axis that models the disturbance against what its noise model leaves there
    (`excited_fit`). That alone does not tell a right model from one fitted to the gust
    (on a record the gust dominates, an excited-bin TIC near 0.2 with modes far off:
    tests/ident/test_aircraft.py), so the flight-test engineer's test follows: the
    manoeuvre flown again gives the same modes (`repeats`), with every mode determined
    (`determined`: the quality step passed) and a bounded simulation (a diverged one scores
    TIC 1). Where the INS found the air calm (`_calm`), the thesis's rule stands alone."""
    if tic_jj < TIC_LIMIT:
        return True, f"TIC_jj {tic_jj:.3f} < {TIC_LIMIT}"
    judged = excited_fit(candidate.result)
    head = f"TIC_jj {tic_jj:.3f} ≥ {TIC_LIMIT}"
    if not judged:
        return False, head
    calm = _calm(candidate.result)
    if calm:
        return False, (
            f"{head} in calm air (the INS measured no gust above its sensors' noise: "
            f"{', '.join(calm)}): the misfit is the model's, not the air's"
        )
    failed = [text for _, passed, text in judged if not passed]
    if failed:
        return False, f"{head} over the record, {'; '.join(failed)}"
    head += f" over the record, {'; '.join(text for *_, text in judged)}"
    if tic_jj >= 1.0:
        return False, f"{head}, but its simulation of the record diverged"
    if not determined:
        return False, f"{head}, but a mode is weak"
    if earlier is None:
        return False, f"{head}; no earlier record to repeat it (fly the manoeuvre again)"
    same, text = repeats(candidate, earlier, determined)
    if not same:
        return False, f"{head}; {text}"
    return True, (
        f"{head}; {text}: the rest is response to what the record does not "
        "measure (turbulence; a bias it causes would repeat too)"
    )


def _calm(result: ResultDocument) -> list[str]:
    """The gusts the INS looked for and found within its sensors' noise, where it found none
    above (calm air: agent.ident.aircraft.noise.detected); [] in turbulence, or where nothing
    measured the wind. In calm air the excited bins and a repeat cannot excuse a whole-record
    misfit as the air's: there is none (JSBSim's T-37 at 200 kt, calm, fitted at TIC_jj 0.34
    and was accepted that way, though no linear model reproduces its response there: even the
    truth's misses JSBSim's own doublets at TIC 0.55, docs/limitations.md)."""
    wind = result.aircraft.wind if result.aircraft else None
    if wind is None or wind.measured:
        return []
    return list(wind.undetected)


def repeats(candidate: Candidate, earlier: Candidate, names: Sequence[str]) -> tuple[bool, str]:
    """Whether `earlier` (another record's model) gives the modes `names` of `candidate` again,
    and no mode the candidate lacks (the spiral aside: NOT_JUDGED_WHEN_MISSING): each
    determined there too (`_weak`: a weak estimate repeats anything within its wide
    bounds), each pole's real and imaginary parts within REPEAT_Z combined standard errors
    (both models' Cramér–Rao bounds). Poles of one name pair by their real parts (a short
    period of two real poles)."""
    worst, where = 0.0, ""
    mine_named = {m.name for m in candidate.result.modes if m.name}
    lacking = [
        name
        for name in dict.fromkeys(m.name for m in earlier.result.modes if m.name)
        if name not in mine_named and name not in NOT_JUDGED_WHEN_MISSING
    ]
    if lacking:  # the manoeuvre flown again shows the same modes, not fewer
        return False, f"{earlier.model_id} has a {', '.join(lacking)} this record lacks"
    for name in names:
        mine, theirs = _poles(candidate.result, name), _poles(earlier.result, name)
        if not theirs:
            return False, f"{earlier.model_id} has no {name} to compare"
        if len(mine) != len(theirs):
            return False, f"{earlier.model_id}'s {name} has {len(theirs)} poles, this {len(mine)}"
        pair = {o.name: o for o in earlier.result.second_order}.get(name)
        if any(_weak(m, pair) for m in theirs):
            return False, f"{earlier.model_id}'s {name} is weak: nothing to repeat"
        for a, b in zip(mine, theirs, strict=True):
            if a.eigenvalue_std is None or b.eigenvalue_std is None:
                return False, f"{name} without a standard error to compare"
            for k in (0, 1):
                spread = np.hypot(a.eigenvalue_std[k], b.eigenvalue_std[k])
                gap = abs(a.eigenvalue[k] - b.eigenvalue[k])
                z = gap / spread if spread > 0 else (0.0 if gap == 0 else np.inf)
                if z > worst:
                    worst, where = z, name
    verdict = "≤" if worst <= REPEAT_Z else ">"
    text = f"{earlier.model_id}'s modes {'repeat' if worst <= REPEAT_Z else 'DIFFER'}"
    detail = f" (largest difference {worst:.1f} σ {verdict} {REPEAT_Z:g}, {where})" if where else ""
    return bool(worst <= REPEAT_Z), text + detail


def _poles(result: ResultDocument, name: str) -> list[ModeDocument]:
    """The poles named `name` in the upper half plane, by real part."""
    found = [m for m in result.modes if m.name == name and m.eigenvalue[1] >= 0]
    return sorted(found, key=lambda m: m.eigenvalue[0])


def suggest(
    candidate: Candidate,
    nominal: Candidate | None,
    tic_jn: float | None,
    tic_nj: float | None,
    uncompared: str = "",
    earlier: Candidate | None = None,
) -> Suggestion:
    """The figure 5.2 procedure; each step's outcome is a line for the operator. `uncompared`:
    why the candidate and the nominal could not be compared (their channels differ: a run
    that moved one axis only), and the candidate is then not suggested. `earlier`: the model
    of an earlier, independent record of the same axes, which step 3 compares this one with
    where turbulence the record does not measure fails the whole record's TIC (`_fit_step`)."""
    steps, ok = [], True
    # A mode slower than half the record (the Cub's spiral: τ ≈ 4 min) is not resolved by it:
    # reported, but it fails neither the stability step nor the quality step. Its sign is not
    # determined either: the simulated Cub's spiral (+0.004 1/s) came back at +0.04 and +0.09
    # 1/s from the two 15 s records of one lateral `sysid sim` flight.
    span = np.inf if candidate.record_s is None else candidate.record_s
    modes = candidate.result.modes
    judged = [m for m in modes if _resolved(m, span)]
    fastest = max((m.eigenvalue[0] for m in modes), default=-np.inf)
    judged_fastest = max((m.eigenvalue[0] for m in judged), default=-np.inf)
    stable = bool(judged_fastest < DIVERGENCE_LIMIT)
    state = (
        "stable"
        if candidate.result.stable
        else f"slowly divergent (doubles in {np.log(2) / fastest:.0f} s)"
        if fastest < DIVERGENCE_LIMIT
        else f"UNSTABLE (doubles in {np.log(2) / judged_fastest:.1f} s)"
        if not stable
        else f"divergent (doubles in {np.log(2) / fastest:.1f} s) in a mode slower than the "
        "record, not judged"
    )
    steps.append(f"1 stability: {state}")
    ok &= stable
    named = [m for m in modes if m.name]
    resolved = [m for m in named if _resolved(m, span)]
    slow = [m.name for m in named if m not in resolved]
    pairs = {o.name: o for o in candidate.result.second_order}
    weak = list(dict.fromkeys(m.name for m in resolved if _weak(m, pairs.get(m.name))))
    # A mode the step would not require when missing is not required when the record leaves
    # it undetermined either: reported, not judged (NOT_JUDGED_WHEN_MISSING).
    undetermined = [name for name in weak if name in NOT_JUDGED_WHEN_MISSING]
    weak = [name for name in weak if name not in undetermined]
    quality = bool(resolved) and not weak
    if quality:
        text = f"named modes EMAC ≥ {EMAC_MIN:.0f} % or Cramér–Rao σ(ωn) ≤ {CR_MAX:.0%}"
    else:
        text = (
            f"weak: {', '.join(weak)} (EMAC below {EMAC_MIN:.0f} %, or without EMAC "
            f"σ(ωn) above {CR_MAX:.0%} of ωn)"
            if weak
            else "no named mode resolved"
        )
    if undetermined:
        text += f"; {', '.join(undetermined)} not determined by the record, not judged"
    if slow:
        text += f"; {', '.join(slow)} slower than the record, not judged"
    steps.append("2 quality: " + text)
    ok &= quality
    have, text = _modes_step(candidate, span)
    steps.append("2b modes: " + text)
    ok &= have
    tic_jj = candidate.tic_jj
    determined = [m.name for m in resolved if m.name not in undetermined] if quality else []
    fits, text = _fit_step(candidate, tic_jj, list(dict.fromkeys(determined)), earlier)
    steps.append("3 " + text)
    ok &= fits
    checks = {
        "stability": stable,
        "quality": quality,
        "modes": have,
        "fit": fits,
    }
    if nominal is None:
        steps.append("4–7 no nominal model yet")
        return Suggestion(update=bool(ok), steps=steps, checks=checks, tic_jj=tic_jj)
    if uncompared:
        steps.append(f"4–7 not compared with nominal {nominal.model_id}: {uncompared}")
        checks |= {"no worse": False, "combined": False}
        return Suggestion(update=False, steps=steps, checks=checks, tic_jj=tic_jj)
    tic_nn = nominal.tic_nn if nominal.tic_nn is not None else nominal.tic_jj
    better = bool(tic_jn is not None and tic_jn <= tic_nn)
    steps.append(
        f"4–5 TIC_jN {tic_jn:.3f} vs TIC_NN {tic_nn:.3f}: {'no worse' if better else 'WORSE'}"
    )
    combined = bool(tic_jn is not None and tic_nj is not None and tic_jj + tic_jn < tic_nn + tic_nj)
    mine, theirs = tic_jj + (tic_jn or 0), tic_nn + (tic_nj or 0)
    verdict = "better" if combined else "NOT better"
    steps.append(f"6–7 TIC_jj + TIC_jN {mine:.3f} vs TIC_NN + TIC_Nj {theirs:.3f}: {verdict}")
    checks |= {"no worse": better, "combined": combined}
    return Suggestion(
        update=bool(ok and better and combined),
        steps=steps,
        checks=checks,
        tic_jj=tic_jj,
        tic_jn=tic_jn,
        tic_nn=tic_nn,
        tic_nj=tic_nj,
    )


# Random bytes naming a series of model numbers (see ModelStore.reserve_id).
SERIES_BYTES = 4
_SERIES_TEXT = re.compile(f"[0-9a-f]{{{2 * SERIES_BYTES}}}")

# Undecided candidates kept for a decision; older ones are dropped (a decision on one is refused
# as unknown: the result log still has it).
CANDIDATES_KEPT = 16


# A model store file's description is a few kB (its data set is beside it, in .npz).
SUMMARY_MAX_BYTES = 16 * 2**20


@dataclass(frozen=True, kw_only=True)
class StoredModel:
    """A model store file's id and modes (what a report highlights)."""

    model_id: str
    modes: list[ModeDocument]


def model_summary(path: Path) -> StoredModel:
    """A model store file's id and modes; ValueError naming the file when it is not one."""
    try:
        with open(path, "rb") as handle:  # bounded: /dev/zero or a stray log is no model
            text = handle.read(SUMMARY_MAX_BYTES + 1)
        if len(text) > SUMMARY_MAX_BYTES:
            raise ValueError(f"over {SUMMARY_MAX_BYTES // 2**20} MiB")
        stored = json.loads(text)
        result = ResultDocument.model_validate(stored["result"])
        return StoredModel(model_id=str(stored["model_id"]), modes=result.modes)
    except (OSError, ValueError, KeyError, TypeError, RecursionError) as exc:
        raise ValueError(f"{path}: not a model store file ({exc})") from None


def _read_numbering(path: Path) -> tuple[str, int]:
    """The numbering's series and last number; a new series from 0 when the file is missing
    or unreadable (logged)."""
    try:
        document = json.loads(path.read_text())
        series, last = document["series"], document["last"]
        if _SERIES_TEXT.fullmatch(str(series)) and type(last) is int and last >= 0:
            return series, last
        raise ValueError(f"not a numbering: {str(document)[:60]}")
    except FileNotFoundError:
        pass
    except (OSError, ValueError, KeyError, TypeError) as exc:
        log.error("%s is unreadable (%s); model ids go on in a new series", path, exc)
    return secrets.token_hex(SERIES_BYTES), 0


class ModelStore:
    """Nominal and previous nominal per identification type, on disk."""

    def __init__(self, directory: Path):
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.candidates: dict[str, Candidate] = {}
        self.damaged = 0
        self.unsaved_ids = 0  # ids given while the numbering could not be written
        self._ids: dict[str, str | None] = {}
        """Candidates awaiting the operator's decision, the latest CANDIDATES_KEPT (each
        holds its data set; a long flight must not grow without bound)."""

    def reserve_id(self, axes: str) -> str:
        """A new model id, `lat-7-3fa9c1d2`, never given twice on this aircraft, across boots
        too: a Decision names a model by its id, so an id from before a reboot (a queued or
        replayed decision) must never name another model. The number counts up in the file
        `numbering`, written (fsynced) before it is used; the tag after it names the
        numbering's series, drawn at random when the file is first made and again whenever
        it is missing or unreadable (deleted, damaged, a new card), so a numbering that
        starts over never repeats an id (two series alike: one draw in 2**32). The wall
        clock plays no part: a flight computer without a real-time clock boots in 1970."""
        path = self.directory / "numbering"
        series, last = _read_numbering(path)
        number = last + 1
        tmp = path.with_suffix(".tmp")
        try:
            with open(tmp, "w") as handle:
                handle.write(json.dumps({"series": series, "last": number}))
                handle.flush()
                os.fsync(handle.fileno())
            tmp.replace(path)
        except OSError as exc:  # a full or failing disk: an id of its own series, never again
            self.unsaved_ids += 1
            log.error("%s not written (%s): the model id takes a series of its own", path, exc)
            series = secrets.token_hex(SERIES_BYTES)
        return f"{axes[:3]}-{number}-{series}"

    def add(self, candidate: Candidate) -> None:
        self.candidates[candidate.model_id] = candidate
        while len(self.candidates) > CANDIDATES_KEPT:
            del self.candidates[next(iter(self.candidates))]

    def nominal(self, axes: str) -> Candidate | None:
        return self._load(axes, "nominal")

    def nominal_id(self, axes: str) -> str | None:
        """The nominal model's id, without loading its data (cached; for the status)."""
        if axes not in self._ids:
            meta, _ = self._paths(axes, "nominal")
            try:
                self._ids[axes] = json.loads(meta.read_text())["model_id"]
            except (OSError, ValueError, KeyError, TypeError):
                self._ids[axes] = None
        return self._ids[axes]

    def previous(self, axes: str) -> Candidate | None:
        return self._load(axes, "previous")

    def find(self, model_id: str) -> Candidate:
        """A model by its id: an undecided candidate, or a nominal or previous one (KeyError
        when none has it)."""
        if model_id in self.candidates:
            return self.candidates[model_id]
        for axes in AXIS_SETS:
            for slot in ("nominal", "previous"):
                found = self._load(axes, slot)
                if found is not None and found.model_id == model_id:
                    return found
        raise KeyError(f"no model {model_id} here (the latest candidates, nominal, previous)")

    def accept(self, model_id: str) -> Candidate:
        """Make a candidate nominal (the old nominal becomes previous)."""
        candidate = self.candidates.pop(model_id)
        current = self.nominal(candidate.axes)
        if current is not None:
            self._save(current, "previous")
        candidate.tic_nn = candidate.tic_jj
        self._save(candidate, "nominal")
        return candidate

    def reject(self, model_id: str) -> None:
        self.candidates.pop(model_id)

    def revert(self, axes: str) -> Candidate:
        """Previous nominal back to nominal (the reverted one becomes previous)."""
        previous, current = self.previous(axes), self.nominal(axes)
        if previous is None:
            raise LookupError(f"no previous {axes} nominal model to revert to")
        self._save(previous, "nominal")
        if current is not None:
            self._save(current, "previous")
        return previous

    def _paths(self, axes: str, slot: str) -> tuple[Path, Path]:
        base = self.directory / f"{axes}_{slot}"
        return base.with_suffix(".json"), base.with_suffix(".npz")

    def _save(self, c: Candidate, slot: str) -> None:
        if slot == "nominal":
            self._ids[c.axes] = c.model_id
        meta, data = self._paths(c.axes, slot)
        arrays = {f"u{k}": u for k, (u, _) in enumerate(c.experiments)}
        arrays |= {f"y{k}": y for k, (_, y) in enumerate(c.experiments)}
        np.savez(data.with_suffix(".tmp.npz"), **arrays)
        data.with_suffix(".tmp.npz").replace(data)
        tmp = meta.with_suffix(".tmp")
        tmp.write_text(
            json.dumps(
                {
                    "model_id": c.model_id,
                    "axes": c.axes,
                    "record_dt": c.record_dt,
                    "result": c.result.model_dump(mode="json"),
                    "tic_nn": c.tic_nn,
                    "count": len(c.experiments),
                    "record_s": c.record_s,
                    "trim": c.trim,
                }
            )
        )
        tmp.replace(meta)

    def _load(self, axes: str, slot: str) -> Candidate | None:
        meta, data = self._paths(axes, slot)
        if not meta.exists():
            return None
        try:
            m = json.loads(meta.read_text())
            with np.load(data) as arrays:
                experiments = tuple((arrays[f"u{k}"], arrays[f"y{k}"]) for k in range(m["count"]))
            earlier = m.get("extra", {})  # where a store written before kept the two
            return Candidate(
                model_id=m["model_id"],
                axes=m["axes"],
                record_dt=m["record_dt"],
                result=ResultDocument.model_validate(m["result"]),
                experiments=experiments,
                tic_nn=m["tic_nn"],
                record_s=m.get("record_s", earlier.get("record_s")),
                trim=m.get("trim", earlier.get("trim")),
            )
        except (OSError, ValueError, KeyError, TypeError, zipfile.BadZipFile) as exc:
            # A damaged store must not stop identification: set the files aside (kept for
            # the post-flight look), count it, and carry on as if there were no such model.
            self.damaged += 1
            self._ids.pop(axes, None)
            for path in (meta, data):
                if path.exists():
                    path.replace(path.with_name(path.name + ".damaged"))
            log.error("%s %s model unreadable (%s): set aside as *.damaged", axes, slot, exc)
            return None
