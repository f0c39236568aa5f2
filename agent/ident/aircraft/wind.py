"""The wind, measured: the INS's velocity over the ground against the air data's airspeed, α
and β. The difference is the gust, taken as its conditional mean given the two sensors'
noise, and the known input of the model (`agent.ident.aircraft.prepare`)."""

from __future__ import annotations

import numpy as np
import scipy.ndimage

# The measured wind's components, the output they correct and the axis they act on.
GUSTS = (("airspeed", "longitudinal"), ("alpha", "longitudinal"), ("beta", "lateral"))
# The gusts whose rate is a known input too, through GUST_RATE_LAGS fitted lags: Dryden's
# pitch-rate gust q_g = s α_g / (1 + τs), τ = 4b/πV (MIL-F-8785C; JSBSim's), the gust's
# gradient along the airframe. The yaw-rate gust from β_g changed nothing measurable on the
# benchmark aircraft, so it is left out.
GUST_RATES = ("alpha",)
GUST_RATE_LAGS = 1
# The measured gust's noise floor is its periodogram's mean above this fraction of the Nyquist
# frequency (no gust reaches there); its periodogram is smoothed over WIENER_BINS bins a side.
NOISE_FLOOR_FROM = 0.5
WIENER_BINS = 8


def measured_gust(g: np.ndarray) -> np.ndarray:
    """The gust's conditional mean given its noisy measurement g (samples): each frequency
    bin scaled by the Wiener gain max(0, 1 − N/P), P the smoothed periodogram and N the white
    noise floor (NOISE_FLOOR_FROM).

    Why: the measured gust is the INS's still-air α less the vane's, and it inherits both
    sensors' noise. Where the gust is weak — the short period's band on a light aircraft in
    light turbulence — that noise is as large as the gust, and a regressor with noise biases
    its own gain toward zero and the rest of the fit with it (errors in variables). Its
    conditional mean is a regressor whose error is uncorrelated with it, so linear gains
    fitted on it are consistent (regression calibration; Carroll, Ruppert, Stefanski &
    Crainiceanu, *Measurement Error in Nonlinear Models*, 2nd ed., 2006, ch. 4). In calm air
    the gain is zero almost everywhere and the measured "gust", pure noise, leaves the fit."""
    mean = float(g.mean())
    G = np.fft.rfft(g - mean)
    P = np.abs(G) ** 2
    smooth = scipy.ndimage.uniform_filter1d(P, 2 * WIENER_BINS + 1, mode="nearest")
    floor = float(np.mean(P[int(NOISE_FLOOR_FROM * P.size) :]))
    gain = np.clip(1.0 - floor / np.maximum(smooth, 1e-300), 0.0, 1.0)
    return np.fft.irfft(gain * G, n=g.size) + mean


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
