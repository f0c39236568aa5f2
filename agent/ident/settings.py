"""How to identify: every choice of the pipeline, None meaning automatic."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
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
    held_inputs: bool = True  # inputs held between samples (commands, zero-order hold)
    smoothing_s: float | None = None  # Savitzky–Golay window; None: no smoothing
    refine: bool = True  # output-error refinement of the OKID/ERA model
    # "auto": "aircraft" when an axis's four outputs are named and p, order are None, else
    # "time"; "time": OKID regression; "frequency": spectra → FRF (thesis §4.3.1);
    # "aircraft": decoupled axes, states measured, fitted in the frequency domain
    # (agent.ident.aircraft)
    method: str = "auto"
    period_s: float | None = None  # excitation period for "frequency"; None: detected
    noise_model: str = "auto"  # refinement: "output" error, "innovation" (PEM), or "auto"
