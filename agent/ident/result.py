"""What one identification produced, in memory: the model, its modes and fit, and the part that
belongs to the method that made it (OKID/ERA's or the whole-aircraft method's). `document`
gives it as the one serialised form (agent.ident.document)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from agent.ident.candidates import MarkovChoice
from agent.ident.convert import StateSpace
from agent.ident.document import (
    AircraftDocument,
    FrequencyDocument,
    MarkovTry,
    Method,
    MissingMode,
    ModeDocument,
    OkidDocument,
    PreprocessingDocument,
    RefinementDocument,
    ResultDocument,
    SecondOrderMode,
    StateSpaceDocument,
    rows,
)
from agent.ident.era import EraResult
from agent.ident.fit import Fit
from agent.ident.frequency import FrequencyData
from agent.ident.modal import Mode, SecondOrder, second_order
from agent.ident.preprocess import Preprocessing
from agent.ident.refine import Refinement, second_order_std


@dataclass(frozen=True, kw_only=True)
class OkidDetails:
    """OKID/ERA's part of an identification."""

    markov: int
    markov_choice: MarkovChoice | None  # None when p was given
    era: EraResult  # the realisation in ERA's balanced coordinates
    observer_gain: np.ndarray  # G in reported coordinates: A + G C is the OKID observer
    fit: Fit  # the OKID/ERA model's own fit, before refinement
    frequency_data: FrequencyData | None = None  # spectra and FRF for "frequency"


@dataclass(frozen=True, kw_only=True)
class Identification:
    """Everything one identification produced."""

    dt: float  # analysis sample time (after decimation)
    preprocessing: Preprocessing
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    discrete: StateSpace  # reported coordinates (outputs when possible)
    continuous: StateSpace | None  # None when no real continuous model exists
    coordinates: str  # "outputs" or "era"
    modes: tuple[Mode, ...]
    fit: Fit
    refinement: Refinement | None  # None when turned off or impossible (see warnings)
    warnings: tuple[str, ...]
    method: Method
    okid: OkidDetails | None = None  # methods "time" and "frequency"
    aircraft: AircraftDocument | None = None  # method "aircraft"
    missing: tuple[tuple[str, str], ...] = ()
    """The modes the outputs' axes must have that no mode is named as: (name, why)
    (agent.ident.naming.missing_modes)."""
    left_out: tuple[str, ...] = ()
    """The model's poles that are no mode, each with why (agent.ident.modal.left_out)."""
    fitted: object | None = field(default=None, compare=False, repr=False)
    """Method "aircraft": the axes as fitted to the record (agent.ident.aircraft.model.Fitted),
    which another record's model is priced on (agent.ident.aircraft.linearity); not part of
    the document."""

    @property
    def order(self) -> int:
        return self.discrete.A.shape[0]

    @property
    def stable(self) -> bool:
        return all(mode.stable for mode in self.modes)

    def document(self, trim: list[dict[str, float]] | None = None) -> ResultDocument:
        """The identification as its one serialised form; `trim`: the records' operating
        points, by channel."""
        model, cont = self.discrete, self.continuous
        out_coords = self.coordinates == "outputs"
        return ResultDocument(
            dt=float(self.dt),
            order=int(self.order),
            inputs=list(self.input_names),
            outputs=list(self.output_names),
            A=rows(model.A),
            B=rows(model.B),
            C=rows(model.C),
            D=rows(model.D),
            Ac=rows(cont.A) if cont is not None and out_coords else None,
            Bc=rows(cont.B) if cont is not None and out_coords else None,
            stable=bool(self.stable),
            tic={n: float(v) for n, v in zip(self.output_names, self.fit.tic, strict=True)},
            tic_avg=float(self.fit.tic_avg),
            modes=[ModeDocument.of(m) for m in self.modes],
            method=self.method,
            coordinates=self.coordinates,
            continuous=None
            if cont is None
            else StateSpaceDocument(A=rows(cont.A), B=rows(cont.B), C=rows(cont.C), D=rows(cont.D)),
            trim=trim or [],
            preprocessing=self._preprocessing(),
            refinement=self._refinement(),
            okid=self._okid(),
            aircraft=self.aircraft,
            warnings=list(self.warnings),
            missing_modes=[MissingMode(name=n, reason=why) for n, why in self.missing],
            poles_left_out=list(self.left_out),
            second_order=[
                SecondOrderMode(
                    name=o.name,
                    frequency_rad_s=o.frequency,
                    damping=o.damping,
                    frequency_std_rad_s=o.frequency_std,
                    damping_std=o.damping_std,
                )
                for o in self.second_order()
            ],
        )

    def second_order(self) -> list[SecondOrder]:
        """Each named mode of two real poles as one second-order mode (agent.ident.modal), with
        the Cramér–Rao 1-σ of its ωn and ζ where the refinement gives a covariance."""
        orders = second_order(self.modes)
        refinement = self.refinement
        if refinement is None or refinement.covariance is None:
            return orders
        return [second_order_std(o, refinement) for o in orders]

    def _preprocessing(self) -> PreprocessingDocument:
        prep = self.preprocessing
        return PreprocessingDocument(
            record_dt=prep.record_dt,
            decimation=prep.factor,
            band_hz=prep.band_hz,
            held_inputs_shifted=prep.held_inputs,
            smoothing_s=prep.smoothing_s,
            dropped_samples_per_end=prep.dropped_samples,
        )

    def _refinement(self) -> RefinementDocument | None:
        ref = self.refinement
        if ref is None:
            return None
        std = ref.matrix_std()
        out_coords = self.coordinates == "outputs"
        names = self.output_names
        return RefinementDocument(
            criterion="output error" if ref.gain is None else "prediction error (innovation form)",
            hold=ref.hold,
            iterations=ref.iterations,
            converged=ref.converged,
            noise_std={n: float(v) for n, v in zip(names, ref.noise_std, strict=True)},
            Ac_std=rows(std.A) if out_coords else None,
            Bc_std=rows(std.B) if out_coords else None,
        )

    def _okid(self) -> OkidDocument | None:
        okid = self.okid
        if okid is None:
            return None
        choice = okid.markov_choice
        return OkidDocument(
            markov=okid.markov,
            markov_auto=None
            if choice is None
            else [MarkovTry(markov=p, order=n, tic_avg=t) for p, n, t in choice.tried],
            singular_values=[float(v) for v in okid.era.singular_values],
            tic_avg=float(okid.fit.tic_avg),
            frequency=self._frequency(),
        )

    def _frequency(self) -> FrequencyDocument | None:
        data = self.okid.frequency_data if self.okid is not None else None
        if data is None:
            return None
        spectra = data.spectra
        return FrequencyDocument(
            periodic=spectra.periodic,
            segment_s=spectra.segment_length * self.dt,
            segments=spectra.segments,
            leakage=spectra.leakage,
            markov_from="inverse FFT" if data.frf.broadband else "observer fit to the FRF",
        )


# A decent fit has TIC below this (thesis §5.3, ref. [67]).
TIC_DECENT = 0.3


def judged(modes: tuple[Mode, ...] | list[Mode], fitted: Fit) -> list[str]:
    """The warnings every method gives on its model: unstable modes, a poor fit."""
    warnings = []
    if any(not mode.stable for mode in modes):
        warnings.append("the identified model has unstable modes")
    if fitted.tic_avg >= TIC_DECENT:
        warnings.append(f"average TIC {fitted.tic_avg:.3f} is not below {TIC_DECENT}")
    return warnings
