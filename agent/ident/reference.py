"""The thesis's identified Super Cub models (appendix A.2, eq. A.2–A.4) and records made from them.

These are the known answers of the identification core and the source of the bundled example
flight records. Units as in the thesis: angles in rad, rates in rad/s, airspeed in m/s,
surfaces in degrees. The thesis does not give the throttle unit; its B column (≈1e−4 per
unit) fits PWM microseconds, so throttle is in µs here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agent.ident.convert import discretize


@dataclass(frozen=True, kw_only=True)
class ReferenceModel:
    """A continuous linear model in measured variables (C = I, D = 0) with its trim point."""

    name: str
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    A: np.ndarray
    B: np.ndarray
    trim_inputs: tuple[float, ...]
    trim_outputs: tuple[float, ...]


_DEG = np.pi / 180

LATERAL = ReferenceModel(
    name="A.2 lateral/directional (eq. A.2)",
    inputs=("aileron", "rudder"),
    outputs=("beta", "p", "r", "phi"),
    A=np.array(
        [
            [0.07918, -0.1425, -0.8387, -0.414],
            [4.81, -7.098, -3.568, -2.693],
            [3.444, 4.548, -1.98, -0.8893],
            [-0.04679, 0.9998, -0.03553, -0.02902],
        ]
    ),
    B=np.array([[-0.002815, 0.01296], [-0.666, -0.2216], [0.2464, -0.5871], [-0.01386, -0.005222]]),
    trim_inputs=(0.0, 0.0),
    trim_outputs=(-6.75 * _DEG, 2.2 * _DEG, -0.62 * _DEG, -0.59 * _DEG),
)

LONGITUDINAL = ReferenceModel(
    name="A.2 longitudinal (eq. A.3)",
    inputs=("throttle", "elevator"),
    outputs=("Vt", "alpha", "q", "theta"),
    A=np.array(
        [
            [-0.4541, -2.628, 1.806, -7.129],
            [-0.0851, -2.468, 1.788, 0.1256],
            [0.2701, -5.163, -7.527, 1.255],
            [0.0, -0.2657, 0.9126, 0.3046],
        ]
    ),
    B=np.array([[0.0, 0.02639], [0.0, 0.05085], [-0.0001826, -1.417], [0.0, -0.01782]]),
    trim_inputs=(1500.0, 0.0),
    trim_outputs=(17.96, 0.09 * _DEG, -0.74 * _DEG, 1.31 * _DEG),
)

FULL = ReferenceModel(
    name="A.2 full lateral and longitudinal (eq. A.4)",
    inputs=("throttle", "elevator", "aileron", "rudder"),
    outputs=("Vt", "alpha", "q", "theta", "beta", "p", "r", "phi"),
    A=np.array(
        [
            [0.35, 21.42, 1.213, -10.43, -13.85, 3.731, 3.668, 5.348],
            [-0.078, -1.892, 1.769, 0.092, 0.783, -0.672, 0.016, 0.549],
            [0.242, -16.74, -8.09, -0.506, -5.946, 1.921, 0.507, -2.755],
            [0.017, 0.601, 0.609, -0.282, -0.129, 0.413, -0.29, 0.401],
            [-0.013, 0.506, -0.068, -0.239, 0.376, 0.083, -1.16, -0.308],
            [-0.395, 0.157, 4.778, 2.027, 3.84, -7.848, -2.151, -5.991],
            [-0.197, -3.526, -4.581, -1.451, 14.5, 1.071, -3.975, 0.625],
            [0.0006, 0.051, 0.079, -0.214, -0.034, 1.131, 0.317, 0.182],
        ]
    ),
    B=np.array(
        [
            [0.0002, 19.83, -10.92, 2.486],
            [-1.068e-05, -1.827, 0.919, -0.4767],
            [2.956e-05, -6.455, 3.168, -1.71],
            [9.704e-06, -2.666, 1.631, -0.07735],
            [1.468e-05, 1.559, -0.4864, 1.037],
            [0.0001101, 23.23, -15, -0.1386],
            [5.53e-05, -11.29, 0.7215, -14.03],
            [8.609e-06, 0.5379, -0.5072, -0.4112],
        ]
    ),
    trim_inputs=(1500.0, 0.0, 0.0, 0.0),
    trim_outputs=(
        16.8,
        0.74 * _DEG,
        -2.77 * _DEG,
        -12.2 * _DEG,
        -9.9 * _DEG,
        6.16 * _DEG,
        -2.28 * _DEG,
        -1.07 * _DEG,
    ),
)

MODELS = {"lateral": LATERAL, "longitudinal": LONGITUDINAL, "full": FULL}

# Typical excitation amplitude per input: a few degrees of surface, ±100 µs of throttle.
AMPLITUDE = {"aileron": 3.0, "rudder": 3.0, "elevator": 2.0, "throttle": 100.0}


def multisine_inputs(
    inputs: tuple[str, ...], dt: float, duration: float, seed: int, band_hz: tuple[float, float]
) -> np.ndarray:
    """Rich, mutually orthogonal inputs: each input a sum of its own harmonics, random phases.

    The harmonics of the record length inside `band_hz` are dealt round-robin to the inputs,
    so no two inputs share a frequency (the thesis's orthogonal multisine idea, eq. 4.30).
    """
    rng = np.random.default_rng(seed)
    n = round(duration / dt)
    t = np.arange(n) * dt
    f0 = 1.0 / duration
    harmonics = np.arange(max(1, int(np.ceil(band_hz[0] / f0))), int(band_hz[1] / f0) + 1)
    u = np.zeros((n, len(inputs)))
    for j, name in enumerate(inputs):
        mine = harmonics[j :: len(inputs)]
        phases = rng.uniform(0, 2 * np.pi, mine.size)
        wave = np.cos(2 * np.pi * f0 * np.outer(t, mine) + phases).sum(axis=1)
        u[:, j] = AMPLITUDE.get(name, 1.0) * wave / np.max(np.abs(wave))
    return u


def simulate(
    model: ReferenceModel, u: np.ndarray, dt: float, x0: np.ndarray | None = None
) -> np.ndarray:
    """Outputs (perturbations) of the zero-order-hold discretised model for inputs u."""
    A, B = discretize(model.A, model.B, dt)
    x = np.zeros(A.shape[0]) if x0 is None else np.asarray(x0, dtype=float)
    y = np.empty((u.shape[0], A.shape[0]))
    for k in range(u.shape[0]):
        y[k] = x
        x = A @ x + B @ u[k]
    return y


# Shaped like convert.StateSpace only: the samples of a flight, not a model.
@dataclass(frozen=True, kw_only=True)
class Record:
    """A synthetic flight record: time, inputs and outputs in absolute (trim + deviation) units."""

    time: np.ndarray
    inputs: np.ndarray
    outputs: np.ndarray
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]

    def columns(self) -> dict[str, np.ndarray]:
        cols = {"time": self.time}
        cols.update({n: self.inputs[:, j] for j, n in enumerate(self.input_names)})
        cols.update({n: self.outputs[:, j] for j, n in enumerate(self.output_names)})
        return cols


def make_record(
    model: ReferenceModel,
    *,
    dt: float = 0.02,
    lead_in: float = 1.0,
    duration: float = 30.0,
    seed: int = 1,
    band_hz: tuple[float, float] = (0.05, 2.0),
    noise: dict[str, float] | None = None,
    inputs: np.ndarray | None = None,
) -> Record:
    """A trimmed lead-in of `lead_in` s, then `duration` s of excitation, with optional noise.

    `noise` maps channel names to white-noise standard deviations (channel units); the noise is
    added to the recorded values only, as a sensor would.
    """
    n_lead = round(lead_in / dt)
    u_exc = (
        multisine_inputs(model.inputs, dt, duration, seed, band_hz) if inputs is None else inputs
    )
    u = np.vstack([np.zeros((n_lead, len(model.inputs))), u_exc])
    y = simulate(model, u, dt)
    rng = np.random.default_rng(seed + 1000)
    u_rec = u + np.asarray(model.trim_inputs)
    y_rec = y + np.asarray(model.trim_outputs)
    for j, name in enumerate(model.inputs):
        u_rec[:, j] += rng.normal(0.0, (noise or {}).get(name, 0.0), u.shape[0])
    for j, name in enumerate(model.outputs):
        y_rec[:, j] += rng.normal(0.0, (noise or {}).get(name, 0.0), y.shape[0])
    return Record(
        time=np.arange(u.shape[0]) * dt,
        inputs=u_rec,
        outputs=y_rec,
        input_names=model.inputs,
        output_names=model.outputs,
    )


def thesis_multisine(
    model: ReferenceModel, dt: float = 0.02, duration: float = 30.0, period: float = 20.0
) -> np.ndarray:
    """The thesis's flown excitation: Schroeder multisines on the table 6.4 harmonics.

    Each surface plays its own four harmonics of a `period`-second base (aileron 3, 6, 9, 12;
    rudder 5, 10, 15, 20; elevator 7, 14, 21, 28) at its AMPLITUDE; throttle, which the
    thesis does not excite with a multisine, gets the harmonics 2, 4 (the flight
    plans step it instead: `signals.steps`).
    """
    from agent.excitation.signals import THESIS_HARMONICS, multisine

    columns = []
    for name in model.inputs:
        harmonics = THESIS_HARMONICS.get(name, (2, 4))
        columns.append(multisine(harmonics, period, dt, duration, AMPLITUDE.get(name, 1.0)))
    return np.column_stack(columns)


def with_output_noise(y: np.ndarray, fraction: float, seed: int) -> np.ndarray:
    """y plus white noise of `fraction` × each output's RMS (the benchmarks' noise convention)."""
    rng = np.random.default_rng(seed)
    scale = fraction * np.sqrt(np.mean(y**2, axis=0))
    return y + rng.normal(size=y.shape) * scale
