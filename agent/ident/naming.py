"""Aircraft mode names (phugoid, short period, roll, spiral, Dutch roll) from shapes and speeds.

Rules (thesis §4.1.3; Klein & Morelli, *Aircraft System Identification*, 2006, §2):
1. A mode belongs to an axis when at least `AXIS_SHARE` of its scaled mode-shape energy lies
   in that axis's outputs (longitudinal: V, α, q, θ; lateral: β, p, r, φ). When the record
   measures one axis only, every mode belongs to it.
2. Lateral: the complex pair with the largest MSV among those damped below
   `LIGHT_DAMPING` — or, when none is, among those below `DUTCH_ROLL_MAX_DAMPING` — is
   the Dutch roll; of the real modes the
   fastest is roll when it is stable with τ < 3 s (the roll damping is negative on every
   aircraft, and a slower mode is the spiral's) and the slowest spiral (a single real mode is
   roll when stable with τ < 1 s, spiral when τ > 3 s). A pair damped at
   `DUTCH_ROLL_MAX_DAMPING` or more is a real pole that noise split in two, and counts as one
   real mode at its natural frequency.
3. Longitudinal: of the complex pairs that V and θ dominate, the slowest is the phugoid; of
   those that α and q dominate, the fastest, when faster than the phugoid, is the short
   period (Klein & Morelli §2: the short period is an α–q motion at nearly constant speed,
   the phugoid a V–θ exchange at nearly constant α). A pair that is neither stays unnamed.
   Without a short-period pair, the two fastest real modes (faster than a phugoid pair),
   when α and q dominate both, are an overdamped short period (both named so). Without a
   phugoid pair, once a short period is named, the two slowest real modes slower than it,
   when V and θ dominate both, are an overdamped phugoid (both named so: a phugoid damped
   past ζ = 1 is two slow real poles). Other real longitudinal modes (relaxed stability)
   get no standard name.
4. Only modes that could be rigid-body aircraft modes are named: MSV ≥ `MIN_MSV` (they carry
   a real share of the response), EMAC ≥ `MIN_EMAC` when known (temporally consistent, not
   noise), and natural frequency ≤ `MAX_FREQUENCY` (small-aircraft rigid-body modes lie well
   below it; noise modes of an over-sampled record sit near the Nyquist frequency).
   Anything the rules do not settle stays unnamed (None).

The modes an aircraft must have (`expected_modes`) are those of the axes its outputs measure;
`missing_modes` lists those no mode was named as, each with the reason the rules give.
"""

from __future__ import annotations

import collections
import dataclasses
from collections.abc import Sequence

import numpy as np

from agent.channels import LATERAL_OUTPUTS, LONGITUDINAL_OUTPUTS
from agent.ident.modal import Mode

AXIS_SHARE = 0.7
# Two modes this close (a share of the larger eigenvalue's magnitude) are twins, whose
# eigenvectors the weakest coupling mixes (`name_modes`).
TWINS = 0.1
MIN_MSV = 1.0  # percent
MIN_EMAC = 50.0  # percent
MAX_FREQUENCY = 30.0  # rad/s
ROLL_MAX_TIME_CONSTANT = 1.0  # s
SPIRAL_MIN_TIME_CONSTANT = 3.0  # s
LATERAL_MODES = ("Dutch roll", "roll", "spiral")
LONGITUDINAL_MODES = ("short period", "phugoid")
# Modes whose time scale a short record may not hold: a missing one's reason says how slow a
# mode the record resolves.
SLOW_MODES = ("spiral", "phugoid")
SHORT_PERIOD_ROLES = ("alpha", "q")
PHUGOID_ROLES = ("airspeed", "theta")
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


def _twins(a: Mode, b: Mode) -> bool:
    """Two eigenvalues within TWINS of the larger's magnitude of each other."""
    return abs(a.eigenvalue - b.eigenvalue) <= TWINS * max(abs(a.eigenvalue), abs(b.eigenvalue))


def _plausible(mode: Mode, min_msv: float) -> bool:
    return not _implausible(mode, min_msv)


def name_modes(
    modes: Sequence[Mode],
    output_roles: Sequence[str | None],
    min_msv: float = MIN_MSV,
    axes: Sequence[str | None] | None = None,
) -> list[Mode]:
    """The modes with `name` set where the rules above identify an aircraft mode.
    `axes`: each mode's axis ("lat", "lon" or None) as the model's structure tells it, for the
    modes whose shape does not (rule 1): two modes of the two axes at nearly one eigenvalue
    (a roll mode beside a pole of an overdamped short period) mix their eigenvectors through
    the weakest coupling, and neither shape lies 70 % in one axis.
    `min_msv` 0 names modes whatever their share of the response: for a model whose every
    state is a measured aircraft state (the aircraft method), where no mode is noise. There
    the MSV misleads too: two real poles nearly coinciding (the Cub's overdamped short
    period) have large residues that cancel, and beside them the phugoid's MSV fell to
    0.4 %."""
    names: dict[int, str] = {}
    candidates = [i for i, mode in enumerate(modes) if _plausible(mode, min_msv)]
    axis = {i: _axis(modes[i], output_roles) or (axes[i] if axes else None) for i in candidates}
    if axes and all(a is not None for a in axes):
        # Two modes of the two axes at nearly one eigenvalue can both look like one axis (each
        # eigenvector a mixture of the two): the shapes then give that axis more modes than
        # its states have. Where the counts differ, the structure's axis stands for a mode
        # with a near twin (JSBSim's Cub: the short period's −12.1 1/s pole beside the roll's
        # −12.2, both shapes 70 % longitudinal, the roll mode lost); a mode with none keeps
        # the word of its shape.
        shapes = collections.Counter(axis.values())
        if shapes != collections.Counter(axes[i] for i in candidates):
            for i in candidates:
                if any(_twins(modes[i], modes[j]) for j in candidates if j != i):
                    axis[i] = axes[i]
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
    # The roll subsidence is stable (the roll damping L_p < 0 on every aircraft) and faster
    # than a spiral can be: seen on JSBSim's glider in light turbulence, a record that did
    # not resolve it left two poles near zero, +0.149 and −0.119 1/s, the faster unstable.
    if len(reals) >= 2:
        if _subsides(modes[reals[-1]], SPIRAL_MIN_TIME_CONSTANT):
            names[reals[-1]] = "roll"
        names[reals[0]] = "spiral"
    elif len(reals) == 1:
        tau = 1.0 / modes[reals[0]].frequency if modes[reals[0]].frequency > 0 else np.inf
        if _subsides(modes[reals[0]], ROLL_MAX_TIME_CONSTANT):
            names[reals[0]] = "roll"
        elif tau > SPIRAL_MIN_TIME_CONSTANT:
            names[reals[0]] = "spiral"


def _subsides(mode: Mode, longest: float) -> bool:
    """Whether a real lateral mode can be the roll subsidence: stable, its time constant
    below `longest` (s)."""
    return complex(mode.eigenvalue).real < 0 and mode.frequency > 1.0 / longest


def _name_longitudinal(
    modes: Sequence[Mode], lon: list[int], roles: Sequence[str | None], names: dict[int, str]
) -> None:
    pairs = sorted((i for i in lon if modes[i].pair), key=lambda i: modes[i].frequency)
    # Each pair by its shape: α and q for the short period, V and θ for the phugoid. Order
    # alone misleads when the model has a pair that is neither: a glider's synthesised α
    # drifting with the wind estimate gave a slow α pair below the phugoid, and the phugoid,
    # the fastest pair there (its short period overdamped), was named the short period.
    like_short = [
        i for i in pairs if _dominated(modes[i], roles, SHORT_PERIOD_ROLES, PHUGOID_ROLES)
    ]
    like_phugoid = [
        i for i in pairs if _dominated(modes[i], roles, PHUGOID_ROLES, SHORT_PERIOD_ROLES)
    ]
    phugoid = like_phugoid[0] if like_phugoid else None
    above = modes[phugoid].frequency if phugoid is not None else 0.0
    faster = [i for i in like_short if modes[i].frequency > above]
    short = faster[-1] if faster else None
    reals = sorted((i for i in lon if not modes[i].pair), key=lambda i: modes[i].frequency)
    shorts = [short] if short is not None else []
    if short is None:
        # An overdamped short period: the two fastest real modes, faster than the phugoid
        # and mostly α and q (JSBSim's J-3 Cub: −6.4 and −10.1 1/s).
        fast = [i for i in reals if modes[i].frequency > above][-2:]
        shorts = _both(modes, fast, roles, SHORT_PERIOD_ROLES, PHUGOID_ROLES)
    phugoids = [phugoid] if phugoid is not None else []
    if phugoid is None and shorts:
        # An overdamped phugoid: the two slowest real modes, slower than the short period and
        # mostly V and θ.
        below = min(modes[i].frequency for i in shorts)
        slow = [i for i in reals if i not in shorts and modes[i].frequency < below][:2]
        phugoids = _both(modes, slow, roles, PHUGOID_ROLES, SHORT_PERIOD_ROLES)
    names.update(dict.fromkeys(shorts, "short period"))
    names.update(dict.fromkeys(phugoids, "phugoid"))


def _dominated(
    mode: Mode, roles: Sequence[str | None], by: Sequence[str], over: Sequence[str]
) -> bool:
    return _energy(mode, roles, by) > _energy(mode, roles, over)


def _both(
    modes: Sequence[Mode],
    two: list[int],
    roles: Sequence[str | None],
    by: Sequence[str],
    over: Sequence[str],
) -> list[int]:
    """`two` when they are two real modes that `by`'s outputs dominate, else none."""
    if len(two) == 2 and all(_dominated(modes[i], roles, by, over) for i in two):
        return two
    return []


def expected_modes(roles: Sequence[str | None]) -> tuple[str, ...]:
    """The modes an aircraft must have, for the axes whose outputs `roles` include: the
    short period and phugoid (longitudinal), the Dutch roll, roll and spiral (lateral)."""
    lon = any(role in LONGITUDINAL_OUTPUTS for role in roles)
    lat = any(role in LATERAL_OUTPUTS for role in roles)
    return (LONGITUDINAL_MODES if lon else ()) + (LATERAL_MODES if lat else ())


# What each rule looked for, for a mode it did not find (the module docstring's rules).
_LOOKED_FOR = {
    "Dutch roll": f"no lateral pair damped below ζ = {DUTCH_ROLL_MAX_DAMPING:g}",
    "roll": "no fast stable real lateral mode (the faster of two with τ < "
    f"{SPIRAL_MIN_TIME_CONSTANT:g} s, or a single one with τ < {ROLL_MAX_TIME_CONSTANT:g} s)",
    "spiral": "no slow real lateral mode (the slower of two, or a single one with τ > "
    f"{SPIRAL_MIN_TIME_CONSTANT:g} s)",
    "short period": "no longitudinal pair, nor two fast real modes, dominated by α and q",
    "phugoid": "no longitudinal pair, nor two real modes slower than the short period, "
    "dominated by airspeed and θ",
}


def missing_modes(
    modes: Sequence[Mode],
    output_roles: Sequence[str | None],
    *,
    span_s: float | None = None,
    min_msv: float = MIN_MSV,
) -> list[tuple[str, str]]:
    """The expected modes (`expected_modes`) that no mode of `modes` (named by `name_modes`
    with the same `min_msv`) is named as, each with why: what the rule looked for, the modes of
    that axis it set aside as implausible (and why) or left unnamed, and for a slow mode how
    slow a mode the record, `span_s` seconds long, resolves."""
    named = {mode.name for mode in modes}
    found = []
    for name in expected_modes(output_roles):
        if name in named:
            continue
        axis = "lat" if name in LATERAL_MODES else "lon"
        mine = [m for m in modes if _axis(m, output_roles) == axis]
        reason = "no named mode: " + _LOOKED_FOR[name]
        aside = [
            f"{_eigenvalue(m)} ({_implausible(m, min_msv)})"
            for m in mine
            if _implausible(m, min_msv)
        ]
        unnamed = [_eigenvalue(m) for m in mine if m.name is None and not _implausible(m, min_msv)]
        if aside:
            reason += "; set aside: " + ", ".join(aside)
        if unnamed:
            reason += "; unnamed: " + ", ".join(unnamed)
        if name in SLOW_MODES and span_s:
            reason += (
                f"; a {span_s:.3g} s record resolves time constants up to {span_s / 2:.3g} s "
                f"and frequencies down to {2 * np.pi / span_s:.2g} rad/s"
            )
        found.append((name, reason))
    return found


def _eigenvalue(mode: Mode) -> str:
    s = mode.eigenvalue
    return f"{s.real:.3g} ± {abs(s.imag):.3g}j 1/s" if mode.pair else f"{s.real:.3g} 1/s"


def _implausible(mode: Mode, min_msv: float) -> str:
    """Why `_plausible` refuses the mode ("" when it does not)."""
    why = []
    if mode.msv < min_msv:
        why.append(f"MSV {mode.msv:.2g} % < {min_msv:g} %")
    if mode.emac is not None and mode.emac < MIN_EMAC:
        why.append(f"EMAC {mode.emac:.0f} % < {MIN_EMAC:.0f} %")
    if mode.frequency > MAX_FREQUENCY:
        why.append(f"ωn {mode.frequency:.3g} > {MAX_FREQUENCY:.0f} rad/s")
    return ", ".join(why)
