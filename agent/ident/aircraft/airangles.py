"""α and β without vanes: synthesised from the INS's velocity over the ground, the attitude and
an estimated wind, for aircraft whose air data measures the airspeed only (most small ones;
the thesis's §7.2 proposes a derived α and β for them).

The air-relative velocity in body axes is v_b = R(ψ, θ, φ) (v_g − W), α = atan2(w_b, u_b),
β = asin(v_b / |v_b|). The wind W (north, east; no mean vertical wind) is steady plus a linear
drift over the record, W(t) = W₀ + W₁ s with s from −½ to ½, estimated with the mean sideslip
β₀ by weighted least squares from two facts that hold whatever the aircraft (the wind
triangle of wind estimation without vanes, e.g. Cho et al., "Wind estimation and airspeed
calibration using a UAV with a single-antenna GPS receiver and pitot tube", IEEE TAES 2011):

- |v_b| is the measured true airspeed V (the pitot's residual |v_b| − V);
- the sideslip scatters about a constant (sin β − sin β₀): a steady wind seen from another
  heading reads as a sideslip that follows the heading, which the aircraft does not fly.

Each residual is weighted by its own rms (two passes), with weak priors (W₀ within tens of
m/s, W₁ within 10 m/s, β₀ within 0.1 rad) that keep the problem posed on a straight record:
with one heading the cross-track wind and β₀ cannot be told apart, and then they need not be,
since a constant sideslip offset is the trim the identification removes; what it needs is how
the wind's projection changes as the attitude does, and that is what the turns determine.

What this cannot give: the gust's α and β parts (a gust is an unsteady wind, of the same
order as the manoeuvre's α and β), which are then unmeasured process noise, and a pitot's
scale error, taken as none (a wrong calibration biases the wind)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.optimize import least_squares

from agent.ident.aircraft.wind import inertial_air_data

# Prior scales (1 σ) that keep the fit posed without pulling a determined estimate: a mean
# wind of tens of m/s is possible for a small aircraft, a drift of 10 m/s over one record is
# a front passing, a mean sideslip of 0.1 rad is a very uncoordinated aircraft.
PRIOR_WIND = 30.0
PRIOR_DRIFT = 10.0
PRIOR_SIDESLIP = 0.1
# Floors of the residuals' weights: the pitot's and the sideslip's resolution, so a record
# that closes the triangle exactly (a noise-free simulation) keeps finite weights.
FLOOR_SPEED = 0.01
FLOOR_SIDESLIP = 1e-4


@dataclass(frozen=True, kw_only=True)
class Synthesised:
    """The synthesised α, β (rad) and the wind they came from."""

    alpha: np.ndarray
    beta: np.ndarray
    wind: tuple[float, float]
    """The mean wind the aircraft flies in, north and east (m/s, where the air goes)."""
    drift: tuple[float, float]
    """The wind's change from the record's start to its end, north and east (m/s)."""
    sideslip: float
    """The mean sideslip β₀ (rad)."""
    airspeed_rms: float
    """How well the wind triangle closes: rms of |v_b| − V (m/s). Gusts and a pitot's
    calibration error show here."""
    heading_span: float
    """The headings the record covered (rad): the steady wind across a record flown on one
    heading is not determined by it (module docstring)."""

    def note(self) -> str:
        """One line for the result: which α and β were used, and the wind."""
        north, east = self.wind
        speed = float(np.hypot(north, east))
        towards = float(np.degrees(np.arctan2(east, north)))
        change = float(np.hypot(*self.drift))
        span = float(np.degrees(self.heading_span))
        return (
            f"alpha and beta synthesised (no vanes) from the INS velocity, the attitude and an "
            f"estimated wind of {speed:.1f} m/s from {(towards + 180.0) % 360.0:.0f}° "
            f"(changing {change:.1f} m/s over the record, airspeed residual "
            f"{self.airspeed_rms:.2f} m/s rms, headings over {span:.0f}°); "
            "the gust's alpha and beta are not measured"
        )


def synthesise(
    speed: np.ndarray, theta: np.ndarray, phi: np.ndarray, navigation: np.ndarray
) -> Synthesised:
    """α and β from the INS and the airspeed (module docstring). `speed`: true airspeed (m/s);
    `theta`, `phi` (rad); `navigation`: (N, 4) ψ (rad), v_N, v_E, v_D (m/s). ValueError when
    the arrays disagree in length or hold a non-finite value."""
    speed, theta, phi = (np.asarray(a, dtype=float).ravel() for a in (speed, theta, phi))
    navigation = np.asarray(navigation, dtype=float)
    n = speed.size
    if theta.size != n or phi.size != n or navigation.shape != (n, 4):
        raise ValueError("airspeed, theta, phi and the navigation need one row per sample")
    if n < 2 or not all(np.isfinite(a).all() for a in (speed, theta, phi, navigation)):
        raise ValueError("synthesising alpha and beta needs finite airspeed, attitude and INS")
    s = np.linspace(-0.5, 0.5, n)
    x = np.zeros((n, 8))
    x[:, 3], x[:, 7] = theta, phi

    def body(params: np.ndarray) -> np.ndarray:
        wn = params[0] + params[2] * s
        we = params[1] + params[3] * s
        nav = navigation.copy()
        nav[:, 1] -= wn
        nav[:, 2] -= we
        return inertial_air_data(x, nav)

    def residuals(params: np.ndarray, weights: tuple[float, float]) -> np.ndarray:
        air = body(params)
        priors = params / np.array([PRIOR_WIND] * 2 + [PRIOR_DRIFT] * 2 + [PRIOR_SIDESLIP])
        return np.concatenate(
            [
                (air[:, 0] - speed) / weights[0],
                (np.sin(air[:, 2]) - params[4]) / weights[1],
                priors,
            ]
        )

    params = _start(speed, theta, navigation)
    weights = (1.0, 0.05)
    for _ in range(2):
        params = least_squares(residuals, params, args=(weights,), method="lm").x
        air = body(params)
        weights = (
            max(float(np.std(air[:, 0] - speed)), FLOOR_SPEED),
            max(float(np.std(np.sin(air[:, 2]))), FLOOR_SIDESLIP),
        )
    air = body(params)
    heading = np.unwrap(navigation[:, 0])
    return Synthesised(
        alpha=air[:, 1],
        beta=air[:, 2],
        wind=(float(params[0]), float(params[1])),
        drift=(float(params[2]), float(params[3])),
        sideslip=float(np.arcsin(np.clip(params[4], -1.0, 1.0))),
        airspeed_rms=float(np.sqrt(np.mean((air[:, 0] - speed) ** 2))),
        heading_span=float(np.ptp(heading)),
    )


def _start(speed: np.ndarray, theta: np.ndarray, navigation: np.ndarray) -> np.ndarray:
    """The wind triangle with the air along the heading: the mean of v_g − V (cos ψ, sin ψ)."""
    psi, vn, ve = navigation[:, 0], navigation[:, 1], navigation[:, 2]
    horizontal = speed * np.cos(theta)
    return np.array(
        [
            float(np.mean(vn - horizontal * np.cos(psi))),
            float(np.mean(ve - horizontal * np.sin(psi))),
            0.0,
            0.0,
            0.0,
        ]
    )


@dataclass(frozen=True, kw_only=True)
class Sources:
    """Which columns α and β come from or are synthesised from, and which to use: "auto"
    (the vanes' where the record has them, else synthesised), "vanes" or "synthesised"."""

    mode: Literal["auto", "vanes", "synthesised"] = "auto"
    airspeed: str = "Vt"
    alpha: str = "alpha"
    beta: str = "beta"
    theta: str = "theta"
    phi: str = "phi"
    navigation: tuple[str, ...] = ("psi", "vn", "ve", "vd")

    @classmethod
    def of(cls, channels, mode: str) -> Sources:
        """The sources named by a config's `[identification.channels]` (agent.config.Channels)."""
        return cls(
            mode=mode,
            airspeed=channels.airspeed,
            alpha=channels.alpha,
            beta=channels.beta,
            theta=channels.theta,
            phi=channels.phi,
            navigation=channels.navigation(),
        )

    @property
    def needed(self) -> tuple[str, ...]:
        """The columns a synthesis reads."""
        return (self.airspeed, self.theta, self.phi, *self.navigation)


def fill(
    columns: Mapping[str, np.ndarray], wanted: Iterable[str], sources: Sources
) -> tuple[dict[str, np.ndarray], Synthesised | None]:
    """`columns` with α and β synthesised where `wanted` names them and the record has no
    vanes' (a column missing, or without one finite value), or always with mode
    "synthesised"; and how (None: the vanes' kept). They are synthesised on the rows where
    every column they need is finite (NaN elsewhere: an onboard window's edges and dropouts,
    which the window's own code cuts or bridges). ValueError, saying what is missing, when
    they are wanted but can be neither read nor synthesised."""
    out = dict(columns)
    angles = [n for n in (sources.alpha, sources.beta) if n in set(wanted)]
    if not angles or sources.mode == "vanes":
        return out, None
    vaneless = [n for n in angles if n not in out or not np.isfinite(out[n]).any()]
    if sources.mode == "auto" and not vaneless:
        return out, None
    lacking = [n for n in sources.needed if n not in out or not np.isfinite(out[n]).any()]
    rows = np.ones(0, bool)
    if not lacking:
        rows = np.logical_and.reduce([np.isfinite(out[n]) for n in sources.needed])
    if lacking or rows.sum() < 2:
        have = "has no " + ", ".join(vaneless) if vaneless else "is to use none"
        raise ValueError(
            f"the record {have} and alpha and beta cannot be synthesised without vanes: that "
            f"needs the airspeed, the attitude and the INS's heading and velocities "
            f"({', '.join(sources.needed)}); "
            + (f"missing: {', '.join(lacking)}" if lacking else "no row has them all")
        )
    navigation = np.column_stack([out[n][rows] for n in sources.navigation])
    made = synthesise(
        out[sources.airspeed][rows], out[sources.theta][rows], out[sources.phi][rows], navigation
    )
    for name, values in ((sources.alpha, made.alpha), (sources.beta, made.beta)):
        column = np.full(rows.size, np.nan)
        column[rows] = values
        out[name] = column
    return out, made
