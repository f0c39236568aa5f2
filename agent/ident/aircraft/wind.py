"""The wind, measured: the INS's velocity over the ground against the air data's airspeed, α
and β. Less the record's steady wind (`steady_wind`), the difference is the gust, taken as
its conditional mean given the two sensors' noise (`agent.ident.aircraft.noise`: where the
gust is weak, the short period's band on a light aircraft in light turbulence, that noise is
as large as the gust; in calm air the measured "gust", pure noise, leaves the fit), and the
known input of the model (`agent.ident.aircraft.prepare`)."""

from __future__ import annotations

import numpy as np

# The measured wind's components, the output they correct and the axis they act on.
GUSTS = (("airspeed", "longitudinal"), ("alpha", "longitudinal"), ("beta", "lateral"))
# The gusts whose rate is a known input too, through GUST_RATE_LAGS fitted lags, each gust's
# gradient along the airframe (MIL-F-8785C's Dryden model; JSBSim's): the pitch-rate gust
# q_g = s α_g / (1 + τs), τ = 4b/πV, and the yaw-rate gust r_g = s β_g / (1 + τs), τ = 3b/πV
# (sign and scale in the fitted gain). The yaw-rate gust matters where the span is large
# against the speed: left out, it biased the Dutch roll of JSBSim's glider (SGS 1-26 at
# 50 kt) in light turbulence (benchmarks/README.md). The rolling gust p_g, the vertical
# gust's gradient across the span, no single-point sensor measures.
GUST_RATES = ("alpha", "beta")
GUST_RATE_LAGS = 1


def body_from_ned(psi: np.ndarray, theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """(N, 3, 3): each sample's rotation from north, east, down into body axes (ZYX Euler
    angles, rad); its transpose turns body axes back."""
    cps, sps, cth, sth, cph, sph = (
        np.cos(psi),
        np.sin(psi),
        np.cos(theta),
        np.sin(theta),
        np.cos(phi),
        np.sin(phi),
    )
    rows = (
        (cth * cps, cth * sps, -sth),
        (sph * sth * cps - cph * sps, sph * sth * sps + cph * cps, sph * cth),
        (cph * sth * cps + sph * sps, cph * sth * sps - sph * cps, cph * cth),
    )
    return np.stack([np.stack(row, axis=-1) for row in rows], axis=-2)


def inertial_air_data(x: np.ndarray, navigation: np.ndarray) -> np.ndarray:
    """The airspeed, α and β the aircraft would have in still air: the INS's velocity over the
    ground (north, east, down) turned into body axes by the Euler angles. `x`: (N, 8) absolute
    states in KINEMATIC_STATES order (θ and φ used); `navigation`: (N, 4) ψ, v_N, v_E, v_D.
    Returns (N, 3): V (m/s), α, β (rad)."""
    rotation = body_from_ned(navigation[:, 0], x[:, 3], x[:, 7])
    u, v, w = np.einsum("nij,nj->ni", rotation, navigation[:, 1:]).T
    speed = np.sqrt(u * u + v * v + w * w)
    return np.column_stack([speed, np.arctan2(w, u), np.arcsin(v / np.maximum(speed, 1e-9))])


def steady_wind(x: np.ndarray, navigation: np.ndarray) -> np.ndarray:
    """The record's steady wind, north, east and down (m/s, (3,)): the mean over the record
    of v_g − Rᵀ v_air, the INS's velocity less the air data's (V, α, β) turned into north,
    east, down. `x` and `navigation` as for `inertial_air_data`.

    The gust the method measures is the wind's unsteady part: a steady wind W moves the
    aircraft with the air but its body-axis projection R W changes as the attitude does, so
    the still-air states computed from v_g would carry a "gust" of R W that follows the
    manoeuvre (an input collinear with the states, its rate unmodelled). Subtracted, the
    still-air states are those relative to the mean air mass. Only the mean: a wind that
    changes is a gust, which accelerates the aircraft and which the vanes measure; a trend
    over the record taken off too, the turbulence's slowest part with it, the glider's bank in
    light turbulence lost its explanation and the sizing held its inputs to a tenth of a
    degree (benchmarks/README.md)."""
    V, alpha, beta = x[:, 0], x[:, 1], x[:, 4]
    body = np.column_stack(
        [V * np.cos(alpha) * np.cos(beta), V * np.sin(beta), V * np.sin(alpha) * np.cos(beta)]
    )
    rotation = body_from_ned(navigation[:, 0], x[:, 3], x[:, 7])
    return np.mean(navigation[:, 1:] - np.einsum("nji,nj->ni", rotation, body), axis=0)
