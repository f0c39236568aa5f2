"""How to identify: every choice of the pipeline, None meaning automatic."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

if TYPE_CHECKING:  # the config's type only: the worker never parses a config
    from agent.config import IdentificationConfig

Method = Literal["auto", "time", "frequency", "aircraft"]
NoiseModel = Literal["auto", "output", "innovation"]


@dataclass(frozen=True, kw_only=True)
class Settings:
    """How to identify; None means choose automatically."""

    markov: int | None = None
    markov_max: int = 30
    order: int | None = None
    order_max: int = 20
    estimate_d: bool = False
    regularization: float = 0.0
    hankel_blocks: int | None = None
    decimation: int | None = None  # None: automatic from the band; 1: none (OKID's only)
    band_hz: float | None = None  # None: from the inputs' spectra
    # Inputs held between samples (commands, zero-order hold), or not (sampled measurements,
    # interpolated); None: chosen by the data (`agent.ident.pipeline.held_by_data`).
    held_inputs: bool | None = True
    smoothing_s: float | None = None  # Savitzky–Golay window; None: no smoothing
    refine: bool = True  # output-error refinement of the OKID/ERA model
    # "auto": "aircraft" when an axis's four outputs are named and p, order are None, else
    # "time"; "time": OKID regression; "frequency": spectra → FRF (thesis §4.3.1);
    # "aircraft": decoupled axes, states measured, fitted in the frequency domain
    # (agent.ident.aircraft)
    method: Method = "auto"
    period_s: float | None = None  # excitation period for "frequency"; None: detected
    noise_model: NoiseModel = "auto"  # refinement: "output" error, "innovation" (PEM), or "auto"
    # The whole-aircraft method's known nonlinear terms (agent.ident.aircraft.prepare): β² in
    # V̇'s equation (sideslip drag), and α·β, α·p, α·r in the lateral axis (the lateral
    # derivatives' change with α). Off only to measure what they do (bench_jsbsim --without).
    sideslip_drag: bool = True
    alpha_products: bool = True
    # The throttle's curvature: its square (about the trim) a known input of the longitudinal
    # axis (agent.ident.aircraft.prepare), where no rpm or thrust is measured.
    throttle_curve: bool = True
    # The lift's change with the air's density along the trim's own climb or descent (a
    # glider's steady glide), a known forcing of α̇'s equation (agent.ident.aircraft.prepare).
    # Off only to measure what it does.
    density: bool = True
    # The longitudinal axis fitted by the filter-error method, the turbulence the record does
    # not measure modelled as process noise (agent.ident.aircraft.process); off, output error.
    process_noise: bool = True
    # The record was flown with the autopilot's loops closed (FBWA: the plan on the sticks),
    # so the surfaces answer the disturbances: the lateral axis is then refined by prediction
    # error in the time domain, the rolling gust as coloured process noise
    # (agent.ident.aircraft.predictor). `predictor` off: the frequency-domain fit always.
    closed_loop: bool = False
    predictor: bool = True
    # Model-structure selection (agent.ident.aircraft.fit.selected): the derivatives whose
    # standard error is above their value fixed at zero, axis by axis (`--select`).
    select: bool = False

    @classmethod
    def from_config(
        cls,
        config: IdentificationConfig,
        *,
        sampled_inputs: bool = False,
        markov: int | None = None,
        order: int | None = None,
        decimation: int | None = None,
        refine: bool | None = None,
        method: Method | None = None,
        period_s: float | None = None,
        select: bool = False,
        closed_loop: bool = False,
    ) -> Settings:
        """The settings of an `[identification]` section; the keywords given (not None)
        override it, as command-line options do. `sampled_inputs`: the inputs are the agent's
        own recording of the surfaces' positions (potentiometers sampling moving surfaces),
        which `held_inputs = "auto"` treats as not held; other records' it chooses by their
        data."""
        held = config.held_inputs
        return cls(
            markov=markov if markov is not None else _auto(config.markov),
            markov_max=config.markov_max,
            order=order if order is not None else _auto(config.order),
            order_max=config.order_max,
            estimate_d=config.estimate_d,
            regularization=config.regularization,
            hankel_blocks=config.hankel_blocks,
            decimation=decimation if decimation is not None else _auto(config.decimation),
            band_hz=config.band_hz,
            held_inputs=(False if sampled_inputs else None) if held == "auto" else held,
            smoothing_s=config.smoothing_s,
            refine=config.refine if refine is None else refine,
            method=method or config.method,
            period_s=period_s if period_s is not None else config.period_s,
            noise_model=config.noise_model,
            select=select,
            closed_loop=closed_loop,
        )


def _auto(value: int | str) -> int | None:
    return None if value == "auto" else int(value)
