"""Candidate OKID/ERA models and the automatic choice of p and the order among them.

Each candidate is one OKID regression (time domain, or fitted to the frequency response)
with p Markov parameters, ERA at the given or suggested order, the modes the data support
(with the order automatic), and the open-loop simulation fit that ranks candidates.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from agent.ident import frequency, okid
from agent.ident.convert import StateSpace
from agent.ident.era import EraResult, default_blocks, era
from agent.ident.errors import DataError, IdentificationFailed
from agent.ident.fit import Fit, fit
from agent.ident.modal import HankelFactors, modal_analysis, modal_subspace
from agent.ident.naming import MIN_EMAC, MIN_MSV
from agent.ident.settings import Settings

# p values tried by the automatic choice: every small p, then a sparser grid (thesis table 6.6
# swept 1…20; the accuracy changes slowly at large p).
MARKOV_CANDIDATES = (1, 2, 3, 4, 5, 6, 8, 10, 12, 15, 20, 25, 30)
# Candidates within this fraction of the best simulation TIC count as equally good; the
# smallest of them is chosen.
PARSIMONY = 0.10
# The search over p stops after this many candidates in a row no better than the best so far
# (beyond the parsimony margin): larger p only adds noise modes.
STALL = 3
# With the order automatic, ERA's modes are kept only if the data support them: temporally
# consistent (EMAC ≥ naming.MIN_EMAC), a real share of the response (MSV ≥ naming.MIN_MSV),
# and no faster than BAND_MULTIPLE × the band of interest, since a mode far above every
# excited frequency shapes the response in band only through its static gain.
BAND_MULTIPLE = 5.0


@dataclass(frozen=True, kw_only=True)
class Candidate:
    """One OKID → ERA → fit run for a given p: what the automatic choice compares."""

    markov: int
    omp: okid.ObserverMarkov
    era: EraResult
    fit: Fit

    @property
    def tic_avg(self) -> float:
        return self.fit.tic_avg


@dataclass(frozen=True)
class MarkovChoice:
    """How p was chosen automatically: every candidate tried, and why the others lost."""

    chosen: int
    tried: tuple[tuple[int, int, float], ...]  # (p, order, TIC_avg)
    failed: tuple[tuple[int, str], ...]  # (p, reason)


def run_candidate(
    batch: Sequence[okid.Experiment],
    p: int,
    settings: Settings,
    dt: float = 1.0,
    band_hz: float | None = None,
    freq: frequency.FrequencyData | None = None,
) -> Candidate:
    """OKID with p Markov parameters, ERA at the given or suggested order, open-loop fit.

    With `freq` the observer Markov parameters come from the frequency response (or, for a
    broadband FRF, the system Markov parameters straight from its inverse FFT; p is then the
    number of them). With the order automatic and `band_hz` known, modes the data do not
    support are cut (modal truncation, see BAND_MULTIPLE).
    """
    r, m = batch[0].u.shape[1], batch[0].y.shape[1]
    blocks = settings.hankel_blocks or default_blocks(m, r, settings.order_max)
    broadband = freq is not None and freq.frf.broadband
    if broadband:
        markov = frequency.inverse_fft_markov(freq.frf, 2 * blocks + 2)
        omp = frequency.markov_observer(markov)
        structural = None
    else:
        if freq is not None:
            omp = frequency.observer_markov_from_frf(freq.frf, p, settings.estimate_d)
        else:
            omp = okid.observer_markov(
                batch, p, estimate_d=settings.estimate_d, regularization=settings.regularization
            )
        markov = okid.system_markov(omp, 2 * blocks + 2)
        structural = p * m if p > 1 else None
    # An ARX model with p lags has McMillan degree ≤ p·m, so its Markov sequence has no more.
    max_order = min(settings.order_max, blocks * m, blocks * r)
    if not broadband:
        max_order = min(max_order, p * m)
    realised = era(
        markov,
        settings.order,
        rows=blocks,
        cols=blocks,
        max_order=max_order,
        structural_rank=structural,
    )
    if settings.order is None and band_hz is not None:
        realised = supported_modes(realised, batch, dt, band_hz)
    model = StateSpace(realised.A, realised.B, realised.C, realised.D)
    return Candidate(markov=omp.markov, omp=omp, era=realised, fit=fit(model, batch))


def supported_modes(
    realised: EraResult, batch: Sequence[okid.Experiment], dt: float, band_hz: float
) -> EraResult:
    """The realisation cut to the modes the data support; IdentificationFailed if none is."""
    input_rms, output_rms = okid.channel_rms(batch)
    try:
        modes = modal_analysis(
            realised.A,
            realised.B,
            realised.C,
            dt,
            factors=HankelFactors(realised.observability, realised.controllability),
            input_scale=input_rms,
            output_scale=output_rms,
            balance=False,
        )
    except IdentificationFailed:
        return realised  # defective A: no modal decomposition to cut with
    limit = 2 * np.pi * BAND_MULTIPLE * band_hz
    # MSV is relative to the largest mode; noise modes can be the largest, so the share is
    # judged among the consistent, in-band modes only.
    plausible = [m for m in modes if (m.emac or 0.0) >= MIN_EMAC and m.frequency <= limit]
    top = max((m.msv for m in plausible), default=0.0)
    kept = [m for m in plausible if top > 0 and 100.0 * m.msv / top >= MIN_MSV]
    if not kept:
        raise IdentificationFailed(
            f"none of the {len(modes)} modes is consistent (EMAC ≥ {MIN_EMAC:.0f} %) and "
            f"below {limit:.1f} rad/s"
        )
    # Counted in states: a pair holds two, and a deadbeat pole (no mode) is cut with the rest.
    if sum(2 if m.pair else 1 for m in kept) == realised.order:
        return realised
    keep = [m.discrete for m in kept]
    V, W = modal_subspace(realised.A, keep)
    return replace(
        realised,
        A=W @ realised.A @ V,
        B=W @ realised.B,
        C=realised.C @ V,
        order=V.shape[1],
        observability=realised.observability @ V,
        controllability=W @ realised.controllability,
    )


def _grouped(failed: Sequence[tuple[int, str]]) -> str:
    """Each distinct reason once, with the p it stopped: "p = 1, 2, 3: <reason>; p = 5: …"."""
    by_reason: dict[str, list[int]] = {}
    for p, why in failed:
        by_reason.setdefault(why, []).append(p)
    return "; ".join(f"p = {', '.join(map(str, ps))}: {why}" for why, ps in by_reason.items())


def choose_markov(
    batch: Sequence[okid.Experiment],
    settings: Settings,
    dt: float = 1.0,
    band_hz: float | None = None,
    freq: frequency.FrequencyData | None = None,
) -> tuple[Candidate, MarkovChoice]:
    """Automatic p: the smallest model whose simulation TIC is within PARSIMONY of the best.

    Candidates are MARKOV_CANDIDATES up to what the record supports. The criterion is the
    open-loop simulation error (TIC_avg) of the identified model, not the one-step prediction
    error of the OKID regression: measured on the A.2 lateral record with realistic sensor
    noise, the BIC of the one-step predictor chose p = 6, where ERA then returns noise modes
    near the Nyquist frequency; the simulation criterion chooses p = 2 and the right modes.
    Among candidates within PARSIMONY of the best TIC the one with the fewest states (then
    the smallest p) wins.
    """
    _r, _m = batch[0].u.shape[1], batch[0].y.shape[1]
    if freq is not None:
        supported = min(settings.markov_max, frequency.max_markov(freq.frf, settings.estimate_d))
        if freq.frf.broadband:
            candidate = run_candidate(batch, 1, settings, dt, band_hz, freq)
            tried = ((candidate.markov, candidate.era.order, candidate.tic_avg),)
            return candidate, MarkovChoice(chosen=candidate.markov, tried=tried, failed=())
        if supported < 1:
            frequency.observer_markov_from_frf(freq.frf, 1, settings.estimate_d)  # raises
    else:
        supported = okid.supported_markov(batch, settings.markov_max, settings.estimate_d)
    if supported < 1:
        okid.observer_markov(batch, 1, estimate_d=settings.estimate_d)  # raises with the reason
    ps = [p for p in MARKOV_CANDIDATES if p <= supported] or [supported]
    candidates, failed = [], []
    stalled = 0
    for p in ps:
        try:
            candidate = run_candidate(batch, p, settings, dt, band_hz, freq)
        except (IdentificationFailed, DataError) as exc:
            failed.append((p, str(exc)))
            stalled += 1 if candidates else 0
            if stalled >= STALL:
                break
            continue
        best = min((c.tic_avg for c in candidates), default=np.inf)
        stalled = stalled + 1 if candidate.tic_avg > best * (1 + PARSIMONY) else 0
        candidates.append(candidate)
        if stalled >= STALL:
            break
    if not candidates:
        raise IdentificationFailed(
            f"no number of Markov parameters gave a model ({_grouped(failed)})"
        )
    best = min(c.tic_avg for c in candidates)
    good = [c for c in candidates if c.tic_avg <= best * (1 + PARSIMONY) + 1e-12]
    chosen = min(good, key=lambda c: (c.era.order, c.markov))
    tried = tuple((c.markov, c.era.order, c.tic_avg) for c in candidates)
    return chosen, MarkovChoice(chosen=chosen.markov, tried=tried, failed=tuple(failed))
