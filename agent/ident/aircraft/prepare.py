"""A batch made ready for the fit: the kinematic forcing, the measured wind as known inputs, and
the known nonlinear terms (sideslip drag, the lateral derivatives' change with α).

Kinematics: with the trim (`Experiment.operating_point`), the equations of θ and φ are pure
kinematics (θ̇ = q cos φ − r sin φ, φ̇ = p + tan θ (q sin φ + r cos φ)); their rows of A and
the θ, φ columns of the other rows are fixed at the kinematics' linear part at the trim
(`AxisProblem`), and their nonlinear rest is a known forcing K, X = (sI − A)⁻¹(B U + K − d).
So the bank of a lateral manoeuvre stops biasing the phugoid: with the lateral inputs
playing, the r sin φ of θ̇ can be larger than q itself. V̇, α̇ and β̇ get no such forcing: their
kinematic nonlinearities share factors such as 1/(V cos β) with the unknown aerodynamic
force, so half of a nonlinear equation is not nearer the truth than none.

Wind: with the INS's heading and velocities too, the gust g is the still-air V, α, β
(`inertial_air_data`) less the air data's, the still air being the record's mean air mass:
the steady wind (`steady_wind`, the record's mean) comes off the INS's velocity first. The forces
depend on the air-relative states x − g but the states move as the inertial ones, ẋ_i =
A(x_i − g) + B u, so the model is fitted on the inertial outputs with the gusts as known
inputs of their own (free) gains: the vanes' reading of the gust stops being noise that
biases the fit and becomes excitation, and A is the still-air aircraft's. Each gust is its
conditional mean given the noisy measurement (`agent.ident.aircraft.noise`), and the α and β
gusts' rates, through GUST_RATE_LAGS fitted lags each, are known inputs of their axes:
Dryden's pitch-rate and yaw-rate gusts (MIL-F-8785C;
`agent.ident.aircraft.wind.GUST_RATES`), the gusts' gradients along the airframe, which
otherwise bias the short period's damping and, where the span is large against the speed (a
glider), the Dutch roll's frequency. A gust that stands nowhere above its sensors' white noise
(`noise.detected`: calm air) is no input: the outputs stay the inertial ones, less noisy than
the vanes, but the "gust" is the difference of two sensors' noise, and its free gains on every
row fitted the phugoid's few bins (JSBSim's Cessna 182 in calm air: the phugoid's damping
16–20 % high on every seed, within 3 % without; benchmarks/README.md). With α's gust left
out, the longitudinal axis is fitted as where nothing measures it (the filter-error method
where the residual shows process noise; agent.ident.aircraft.model).

Sideslip drag (`sideslip_drag`): where β is measured, β² (the vane's air-relative β, from
trim) is a known input of V̇'s equation alone, with a fitted gain: drag due to sideslip,
C_D ∝ β² (Klein & Morelli, *Aircraft System Identification*, 2006, ch. 3's drag models).
Odd-harmonic inputs keep even-order effects off the longitudinal lines only while β stays
periodic; when the bank drifts (the spiral mode), the sideslip's slow wander puts sideslip
drag on the throttle's lines. Free on every longitudinal row instead, its gains are collinear
with the short period's.

The lateral derivatives' change with α (`alpha_products`): where both axes are fitted
together, α·β, α·p and α·r (about their means: below) are known inputs of the lateral
axis, with fitted gains. The longitudinal manoeuvre moves α while the lateral one plays, and
C_lβ, C_nβ, C_lp, C_lr and C_nr vary with α (JSBSim's Cub tabulates C_lβ and C_lr against
it); the products fall on the sum and difference frequencies of the two axes' lines, some of
which are the lateral axis's own. A lateral record alone moves α too little: no products.
The products are of the air-relative α and β (the vanes', what the moments depend on; p and r
as the gyros read them), each about its mean over the record. About the trim instead, a
constant part of α times p is p itself, and the roll damping traded against the product's
gain: in turbulence the trim (the record's first half second) carries that moment's gust,
which threw the glider's roll mode off on some seeds (benchmarks/README.md).

Without vanes (`Experiment.air_angles`: α and β synthesised from the INS and an estimated
steady wind, agent.ident.aircraft.airangles) the α and β gusts are not measured: they are
the INS's less the wind estimate, so their "gust" would be that estimate's projection, a
function of the attitude collinear with the states (on JSBSim's C172R in light turbulence it
took the short period up to 17 % off). Only the airspeed's gust (pitot against INS) is a
known input then; the vertical and lateral gusts are unmeasured process noise.

The throttle's curvature (`throttles`): a throttle's square about the trim (over its largest
deviation in the batch, so in the throttle's units) is a known input of the longitudinal axis,
on V̇ alone (thrust acts along the airspeed; its share in α̇ is T sin α / m V: a gain free on
each equation took JSBSim's C172R's card phugoid from 3.0 to 4.2 % off in median, on V̇ alone
it stays at 3.0 %; benchmarks/README.md), where no rpm or thrust is measured. A piston
engine's thrust bends with the throttle near full power: JSBSim's Cessna 310 at its 100-kt
trim gained 93 lb and lost 172 lb of thrust at ±10 % throttle, and a linear model of a classic
card's 5-s throttle doublet put its phugoid's damping 55 % high on every seed
(benchmarks/README.md). An odd-harmonic multisine keeps the square on the lines between its
own; steps and doublets do not. It is a term of still air only: where the INS measured the
longitudinal gusts (airspeed and, with vanes, α) and found them within the sensors' noise. The
square of a doublet or of a multisine's throttle is slow, its information in a few low bins,
and where the air moves the aircraft there its free gains fitted the gusts' slow response
instead (JSBSim's Cessna 182 in light turbulence: a seed's phugoid 8.4 → 11.3 % off, the J-3
Cub's 2.4 → 4.7 %, their gains 3–7 σ from nought; benchmarks/README.md). In still air it joins the
fit where the data ask for it (agent.ident.aircraft.model `_curved`: the Akaike criterion).

The air's density along the trim's own climb or descent (`_density_forcing`): the model is
linear about one trim, but a trim that climbs or descends (a glider's steady glide, about
1 m/s down at 50 kt) flies into air of another density, and its lift at the trim's α changes
with it: α̇ gains −(1/ρ dρ/dh) g cos γ₀ ḣ₀ t / V₀ over the record (DENSITY_GRADIENT, the ISA
troposphere's; ḣ₀ the INS's climb rate over the trim), a known forcing of α̇'s equation with
no free gain, none in level flight (a trim through less than LEVEL_M over the record).
Unexplained, that slow drift sits in the lowest bins, the
phugoid's: JSBSim's SGS 1-26 glider, descending about 200 m over the sweep card's 173 s in
calm air, had its short period 11.5 % and its phugoid 13.1 % off on two seeds of ten by the
filter error, which read the drift as process noise; forced, the row's worst are 7.3 and
5.0 % (its fitted α̇ per metre of height, a free gain in a trial, 3.6–4.7·10⁻⁵ 1/(m s) ±
2·10⁻⁶ over three seeds, where the lift's share gives 4.2·10⁻⁵; benchmarks/README.md). The
height the manoeuvre itself gains or loses is not forced: its density effect is part of the
phugoid's own motion, which the fitted derivatives hold as the validated truth does (the
measured height as the forcing instead, the T-6's calm phugoid 2.0 → 3.0 % off). V̇'s share,
the drag's change less the thrust's, is unknown where an engine lapses with height and is
left out everywhere (on the glider, whose drag alone gives it, over the calm sweep card's
ten seeds: the phugoid's median 1.7 → 1.1 % but its worst 5.3 → 7.4 %). Without the INS
(the vanes alone) the climb rate is not measured and the forcing is not made.

What each term does on the benchmark aircraft: benchmarks/README.md, *The whole-aircraft
method's terms* (`make bench-jsbsim`, with `--without` to leave one out).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from agent.ident.aircraft.airangles import Synthesised
from agent.ident.aircraft.axes import ATTITUDE
from agent.ident.aircraft.kinematics import (
    GRAVITY,
    KINEMATIC_STATES,
    kinematic_jacobian,
    kinematic_remainder,
)
from agent.ident.aircraft.noise import conditional_mean, detected
from agent.ident.aircraft.wind import GUST_RATES, GUSTS, inertial_air_data, steady_wind
from agent.ident.okid import Experiment

# The lateral states whose products with α are known inputs (`alpha_products`).
BILINEAR = ("beta", "p", "r")
# A measured gust whose rms is at most this share of its air-data channel's motion is no gust
# (the two sensors agree to rounding): it is left out (`prepare`).
NO_GUST = 1e-6
# The air's density's relative change with height, 1/ρ dρ/dh (1/m): the ISA troposphere's at
# sea level (ρ ∝ (1 − 2.2558·10⁻⁵ h)^4.2559, h in m; −1.03·10⁻⁴ at 3000 m), for the density's
# forcing along a climbing or descending trim (`_density_forcing`).
DENSITY_GRADIENT = -9.60e-5
# A trim that climbs or descends through less than this over the record (m; 0.5 % of the
# density) is level for the density's forcing: its share is then a hundredth of a degree of
# α, and the trim's half second of v_D is its own noise there (the J-3 Cub in light
# turbulence: ±0.05 m/s, whose forcing moved two seeds of its sweep without vanes past 10 %
# through the filter error; benchmarks/README.md).
LEVEL_M = 50.0


@dataclass(frozen=True, kw_only=True)
class Prepared:
    """A batch made ready for the fit: outputs on their inertial footing where the wind is
    measured, the measured gusts appended to the inputs, and the kinematic forcing."""

    batch: list[Experiment]  # u: the controls, then the known inputs
    known: list[np.ndarray] | None = None  # kinematic remainder per experiment, or None
    gusts: tuple[str, ...] = ()  # the gust columns' outputs ("airspeed", "alpha", "beta")
    # Gusts measured but no larger than the sensors' noise: not inputs, their outputs still
    # the inertial ones.
    undetected: tuple[str, ...] = ()
    # The INS measured the longitudinal gusts (airspeed and, with vanes, α) and found them
    # within the sensors' noise: still air.
    still: bool = False
    extra_names: tuple[str, ...] = ()  # the known inputs' names ("gust alpha", "beta²", ...)
    extra_axes: dict[int, str] = field(default_factory=dict)  # known input → its axis
    gust_rms: dict[str, float] = field(default_factory=dict)
    kinematics: np.ndarray | None = None  # see Transforms.kinematics (mean over experiments)
    attitude: tuple[int, ...] = ()  # output columns of θ and φ
    rates: tuple[int, ...] = ()  # known input columns of gust rates (GUST_RATE_LAGS lags each)
    rows: dict[int, int] = field(default_factory=dict)  # see Transforms.rows
    bilinear: tuple[int, ...] = ()  # known input columns of α·β, α·p, α·r (BILINEAR)
    curve: tuple[int, ...] = ()  # known input columns of the throttles' squares
    # Per experiment whose α and β were synthesised (no vanes), how (else empty).
    air_angles: tuple[Synthesised, ...] = ()
    # Per experiment whose trim the density's forcing took as climbing, its climb rate (m/s).
    climbs: tuple[float, ...] = ()


@dataclass(frozen=True, kw_only=True)
class _Terms:
    """Which known inputs a batch gets, in their column order after the controls."""

    gusts: tuple[str, ...]  # measured gusts, by the output they correct: known inputs
    rated: tuple[str, ...]  # gusts whose rate is an input too
    inertial: tuple[str, ...]  # outputs put on their inertial footing (the wind measured)
    drag: bool  # β², sideslip drag
    bilinear: bool  # α·β, α·p, α·r
    density: bool = False  # the density's forcing along the trim's climb (`_density_forcing`)
    # Throttle input column → (its name, the batch's largest |deviation|): its square over
    # that, a known input (the throttle's curvature).
    curve: dict[int, tuple[str, float]] = field(default_factory=dict)


def prepare(
    batch: Sequence[Experiment],
    output_roles: Sequence[str | None],
    *,
    trim_samples: int = 1,
    dt: float = 1.0,
    sideslip_drag: bool = True,
    alpha_products: bool = True,
    throttles: dict[int, str] | None = None,
    density: bool = True,
) -> Prepared:
    """Use the operating point and the INS's velocities when every experiment carries them:
    the kinematic forcing with the first, the measured wind with both (module docstring).
    `trim_samples`: the records' first samples whose mean is the trim; `dt` (s): the records'
    sample time, for the gust rates; `throttles`: input column → name of each throttle whose
    curvature is a known input (module docstring)."""
    index = {role: k for k, role in enumerate(output_roles) if role is not None}
    # The kinematics need the airspeed and θ: outputs, or measured as the flight's states
    # (`Experiment.flight`) in every experiment.
    flown = set.intersection(*(set(e.flight or {}) for e in batch))
    known = set(index) | flown
    if not {"airspeed", "theta"} <= known or any(e.operating_point is None for e in batch):
        return Prepared(
            batch=[Experiment(e.u, e.y) for e in batch],
            air_angles=tuple(e.air_angles for e in batch if e.air_angles is not None),
        )
    measured = "theta" in index and all(e.navigation is not None for e in batch)
    # Synthesised α and β (no vanes) are the INS's less an estimated steady wind: the gust's
    # α and β parts are not in them, so only the airspeed's gust (the pitot's) is measured.
    vaneless = any(e.air_angles is not None for e in batch)
    gusts = tuple(
        role
        for role, _ in GUSTS
        if role in index and measured and not (vaneless and role in ("alpha", "beta"))
    )
    terms = _Terms(
        gusts=gusts,
        rated=tuple(role for role in GUST_RATES if role in gusts),
        inertial=gusts,
        drag=sideslip_drag and "beta" in index and "airspeed" in index,
        bilinear=alpha_products and all(role in index for role in ("alpha", *BILINEAR)),
        curve=_curves(batch, throttles or {}, trim_samples) if "airspeed" in index else {},
        density=density and "alpha" in index and all(e.navigation is not None for e in batch),
    )
    out, known, jacobians, squares, motion, count, heard, climbs = _assemble(
        batch, index, terms, trim_samples, dt
    )
    # A gust the air data and the INS agree on to the last digits (calm air without sensor
    # noise: a simulation) holds nothing to fit a gain to; left in, its free gains grew
    # without bound and the time-domain prediction overflowed (TIC 1 on every output). One
    # no larger than the sensors' noise (calm air) is left out too (module docstring).
    calm = {
        role for role in gusts if squares[role] <= NO_GUST**2 * motion[role] or role not in heard
    }
    # The throttle's curvature only where the record shows still air (module docstring):
    # the INS measured the longitudinal gusts and found them within the sensors' noise.
    still = "airspeed" in calm and {"airspeed", "alpha"} & set(gusts) <= calm
    if calm or (terms.curve and not still):
        gusts = tuple(role for role in gusts if role not in calm)
        terms = replace(
            terms,
            gusts=gusts,
            rated=tuple(g for g in terms.rated if g in gusts),
            curve=terms.curve if still else {},
        )
        out, known, jacobians, squares, motion, count, _, climbs = _assemble(
            batch, index, terms, trim_samples, dt
        )
    r, m = batch[0].u.shape[1], batch[0].y.shape[1]
    names, axes, rates, rows, products, curve = _columns(terms, index, r)
    return Prepared(
        batch=out,
        known=known,
        gusts=gusts,
        undetected=tuple(role for role in terms.inertial if role not in gusts),
        still=still,
        extra_names=names,
        extra_axes=axes,
        gust_rms={role: float(np.sqrt(v / count)) for role, v in squares.items()},
        kinematics=_output_jacobian(np.mean(jacobians, axis=0), index, m),
        attitude=tuple(index[role] for role in ATTITUDE if role in index),
        rates=rates,
        rows=rows,
        bilinear=products,
        curve=curve,
        air_angles=tuple(e.air_angles for e in batch if e.air_angles is not None),
        climbs=tuple(climbs),
    )


def _curves(batch, throttles: dict[int, str], trim_samples: int) -> dict[int, tuple[str, float]]:
    """Each throttle that moved in the batch: its name and largest |deviation from trim|."""
    out = {}
    for j, name in throttles.items():
        peak = max(float(np.max(np.abs(_about_trim(e.u[:, j], trim_samples)))) for e in batch)
        if peak > 0:
            out[j] = (name, peak)
    return out


def _about_trim(signal: np.ndarray, trim_samples: int) -> np.ndarray:
    """`signal` less its mean over the record's first `trim_samples` (the trim): a square of
    a control is a curvature about the trim only from there, whatever the record's units."""
    return signal - signal[:trim_samples].mean()


def _assemble(batch, index: dict[str, int], terms: _Terms, trim_samples: int, dt: float):
    """Each experiment's inputs with the known ones, outputs and kinematic forcing; the
    kinematics' Jacobians; per gust its sum of squares about its mean and its air-data
    channel's, over the batch, and the samples counted; and the measured gusts that stand
    above their sensors' noise in some experiment (`noise.detected`)."""
    out, known, jacobians, climbs = [], [], [], []
    squares, motion, count = dict.fromkeys(terms.gusts, 0.0), dict.fromkeys(terms.gusts, 0.0), 0
    heard: set[str] = set()
    for e in batch:
        u, y, x, air, gust_columns, raw = _known_inputs(e, index, terms, trim_samples, dt)
        for role, gust in zip(terms.gusts, gust_columns, strict=False):
            channel = air[:, KINEMATIC_STATES.index(role)]
            squares[role] += float(np.sum((gust - gust.mean()) ** 2))
            motion[role] += float(np.sum((channel - channel.mean()) ** 2))
        heard |= {role for role, gust in raw.items() if detected(gust)}
        count += y.shape[0]
        trim = x[:trim_samples].mean(axis=0)
        jacobians.append(kinematic_jacobian(trim))
        out.append(Experiment(u, y))
        forcing = _attitude_forcing(x, trim, index, y.shape)
        if terms.density:
            climb = _climb(e.navigation, y.shape[0], trim_samples, dt)
            if climb:
                forcing += _density_forcing(climb, trim, index, y.shape, trim_samples, dt)
                climbs.append(climb)
        known.append(forcing)
    return out, known, jacobians, squares, motion, count, heard, climbs


def _columns(terms: _Terms, index: dict[str, int], r: int):
    """The known inputs' names, axes (by input column), and the columns of the gust rates, of
    the one-equation inputs (→ their output column) and of the α products."""
    where = dict(GUSTS)
    names = tuple(f"gust {role}" for role in terms.gusts)
    axes = [where[role] for role in terms.gusts]
    rates = tuple(r + len(names) + k for k in range(len(terms.rated)))
    names = (*names, *(f"gust {role} rate" for role in terms.rated))
    axes = [*axes, *(where[role] for role in terms.rated)]
    rows = {}
    if terms.drag:
        rows[r + len(names)] = index["airspeed"]
        names = (*names, "beta²")
        axes = [*axes, "longitudinal"]
    products: tuple[int, ...] = ()
    if terms.bilinear:
        products = tuple(r + len(names) + k for k in range(len(BILINEAR)))
        names = (*names, *(f"alpha·{role}" for role in BILINEAR))
        axes = [*axes, *(["lateral"] * len(BILINEAR))]
    curve = tuple(r + len(names) + k for k in range(len(terms.curve)))
    for column in curve:  # the thrust's line is the airspeed's (module docstring)
        rows[column] = index["airspeed"]
    names = (*names, *(f"{name}²" for name, _ in terms.curve.values()))
    axes = [*axes, *(["longitudinal"] * len(terms.curve))]
    return names, {r + k: a for k, a in enumerate(axes)}, rates, rows, products, curve


def _output_jacobian(mean: np.ndarray, index: dict[str, int], m: int) -> np.ndarray:
    """The kinematics' Jacobian (KINEMATIC_STATES order) in the record's output columns."""
    J = np.zeros((m, m))
    present = [(k, index[role]) for k, role in enumerate(KINEMATIC_STATES) if role in index]
    for a, ca in present:
        for b, cb in present:
            J[ca, cb] = mean[a, b]
    return J


def _known_inputs(e: Experiment, index: dict[str, int], terms: _Terms, trim_samples: int, dt):
    """One experiment's inputs with the known ones appended, its outputs (the inertial ones
    where the wind is measured), its absolute states, its air-relative ones, and its gusts."""
    x = np.zeros((e.y.shape[0], len(KINEMATIC_STATES)))
    for k, role in enumerate(KINEMATIC_STATES):
        if role in index:
            x[:, k] = e.y[:, index[role]] + e.operating_point[index[role]]
        elif e.flight and role in e.flight:  # measured, not modelled: its kinematics only
            x[:, k] = e.flight[role]
    u, y = e.u, e.y.copy()
    # Sideslip drag's regressor: the air-relative β (the vane's), before the wind's
    # correction below puts the inertial β in its place.
    beta = _about_trim(x[:, KINEMATIC_STATES.index("beta")], trim_samples)
    air = x.copy()  # the air-relative states: what the forces depend on
    gusts, raw = [], {}
    if terms.inertial:
        navigation = e.navigation.copy()
        navigation[:, 1:] -= steady_wind(x, navigation)  # relative to the mean air mass
        still = inertial_air_data(x, navigation)
        for role in terms.inertial:
            k = KINEMATIC_STATES.index(role)
            inertial = still[:, ("airspeed", "alpha", "beta").index(role)]
            raw[role] = inertial - x[:, k]
            x[:, k] = inertial
            y[:, index[role]] = inertial - e.operating_point[index[role]]
    if terms.gusts:
        gusts = [conditional_mean(raw[role]) for role in terms.gusts]
        rates = [np.gradient(gusts[terms.gusts.index(role)], dt) for role in terms.rated]
        u = np.hstack([u, np.column_stack([*gusts, *rates])])
    if terms.drag:
        u = np.hstack([u, (beta * beta)[:, None]])
    if terms.bilinear:  # on the air-relative states, about the record's mean (docstring)
        deviation = air - air.mean(axis=0)
        alpha = deviation[:, KINEMATIC_STATES.index("alpha")]
        lateral = [KINEMATIC_STATES.index(role) for role in BILINEAR]
        u = np.hstack([u, alpha[:, None] * deviation[:, lateral]])
    for j, (_, peak) in terms.curve.items():  # in the throttle's units: δ² / its peak
        delta = _about_trim(e.u[:, j], trim_samples)
        u = np.hstack([u, (delta * delta / peak)[:, None]])
    return u, y, x, air, gusts, raw


def _climb(navigation: np.ndarray, length: int, trim_samples: int, dt: float) -> float:
    """The trim's climb rate (m/s, the INS's −v_D over the trim), or 0 where the record takes it
    through less than LEVEL_M (level)."""
    climb = -float(np.mean(navigation[:trim_samples, 3]))
    return climb if abs(climb) * length * dt >= LEVEL_M else 0.0


def _density_forcing(
    climb: float, trim: np.ndarray, index: dict[str, int], shape, trim_samples: int, dt
) -> np.ndarray:
    """The lift's change with the air's density along the trim's own climb or descent (m/s), in
    α̇'s equation (zero elsewhere; module docstring): the height it takes the trim to from the
    trim's middle, and α̇'s −(1/ρ dρ/dh) g cos γ₀ / V₀ per metre (the lift at the trim,
    m g cos γ₀, in proportion to the density)."""
    forcing = np.zeros(shape)
    airspeed = trim[KINEMATIC_STATES.index("airspeed")]
    if airspeed <= 0:
        return forcing
    gamma = np.arcsin(np.clip(climb / airspeed, -1.0, 1.0))
    height = climb * (np.arange(shape[0]) - (trim_samples - 1) / 2) * dt
    gain = -DENSITY_GRADIENT * GRAVITY * np.cos(gamma) / airspeed
    forcing[:, index["alpha"]] = gain * height
    return forcing


def _attitude_forcing(x: np.ndarray, trim: np.ndarray, index: dict[str, int], shape):
    """The kinematics' nonlinear remainder in the θ and φ equations (zero elsewhere)."""
    remainder = kinematic_remainder(x, trim)
    forcing = np.zeros(shape)
    for role in ATTITUDE:
        if role in index:
            forcing[:, index[role]] = remainder[:, KINEMATIC_STATES.index(role)]
    return forcing
