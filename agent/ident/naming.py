"""Aircraft mode names (phugoid, short period, roll, spiral, Dutch roll) from shapes and speeds.

Rules (thesis §4.1.3; Klein & Morelli, *Aircraft System Identification*, 2006, §2):
1. A mode belongs to an axis when at least `AXIS_SHARE` of its scaled mode-shape energy lies
   in that axis's outputs (longitudinal: V, α, q, θ; lateral: β, p, r, φ). When the record
   measures one axis only, every mode belongs to it.
2. Lateral: the complex pair with the largest MSV among those damped below
   `LIGHT_DAMPING` — or, when none is, among those below `DUTCH_ROLL_MAX_DAMPING` — is
   the Dutch roll; of the real modes the
   fastest is roll and the slowest spiral (a single real mode is roll when τ < 1 s, spiral
   when τ > 3 s). A pair damped at `DUTCH_ROLL_MAX_DAMPING` or more is a real pole that noise
   split in two, and counts as one real mode at its natural frequency.
3. Longitudinal: of two or more complex pairs the fastest is the short period and the slowest
   the phugoid; a single pair is the short period when α and q dominate its shape, the phugoid
   when V and θ do. With a single pair that is the phugoid, the two fastest real modes, when
   α and q dominate both, are an overdamped short period (both named so). Other real
   longitudinal modes (relaxed stability) get no standard name.
4. Only modes that could be rigid-body aircraft modes are named: MSV ≥ `MIN_MSV` (they carry
   a real share of the response), EMAC ≥ `MIN_EMAC` when known (temporally consistent, not
   noise), and natural frequency ≤ `MAX_FREQUENCY` (small-aircraft rigid-body modes lie well
   below it; noise modes of an over-sampled record sit near the Nyquist frequency).
   Anything the rules do not settle stays unnamed (None).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from agent.channels import LATERAL_OUTPUTS, LONGITUDINAL_OUTPUTS
from agent.ident.modal import Mode

AXIS_SHARE = 0.7
MIN_MSV = 1.0  # percent
MIN_EMAC = 50.0  # percent
MAX_FREQUENCY = 30.0  # rad/s
ROLL_MAX_TIME_CONSTANT = 1.0  # s
SPIRAL_MIN_TIME_CONSTANT = 3.0  # s
# A complex pair this damped is two nearly real poles (noise splitting a real mode, seen in
# the simulator: ζ = 0.999 at the roll pole), not an oscillation: never the Dutch roll. Real
# Dutch rolls stay well below (the J-3 Cub's 0.29; the thesis's appendix A.2 model's 0.77).
DUTCH_ROLL_MAX_DAMPING = 0.95
# A split roll pole was also seen at ζ = 0.92 with more of the response than the real Dutch
# roll (ζ = 0.29): a pair this lightly damped is preferred, as a Dutch roll oscillates. The
# heaviest-damped Dutch roll among our references is the thesis's A.2 model's 0.76.
LIGHT_DAMPING = 0.8


def _energy(mode: Mode, roles: Sequence[str | None], wanted: Sequence[str]) -> float:
    return float(
        sum(abs(c) ** 2 for c, role in zip(mode.shape, roles, strict=True) if role in wanted)
    )


def _axis(mode: Mode, roles: Sequence[str | None]) -> str | None:
    has_lat = any(role in LATERAL_OUTPUTS for role in roles)
    has_lon = any(role in LONGITUDINAL_OUTPUTS for role in roles)
    if has_lat != has_lon:
        return "lat" if has_lat else "lon"
    if not has_lat:
        return None
    lat, lon = _energy(mode, roles, LATERAL_OUTPUTS), _energy(mode, roles, LONGITUDINAL_OUTPUTS)
    share = lat / (lat + lon) if lat + lon > 0 else 0.5
    if share >= AXIS_SHARE:
        return "lat"
    return "lon" if share <= 1 - AXIS_SHARE else None


def _plausible(mode: Mode, min_msv: float) -> bool:
    consistent = mode.emac is None or mode.emac >= MIN_EMAC
    return mode.msv >= min_msv and consistent and mode.frequency <= MAX_FREQUENCY


def name_modes(
    modes: Sequence[Mode], output_roles: Sequence[str | None], min_msv: float = MIN_MSV
) -> list[Mode]:
    """The modes with `name` set where the rules above identify an aircraft mode.
    `min_msv` 0 names modes whatever their share of the response: for a model whose every
    state is a measured aircraft state (the aircraft method), where no mode is noise. There
    the MSV misleads too: two real poles nearly coinciding (the Cub's overdamped short
    period) have large residues that cancel, and beside them the phugoid's MSV fell to
    0.4 %."""
    names: dict[int, str] = {}
    candidates = [i for i, mode in enumerate(modes) if _plausible(mode, min_msv)]
    axis = {i: _axis(modes[i], output_roles) for i in candidates}
    lat = [i for i in candidates if axis[i] == "lat"]
    lon = [i for i in candidates if axis[i] == "lon"]
    _name_lateral(modes, lat, names)
    _name_longitudinal(modes, lon, output_roles, names)
    return [dataclasses.replace(mode, name=names.get(i)) for i, mode in enumerate(modes)]


def _name_lateral(modes: Sequence[Mode], lat: list[int], names: dict[int, str]) -> None:
    pairs = [i for i in lat if modes[i].pair and modes[i].damping < LIGHT_DAMPING] or [
        i for i in lat if modes[i].pair and modes[i].damping < DUTCH_ROLL_MAX_DAMPING
    ]
    if pairs:
        names[max(pairs, key=lambda i: modes[i].msv)] = "Dutch roll"
    # Seen in the simulator: the roll pole split into −11.35 ± 0.41j (ζ = 0.999) while an
    # extra real pole at −0.65 took the roll's name.
    reals = sorted(
        (i for i in lat if not modes[i].pair or modes[i].damping >= DUTCH_ROLL_MAX_DAMPING),
        key=lambda i: modes[i].frequency,
    )
    if len(reals) >= 2:
        names[reals[-1]] = "roll"
        names[reals[0]] = "spiral"
    elif len(reals) == 1:
        tau = 1.0 / modes[reals[0]].frequency if modes[reals[0]].frequency > 0 else np.inf
        if tau < ROLL_MAX_TIME_CONSTANT:
            names[reals[0]] = "roll"
        elif tau > SPIRAL_MIN_TIME_CONSTANT:
            names[reals[0]] = "spiral"


def _name_longitudinal(
    modes: Sequence[Mode], lon: list[int], roles: Sequence[str | None], names: dict[int, str]
) -> None:
    pairs = sorted((i for i in lon if modes[i].pair), key=lambda i: modes[i].frequency)
    if len(pairs) >= 2:
        names[pairs[-1]] = "short period"
        names[pairs[0]] = "phugoid"
    elif len(pairs) == 1:
        mode = modes[pairs[0]]
        short = _energy(mode, roles, ("alpha", "q"))
        long_ = _energy(mode, roles, ("airspeed", "theta"))
        if short > long_:
            names[pairs[0]] = "short period"
        elif long_ > short:
            names[pairs[0]] = "phugoid"
            # An overdamped short period: the two fastest real modes, faster than the
            # phugoid and mostly α and q (JSBSim's J-3 Cub: −6.4 and −10.1 1/s).
            reals = sorted(
                (i for i in lon if not modes[i].pair and modes[i].frequency > mode.frequency),
                key=lambda i: -modes[i].frequency,
            )
            fast = [
                i
                for i in reals[:2]
                if _energy(modes[i], roles, ("alpha", "q"))
                > _energy(modes[i], roles, ("airspeed", "theta"))
            ]
            if len(fast) == 2:
                for i in fast:
                    names[i] = "short period"
