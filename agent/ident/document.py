"""An identification as one document: what `sysid identify --json` prints, what the worker hands
the agent, what the model store keeps and what the link's result message carries a part of.

Typed (pydantic), serialised once, read back by every consumer: no dict of string keys travels
between layers. The parts that belong to one method are optional: `okid` (Markov parameters,
Hankel singular values, the OKID/ERA model's own fit, the frequency-domain variant's spectra)
is None for the whole-aircraft method, `aircraft` (band, axes, coupling, engine lags, wind) is
None for OKID. `Identification.document` (agent.ident.result) builds one.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, model_validator

from agent.ident.convert import StateSpace
from agent.ident.modal import Mode

Matrix = list[list[float]]
Method = Literal["time", "frequency", "aircraft"]


class Document(BaseModel):
    """A part of the document: frozen, unknown keys refused, NaN and ∞ kept as JSON's
    NaN / Infinity (as Python's json module writes them) rather than silently null."""

    model_config = ConfigDict(frozen=True, extra="forbid", ser_json_inf_nan="constants")


class ModeDocument(Document):
    """One mode with its quality indicators and, after refinement, its Cramér–Rao 1-σ. Every
    number is finite: a mode has a continuous-time eigenvalue (a pole at z = 0 has none and is
    no mode, see agent.ident.modal), so NaN or ∞ here is a fault, refused where it is made."""

    model_config = Document.model_config | ConfigDict(allow_inf_nan=False)

    name: str | None
    eigenvalue: tuple[float, float]  # real, imaginary (1/s)
    frequency_rad_s: float
    damping: float
    time_constant_s: float | None
    msv: float | None
    mci: float | None
    moi: float | None
    emac: float | None
    mpc: float | None
    cmi: float | None
    eigenvalue_std: tuple[float, float] | None = None
    frequency_std_rad_s: float | None = None
    damping_std: float | None = None

    @classmethod
    def of(cls, mode: Mode) -> ModeDocument:
        """The document of an analysed mode."""
        u = mode.uncertainty
        return cls(
            name=mode.name,
            eigenvalue=(float(mode.eigenvalue.real), float(mode.eigenvalue.imag)),
            frequency_rad_s=float(mode.frequency),
            damping=float(mode.damping),
            time_constant_s=_num(mode.time_constant),
            msv=float(mode.msv),
            mci=float(mode.mci),
            moi=float(mode.moi),
            emac=_num(mode.emac),
            mpc=float(mode.mpc),
            cmi=_num(mode.cmi),
            eigenvalue_std=None if u is None else _pair(u.real, u.imag),
            frequency_std_rad_s=None if u is None else _finite(u.frequency),
            damping_std=None if u is None else _finite(u.damping),
        )

    @property
    def frequency_hz(self) -> float:
        return self.frequency_rad_s / (2 * np.pi)

    @property
    def real(self) -> float:
        return self.eigenvalue[0]

    @property
    def imag(self) -> float:
        return self.eigenvalue[1]

    @property
    def real_std(self) -> float | None:
        return None if self.eigenvalue_std is None else self.eigenvalue_std[0]

    @property
    def imag_std(self) -> float | None:
        return None if self.eigenvalue_std is None else self.eigenvalue_std[1]

    @property
    def pair(self) -> bool:
        """One of a complex pair (the document holds the one with positive imaginary part)."""
        return self.eigenvalue[1] != 0.0


class SecondOrderMode(Document):
    """A named mode made of two real poles as the one second-order mode it is
    (agent.ident.modal.second_order): its ωn and ζ, and their Cramér–Rao 1-σ."""

    model_config = Document.model_config | ConfigDict(allow_inf_nan=False)

    name: str
    frequency_rad_s: float
    damping: float
    frequency_std_rad_s: float | None = None  # Cramér–Rao 1-σ (null: no covariance)
    damping_std: float | None = None


class MissingMode(Document):
    """A mode the run's axes must have (agent.ident.naming.expected_modes) that no identified
    mode was named as, and why."""

    name: str
    reason: str


class MarkovTry(Document):
    """One Markov-parameter count tried by the automatic choice, and what it gave."""

    markov: int
    order: int
    tic_avg: float


class FrequencyDocument(Document):
    """The frequency-domain OKID's spectra (thesis §4.3.1)."""

    periodic: bool
    segment_s: float
    segments: int
    leakage: float | None
    markov_from: Literal["inverse FFT", "observer fit to the FRF"]


class OkidDocument(Document):
    """OKID/ERA's part: the Markov parameters, the Hankel singular values and the OKID/ERA
    model's own fit (before refinement)."""

    markov: int
    markov_auto: list[MarkovTry] | None  # None when p was given
    singular_values: list[float]
    tic_avg: float
    frequency: FrequencyDocument | None = None  # method "frequency"


class Gain(Document):
    """A fitted gain and its standard error."""

    gain: float
    std: float


class AirAngles(Document):
    """How one record's α and β were synthesised without vanes (agent.ident.aircraft.airangles):
    the wind estimated from the INS and the airspeed."""

    wind_mps: tuple[float, float]  # mean wind, north and east (where the air goes)
    drift_mps: tuple[float, float]  # its change over the record
    sideslip_rad: float  # the mean sideslip estimated with it
    airspeed_rms_mps: float  # how well the wind triangle closes
    heading_span_deg: float  # the headings the record covered


class Wind(Document):
    measured: bool  # the gusts were measured (INS velocities) and were known inputs
    gust_rms: dict[str, float]  # by the output each gust corrects
    # Gusts the INS measured no larger than the sensors' noise (calm air): not inputs; their
    # outputs are still the inertial ones.
    undetected: list[str] = []
    # "vanes": α and β as recorded; "synthesised": from the INS and an estimated wind (no
    # vanes), one entry per record in `synthesised`, and then only the airspeed's gust measured.
    air_angles: Literal["vanes", "synthesised"] = "vanes"
    synthesised: list[AirAngles] = []


class Coupling(Document):
    """What the other axis explains of one axis: the share of its weighted cost, and the change
    of its outputs as a share of their rms, with the other axis's controls or states added."""

    by_inputs: float
    by_states: float
    response_by_inputs: float
    response_by_states: float


class NoiseMisfit(Document):
    """An output's misfit power at the excited bins over what its axis's noise model leaves
    there (1: as the model claims), and that ratio's central band for the noise alone
    (agent.ident.aircraft.predictor.misfit_to_noise)."""

    ratio: float
    low: float
    high: float


class AxisDocument(Document):
    name: Literal["longitudinal", "lateral"]
    outputs: list[str]
    inputs: list[str]  # its controls, known inputs and coupling states
    iterations: int
    converged: bool
    # "filter error" where the record showed process noise (agent.ident.aircraft.process),
    # with each output's share of its residual power that the process noise explains;
    # "prediction error": refined in the time domain with coloured process noise
    # (agent.ident.aircraft.predictor), each noisy equation's noise pole (1/s) by its output.
    estimator: Literal["output error", "filter error", "prediction error"] = "output error"
    process_share: dict[str, float] = {}
    process_poles: dict[str, float] = {}
    # Each output's Theil inequality coefficient at the bins the fit used (the controls'
    # excited bins; agent.ident.aircraft.fit.excited_tic).
    tic_excited: dict[str, float] = {}
    # For a "prediction error" axis, each output's misfit against its noise model.
    noise_misfit: dict[str, NoiseMisfit] = {}


class Engine(Document):
    """How an input reaches the thrust: through `lags` equal first-order lags of
    `time_constant_s` (0: at once), the number chosen from the data (`criterion`: the Akaike
    criterion of each number tried, less the chosen one's), or a measured rpm or thrust, which
    acts at once."""

    input: str
    lags: int
    time_constant_s: float | None = None
    criterion: dict[int, float] = {}
    measured: bool = False


class AircraftDocument(Document):
    """The whole-aircraft method's part (agent.ident.aircraft)."""

    band_hz: tuple[float, float]
    bins: int
    kinematics: bool  # the kinematics were known (the trim was)
    wind: Wind
    model: str  # "lateral", "longitudinal", "decoupled", "decoupled, lateral coupled by …"
    axes: list[AxisDocument]
    coupling: dict[str, Coupling] = {}
    engine_lag_s: dict[str, dict[str, float]] = {}  # axis → input → the lags' time constant
    engine: list[Engine] = []  # each engine input: its lags as the data chose them
    sideslip_drag: Gain | None = None  # V̇'s gain on β²
    alpha_products: dict[str, dict[str, Gain]] = {}  # "alpha·beta" → output → gain
    # "throttle²" → output → gain: the throttle's square over its record's largest deviation,
    # in the throttle's units (agent.ident.aircraft.prepare).
    throttle_curve: dict[str, dict[str, Gain]] = {}
    # Per record whose trim climbed or descended through LEVEL_M or more, the INS's climb rate
    # over its trim (m/s, down negative) that the density's forcing of α̇ used
    # (agent.ident.aircraft.prepare); empty in level flight or without the INS.
    density_climb_mps: list[float] = []


class PreprocessingDocument(Document):
    record_dt: float
    decimation: int
    band_hz: float
    held_inputs_shifted: bool
    smoothing_s: float | None
    dropped_samples_per_end: int


class RefinementDocument(Document):
    criterion: Literal["output error", "prediction error (innovation form)"]
    hold: Literal["zoh", "foh"]
    iterations: int
    converged: bool
    noise_std: dict[str, float]
    Ac_std: Matrix | None  # None unless the model is in output coordinates
    Bc_std: Matrix | None


class StateSpaceDocument(Document):
    A: Matrix
    B: Matrix
    C: Matrix
    D: Matrix

    def model(self) -> StateSpace:
        return StateSpace(*(np.asarray(m, dtype=float) for m in (self.A, self.B, self.C, self.D)))


class ValidationDocument(Document):
    """The model on held-out records (`sysid identify --validate`): each output's TIC with each
    record's initial state and a bias on each output estimated, as a validation scores it,
    and from the record's trim (x(0) = 0, no bias) beside it."""

    files: list[str]
    tic: dict[str, float]
    tic_avg: float
    tic_from_trim: dict[str, float]
    tic_from_trim_avg: float


class ResultDocument(Document):
    """One identification. The discrete model (A, B, C, D at dt) and the contract's keys first,
    then the parts; `sysid identify --json` prints exactly this."""

    dt: float
    order: int
    inputs: list[str]
    outputs: list[str]
    A: Matrix
    B: Matrix
    C: Matrix
    D: Matrix
    Ac: Matrix | None  # the continuous model in output coordinates, when it exists
    Bc: Matrix | None
    stable: bool
    tic: dict[str, float]
    tic_avg: float
    modes: list[ModeDocument]
    method: Method
    coordinates: Literal["outputs", "era"]
    continuous: StateSpaceDocument | None
    trim: list[dict[str, float]] = []
    preprocessing: PreprocessingDocument
    refinement: RefinementDocument | None = None
    okid: OkidDocument | None = None
    aircraft: AircraftDocument | None = None
    warnings: list[str] = []
    missing_modes: list[MissingMode] = []
    """The modes the run's axes must have that were not identified, each with why."""
    poles_left_out: list[str] = []
    """The model's poles left out of the modes, each with why (a discrete pole at z ≈ 0, a
    pure sample delay, has no continuous-time eigenvalue)."""
    second_order: list[SecondOrderMode] = []
    """Each named mode of two real poles (an overdamped short period) as one mode: ωn, ζ."""
    tic_validation: dict[str, float] | None = None
    """Each output's TIC on the model's own records with each record's initial state and a
    bias on each output estimated (`agent.ident.fit.validation_fit`), as a validation scores
    it: a record that does not start trimmed is not held against the model (`tic` is from
    the trim). None where not computed (onboard)."""
    validation: ValidationDocument | None = None
    """The model on held-out records (`sysid identify --validate`); None: none given."""

    @model_validator(mode="before")
    @classmethod
    def _modes_without_eigenvalue(cls, data: Any) -> Any:
        """Read a document written before poles at z = 0 were left out of the modes: such a
        mode has no finite eigenvalue (NaN, ∞ or null) and is left out now, with a note; a
        standard error that is not finite is unknown (None)."""
        if not isinstance(data, dict) or not isinstance(data.get("modes"), list):
            return data
        modes, left_out = [], list(data.get("poles_left_out", []))
        for mode in data["modes"]:
            if not isinstance(mode, dict):
                modes.append(mode)
            elif _no_eigenvalue(mode.get("eigenvalue")):
                left_out.append(
                    "a mode with no finite eigenvalue (a discrete pole at z = 0, written before "
                    "such poles were left out): left out of the modes"
                )
            else:
                modes.append(_finite_stds(mode))
        return {**data, "modes": modes, "poles_left_out": left_out}

    @model_validator(mode="before")
    @classmethod
    def _earlier_layout(cls, data: Any) -> Any:
        """Read a document written before the method's parts were typed (a model store kept
        across an update): Markov parameters, singular values and the spectra were top-level
        keys, the OKID/ERA fit was the refinement's, and the aircraft method wrote p = 0."""
        if not isinstance(data, dict) or "markov" not in data:
            return data
        data = dict(data)
        markov, singular = data.pop("markov"), data.pop("singular_values", [])
        tried, spectra = data.pop("markov_auto", None), data.pop("frequency", None)
        refinement = data.get("refinement")
        if isinstance(refinement, dict):
            refinement = dict(refinement)
            okid_tic = refinement.pop("okid_tic_avg", data.get("tic_avg"))
            data["refinement"] = refinement
        else:
            okid_tic = data.get("tic_avg")
        if data.get("method") != "aircraft":
            data["okid"] = {
                "markov": markov,
                "markov_auto": tried,
                "singular_values": singular,
                "tic_avg": okid_tic,
                "frequency": spectra,
            }
        return data

    def model(self) -> StateSpace:
        """The discrete model (at dt)."""
        return StateSpace(*(np.asarray(m, dtype=float) for m in (self.A, self.B, self.C, self.D)))

    def mode(self, name: str) -> ModeDocument | None:
        """The mode of that name, if identified."""
        return next((m for m in self.modes if m.name == name), None)


def rows(matrix: np.ndarray) -> Matrix:
    return [[float(v) for v in row] for row in np.asarray(matrix)]


def _num(value: float | None) -> float | None:
    return None if value is None else float(value)


def _finite(value: float) -> float | None:
    """A standard error, None (unknown) when it is not finite (a singular covariance)."""
    return float(value) if np.isfinite(value) else None


def _pair(real: float, imag: float) -> tuple[float, float] | None:
    return (float(real), float(imag)) if np.isfinite(real) and np.isfinite(imag) else None


_STDS = ("eigenvalue_std", "frequency_std_rad_s", "damping_std")


def _no_eigenvalue(value: Any) -> bool:
    """Whether a mode's eigenvalue, as read, is a pair with a null, NaN or ∞ in it."""
    return (
        isinstance(value, list | tuple)
        and len(value) == 2
        and any(v is None or (isinstance(v, float) and not np.isfinite(v)) for v in value)
    )


def _all_finite(*values: Any) -> bool:
    """Every value given, flattened, is a finite number (a missing one or null is not)."""
    flat = [v for value in values for v in (value if isinstance(value, list | tuple) else [value])]
    return all(isinstance(v, int | float) and np.isfinite(v) for v in flat)


def _finite_stds(mode: dict) -> dict:
    """The mode's standard errors, those not finite as None (unknown)."""
    return {
        k: None if k in _STDS and v is not None and not _all_finite(v) else v
        for k, v in mode.items()
    }
