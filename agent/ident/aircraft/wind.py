"""The wind, measured: the INS's velocity over the ground against the air data's airspeed, α
and β. The difference is the gust, taken as its conditional mean given the two sensors'
noise (`agent.ident.aircraft.noise`: where the gust is weak, the short period's band on a
light aircraft in light turbulence, that noise is as large as the gust; in calm air the
measured "gust", pure noise, leaves the fit), and the known input of the model
(`agent.ident.aircraft.prepare`)."""

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


def inertial_air_data(x: np.ndarray, navigation: np.ndarray) -> np.ndarray:
    """The airspeed, α and β the aircraft would have in still air: the INS's velocity over the
    ground (north, east, down) turned into body axes by the Euler angles. `x`: (N, 8) absolute
    states in KINEMATIC_STATES order (θ and φ used); `navigation`: (N, 4) ψ, v_N, v_E, v_D.
    Returns (N, 3): V (m/s), α, β (rad)."""
    theta, phi = x[:, 3], x[:, 7]
    psi, vn, ve, vd = navigation.T
    cps, sps, cth, sth, cph, sph = (
        np.cos(psi),
        np.sin(psi),
        np.cos(theta),
        np.sin(theta),
        np.cos(phi),
        np.sin(phi),
    )
    u = cth * cps * vn + cth * sps * ve - sth * vd
    v = (sph * sth * cps - cph * sps) * vn + (sph * sth * sps + cph * cps) * ve + sph * cth * vd
    w = (cph * sth * cps + sph * sps) * vn + (cph * sth * sps - sph * cps) * ve + cph * cth * vd
    speed = np.sqrt(u * u + v * v + w * w)
    return np.column_stack([speed, np.arctan2(w, u), np.arcsin(v / np.maximum(speed, 1e-9))])
