"""Did each surface follow its command? The check a flight-test engineer makes on the first
manoeuvre of a flight, made on every finished excitation window (an aborted run's commands
may never have reached the servos).

A plan commands deflections in eq. 3.1's sign (docs/excitation.md, "Signs"); `direction` in
[excitation.surfaces] turns them into PWM, and the potentiometer box measures where the
surfaces went, in the same sign through its calibration. If either is set up the wrong way
round, the surface moves against its command. Identification cannot tell: the model's B
simply changes sign, its modes stay right, and its derivatives come out with the wrong sign.
So the measured surface is correlated with the command, at the servo's lag (up to MAX_LAG_S),
and a clearly negative or missing correlation is reported to the operator.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from agent.excitation.plan import Timeline

# The servo's transport delay and slew put the surface up to this long behind its command.
MAX_LAG_S = 0.3
# Below this correlation a surface did not follow its command; below its negative, it moved
# against it. A surface following a doublet through 0.1° of pot noise correlates above 0.9.
FOLLOWS = 0.5
# The linkage's knee (where its travel per degree changes) is searched at these quantiles of
# the commanded deflections, and kept away from trim only where it takes at least KNEE_SHARE
# off the residual of a knee at trim: a straight linkage's residual is the servo's lag and the
# pot's noise, which a knee does not explain (JSBSim's Cessna 310, its elevator 14° per unit
# one way of zero and 4° the other, zero 1.5° of command from trim: 20 % off).
KNEE_QUANTILES = np.linspace(0.05, 0.95, 19)
KNEE_SHARE = 0.05


@dataclass(frozen=True)
class Following:
    """How one control's measured position followed its command over a window."""

    control: str
    correlation: float
    """Correlation of measured with commanded at `lag_s` (the lag of the largest |r|)."""
    lag_s: float
    gain: float
    """Measured per commanded deflection at that lag (the servo's and linkage's gain)."""
    even: float = 0.0
    """Measured per |commanded − knee| deflection at that lag, fitted with the gain: the
    linkage's even part. Differential ailerons (more up than down) make the ganged aileron's
    mean move with the command's amplitude, |δA| acting as a bias that banks the aircraft (the
    sizing's prediction uses it, agent/sizing.py); an elevator with more travel up than down
    moves more per degree one way (the gains' design uses it, agent/tune.py)."""
    knee: float = 0.0
    """The commanded deflection where the travel per degree changes (0: at trim): the
    position moves gain·u + even·(|u − knee| − |knee|) from trim (`moved`)."""

    def moved(self, u):
        """The position's change from trim for commanded deflections `u` (the linkage fitted)."""
        return moved(u, self.gain, self.even, self.knee)

    @property
    def verdict(self) -> str:
        """One of: follows, reversed, not following."""
        if self.correlation >= FOLLOWS:
            return "follows"
        return "reversed" if self.correlation <= -FOLLOWS else "not following"

    def text(self) -> str:
        """One line for the operator; empty when the surface follows."""
        r = f"r = {self.correlation:+.2f}"
        if self.verdict == "reversed":
            return (
                f"{self.control} moved against its command ({r}): check its direction in "
                "[excitation.surfaces] and the sign of its potentiometer calibration"
            )
        if self.verdict == "not following":
            return (
                f"{self.control} did not follow its command ({r}): check its channel in "
                "[excitation.surfaces], its servo and its potentiometer"
            )
        return ""


def following(
    timeline: Timeline, start: float, times: np.ndarray, measured: Mapping[str, np.ndarray]
) -> list[Following]:
    """Each commanded control with a measured column: its command at `times` (the plan's
    sample then, trim outside the plan) against its measured positions there."""
    times = np.asarray(times, dtype=float)
    if times.size < 3:
        return []
    dt = float(np.median(np.diff(times)))
    if not dt > 0:
        return []
    index = np.floor((times - start) / timeline.dt).astype(int)
    inside = (index >= 0) & (index < timeline.count)
    result = []
    for control, values in timeline.values.items():
        column = measured.get(control)
        if column is None:
            continue
        commanded = np.where(inside, values[np.clip(index, 0, timeline.count - 1)], 0.0)
        best = _best_lag(commanded, np.asarray(column, dtype=float), round(MAX_LAG_S / dt))
        if best is not None:
            lag, r, _ = best
            gain, even, knee = linkage(commanded[: commanded.size - lag], column[lag:])
            result.append(Following(control, r, lag * dt, gain, even, knee))
    return result


def moved(u, gain: float, even: float, knee: float = 0.0):
    """A linkage's change from trim for commands `u` from trim: gain·u + even·(|u − knee| −
    |knee|), the travel per unit gain − even below the knee and gain + even above it (the
    same for a surface's commanded degrees here, the sizing's, and ArduPlane's notional
    degrees in agent.tune)."""
    u = np.asarray(u, dtype=float)
    return gain * u + even * (np.abs(u - knee) - abs(knee))


def linkage(u: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """(gain, even, knee): y = c + gain·u + even·|u − knee| by least squares over the finite
    pairs, the knee at trim (0) or at the quantile of the commands (KNEE_QUANTILES) that
    fits best where that takes KNEE_SHARE off the residual (`Following.moved`)."""
    u, y = np.asarray(u, dtype=float), np.asarray(y, dtype=float)
    ok = np.isfinite(u) & np.isfinite(y)
    a, b = u[ok], y[ok]

    def fit(knee: float) -> tuple[float, np.ndarray]:
        regressors = np.column_stack([np.ones(a.size), a, np.abs(a - knee)])
        coef, *_ = np.linalg.lstsq(regressors, b, rcond=None)
        return float(np.sum((regressors @ coef - b) ** 2)), coef

    at_trim, coef = fit(0.0)
    knee, best = 0.0, (1.0 - KNEE_SHARE) * at_trim
    moving = a[a != 0.0]
    # (A residual at rounding's level, a static map's without noise, holds no knee to find.)
    straight = at_trim <= 1e-12 * float(np.sum((b - b.mean()) ** 2))
    for k in np.quantile(moving, KNEE_QUANTILES) if moving.size and not straight else ():
        residual, c = fit(float(k))
        if residual < best:
            knee, coef, best = float(k), c, residual
    return float(coef[1]), float(coef[2]), knee


def _best_lag(u: np.ndarray, y: np.ndarray, lags: int) -> tuple[int, float, float] | None:
    """(lag, correlation, gain) of y against u delayed by 0…lags samples at the largest |r|;
    None when the command does not vary or either has gaps (NaN) throughout."""
    best = None
    for lag in range(min(lags, u.size - 3) + 1):
        a, b = u[: u.size - lag], y[lag:]
        ok = np.isfinite(a) & np.isfinite(b)
        if np.count_nonzero(ok) < 3:
            continue
        a, b = a[ok] - a[ok].mean(), b[ok] - b[ok].mean()
        su, sy = float(a @ a), float(b @ b)
        if su <= 0.0:
            continue  # nothing commanded to follow here
        r = float(a @ b) / np.sqrt(su * sy) if sy > 0.0 else 0.0  # a stuck surface: 0
        if best is None or abs(r) > abs(best[1]):
            best = (lag, r, float(a @ b) / su)
    return best
