"""Whether an aircraft is linear between two amplitudes, from its own records: another
record's model priced on this record by this record's own fit criterion.

A linear model identified at a large amplitude is the aircraft's best linear approximation
there; where the aircraft is not linear over the span, that model explains a record flown at
a smaller amplitude worse than the smaller record's own model does, beyond what the
estimation explains. The test runs in the data, where the fit itself runs: each axis of the
smaller record's fit (`Fitted`) is evaluated at the larger record's dynamics (its A), the
rest refitted (the transients, the engine's lags and every gain of a control or known input:
`bound.nuisance`), and its weighted cost compared with the cost at the record's own
dynamics, refitted the same way. A mode poorly determined by the small record cannot pass
for a nonlinearity here, as it could when the two models' modes were compared against their
standard errors: a record that does not determine a mode does not care where the other model
puts it (benchmarks/README.md, *Off the benchmark: the PC-7*). The direction matters for the
same reason: the larger record's model on the smaller record, never the reverse.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from agent.ident.aircraft.bound import _at_model, nuisance
from agent.ident.aircraft.fit import weighted_cost
from agent.ident.aircraft.model import Fitted


def assembled(fitted: Fitted) -> np.ndarray:
    """The fits' A (m × m, the record's outputs), the other axis's states' gains among them."""
    m = len(fitted.outputs)
    width = fitted.sp.U.shape[1]
    A = np.zeros((m, m))
    for fit in fitted.fits:
        states = list(fit.states)
        A[np.ix_(states, states)] = fit.A
        for c, j in enumerate(fit.inputs):
            if j >= width:  # another axis's state: its gain is an entry of A
                A[states, j - width] = fit.B[:, c]
    return A


def costs(record: Fitted, model: Fitted) -> dict[str, tuple[float, float]]:
    """Axis → (the record's weighted cost at its own model's dynamics, at `model`'s), each
    with the rest refitted — the transients, the engine's lags and every gain of a control or
    known input (a gain that moves with the amplitude, a linkage's or an effectiveness's, is
    not what moves a mode) — and the record's own weights (its fit's σ per bin), for the axes
    both fitted from the same channels; empty where the records' channels differ."""
    if (record.inputs, record.outputs) != (model.inputs, model.outputs):
        return {}
    if record.sp.U.shape[1] != model.sp.U.shape[1]:  # different known inputs (wind, products)
        return {}
    theirs = {fit.name: fit for fit in model.fits}
    gains = np.full((len(record.outputs), record.sp.U.shape[1]), np.nan)  # all nuisance
    own, other = assembled(record), assembled(model)
    out = {}
    for fit in record.fits:
        if fit.name not in theirs or theirs[fit.name].states != fit.states:
            continue
        pair = []
        for A in (own, other):
            # A model whose dynamics are not numbers (a diverged fit) costs inf or NaN, said so.
            with np.errstate(all="ignore"):
                problem, theta, given = _at_model(record, fit, A, gains)
                theta = nuisance(problem, theta, ~given, fit.bin_std)
                pair.append(weighted_cost(problem, theta, fit.bin_std))
        out[fit.name] = (pair[0], pair[1])
    return out


def excess(record: Fitted, model: Fitted) -> Mapping[str, float]:
    """Axis → how much more of the record's weighted cost `model`'s dynamics leave than the
    record's own do, as a share of the latter (`costs`); not finite where it cannot be told
    (a model with no finite response costs inf, a cost that is not a number NaN, and NaN
    where the record's own cost is none to compare with)."""
    return {
        axis: (cross - own) / own if own > 0 else np.nan
        for axis, (own, cross) in costs(record, model).items()
    }
