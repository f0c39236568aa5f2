"""The validated configuration tree: pydantic models of `config.toml`.

Every section is frozen and forbids unknown keys, so a typo is an error rather than a silently
ignored setting. Loaded once at start-up and passed down; there are no global settings.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Annotated, Literal

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    ValidationError,
    model_validator,
)

from agent.channels import AXIS_SETS, INPUT_ROLES, OUTPUT_ROLES


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, use_attribute_docstrings=True)


def _auto_or_count(value: object) -> object:
    if value == "auto" or (isinstance(value, int) and not isinstance(value, bool) and value >= 1):
        return value
    raise ValueError(f'must be "auto" or an integer ≥ 1, got {value!r}')


AutoOrCount = Annotated[int | Literal["auto"], BeforeValidator(_auto_or_count)]
Name = Annotated[str, Field(min_length=1, pattern=r"^[A-Za-z_][A-Za-z0-9_.\-]*$")]


class Channels(_Section):
    """Which recorded column or signal carries each channel role."""

    throttle: Name = "throttle"
    """Throttle command (µs of PWM in the thesis's models)."""
    elevator: Name = "elevator"
    """Elevator deflection δE, degrees, ganged as ½(δE_L + δE_R) (thesis eq. 3.1)."""
    aileron: Name = "aileron"
    """Aileron deflection δA, degrees, ganged as ½(δA_R − δA_L) (thesis eq. 3.1)."""
    rudder: Name = "rudder"
    """Rudder deflection δR, degrees."""
    airspeed: Name = "Vt"
    """True airspeed V_T, m/s."""
    alpha: Name = "alpha"
    """Angle of attack α, rad."""
    q: Name = "q"
    """Body pitch rate q, rad/s."""
    theta: Name = "theta"
    """Pitch attitude θ, rad."""
    beta: Name = "beta"
    """Sideslip angle β, rad."""
    p: Name = "p"
    """Body roll rate p, rad/s."""
    r: Name = "r"
    """Body yaw rate r, rad/s."""
    phi: Name = "phi"
    """Bank angle φ, rad."""

    @model_validator(mode="after")
    def _distinct(self) -> Channels:
        names = [getattr(self, role) for role in INPUT_ROLES + OUTPUT_ROLES]
        repeated = sorted({n for n in names if names.count(n) > 1})
        if repeated:
            raise ValueError(f"each channel needs its own name; repeated: {', '.join(repeated)}")
        return self

    def axis_set(self, axes: str) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """(input names, output names) of an axis set: lateral, longitudinal or full."""
        inputs, outputs = AXIS_SETS[axes]
        return tuple(getattr(self, r) for r in inputs), tuple(getattr(self, r) for r in outputs)

    def role_of(self, name: str) -> str | None:
        """The role a column name carries, or None."""
        for role in INPUT_ROLES + OUTPUT_ROLES:
            if getattr(self, role) == name:
                return role
        return None


class Identification(_Section):
    """How models are identified (OKID → ERA → modes → fit), onboard and offline."""

    axes: Literal["lateral", "longitudinal", "full"] = "lateral"
    """Default axis set: lateral (aileron, rudder → β, p, r, φ), longitudinal (throttle,
    elevator → V, α, q, θ) or full (all four → all eight)."""
    channels: Channels = Channels()
    """Names of the recorded channels for each role."""
    markov: AutoOrCount = "auto"
    """Markov parameters p of the OKID regression; "auto" picks p from 1…markov_max by the
    simulation fit of the identified model."""
    markov_max: int = Field(30, ge=1, le=200)
    """Largest p the automatic choice tries."""
    order: AutoOrCount = "auto"
    """Model order n; "auto" reads it from the gap in the Hankel singular values."""
    order_max: int = Field(20, ge=1, le=100)
    """Largest order the automatic choice accepts."""
    trim_seconds: float = Field(0.5, ge=0.0)
    """Trim is the mean of the first trim_seconds of each record (trimmed flight before the
    excitation), subtracted from inputs and outputs; 0 disables trim removal."""
    estimate_d: bool = False
    """Estimate the feed-through D; false forces D = 0, a strictly proper model (thesis §4.1.3)."""
    regularization: float = Field(0.0, ge=0.0, lt=1.0)
    """Tikhonov weight ρ of the OKID least squares, relative to the largest singular value
    of the normalised regression; 0 is plain least squares."""
    hankel_blocks: int | None = Field(None, ge=2, le=500)
    """Block rows (= columns) of the ERA Hankel matrix; unset: 20, more if order_max needs."""
    decimation: AutoOrCount = "auto"
    """Decimation factor after the anti-alias filter; "auto" brings the rate down to 25 × the
    band of interest; 1 keeps the record rate."""
    band_hz: float | None = Field(None, gt=0.0)
    """Band of interest in Hz; unset: where 99 % of every input's power lies (≥ 0.5 Hz)."""
    held_inputs: bool = True
    """Inputs are held between samples (commands; a zero-order hold). false: they are samples
    of continuously varying signals (e.g. surface potentiometers)."""
    smoothing_s: float | None = Field(None, gt=0.0)
    """Savitzky–Golay smoothing window in seconds (cubic), on inputs and outputs; unset: none."""
    method: Literal["time", "frequency"] = "time"
    """OKID from the time-domain regression, or from averaged spectra and the frequency
    response over whole excitation periods (thesis §4.3.1)."""
    period_s: float | None = Field(None, gt=0.0)
    """Excitation period for the frequency method; unset: detected from the inputs."""
    noise_model: Literal["auto", "output", "innovation"] = "auto"
    """Refinement criterion: "output" error (white sensor noise), "innovation" (prediction
    error of the Kalman predictor: turbulence as process noise), or "auto": output error,
    switching to the innovation form when its residuals are coloured and its fit poor."""
    refine: bool = True
    """Refine the OKID/ERA model by output error (maximum likelihood) and report Cramér–Rao
    standard errors; false reports the OKID/ERA model as is."""


class Config(_Section):
    """The whole configuration file."""

    identification: Identification = Identification()
    """The identification core's settings."""


class ConfigError(Exception):
    """config.toml cannot be used; `problems` lists (key path, reason) pairs."""

    def __init__(self, path: Path, problems: list[tuple[str, str]]):
        self.path = path
        self.problems = problems
        lines = "\n".join(f"  {key}: {reason}" for key, reason in problems)
        super().__init__(f"{path}: invalid configuration\n{lines}")


def load_config(path: str | Path) -> Config:
    """Read and validate a TOML configuration file; raise ConfigError saying what is wrong."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(path, [("(file)", "no such file")]) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(path, [("(file)", f"cannot be read: {exc}")]) from exc
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(path, [("(syntax)", str(exc))]) from exc
    try:
        return Config.model_validate(raw)
    except ValidationError as exc:
        problems = [
            (".".join(str(part) for part in err["loc"]) or "(top level)", err["msg"])
            for err in exc.errors()
        ]
        raise ConfigError(path, problems) from exc
