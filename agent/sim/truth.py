"""The truth an identified model is judged against: JSBSim's own linear response at the trim
point, measured from the nonlinear simulation and checked against it.

Why not JSBSim's `FGLinearization`: on the benchmark aircraft it does not reproduce JSBSim's
own small-amplitude response. Its engine-speed state is broken (the column of `Rpm0` is zero,
so nothing depends on it, and its row depends on latitude and longitude), so the throttle
moves the airspeed at once instead of through the propeller's spin-up of about a second; on
the Cessna 182 the `Rpm0` row even gives an unstable pole at +1.12 1/s, and a doublet on any
surface diverges from JSBSim's response (TIC 1.0 on every output). `benchmarks/truth_check.py`
prints both checks side by side.

What is done instead (the best linear approximation of the nonlinear model; Pintelon &
Schoukens, *System Identification: A Frequency Domain Approach*, 2nd ed., 2012, ch. 3):

1. From the trim, JSBSim flies a small multisine on all four controls at once, in
   REALISATIONS random-phase realisations, each twice: once as is and once negated. Half the
   difference of the two responses is their odd part, so every even-order nonlinearity
   cancels exactly. Sideslip drag (∝ β²) is one example, and so is the speed lost in a bank.
   These would otherwise show up as a linear coupling that is not there. The realisations
   average out what odd distortion remains.
2. Each control's multisine holds its own harmonics of 1/300 s, log-spaced from 0.01 to 2 Hz
   and disjoint between the controls, so their effects can be told apart. The phugoid and the
   spiral are in the band.
3. The states are the eight measured outputs plus the unmeasured altitude (density) and the
   engine's slow states, as its kind has them (agent.sim.plant.ENGINE_STATES: a piston
   engine's speed and manifold pressure, a turboprop's speed and N1, a turbine's spools N1
   and N2, nothing on a glider). The inputs are the surfaces' positions, as the potentiometer
   box measures them, and the throttle's. Actuator dynamics therefore stay outside the truth,
   as they stay outside what is identified.
4. A least-squares regression of the state derivatives (central differences at the 200 Hz
   integration rate) on the states and inputs gives ẋ = A x + B u. The inputs are the mean
   of the two steps' positions the difference spans: either one alone would place them half
   a step (2.5 ms) off, which moved the Cub's short period by several per cent. What is
   known exactly is held at its value: the rows of θ, φ and the altitude are the rigid
   body's kinematics linearised at the trim, and the θ and φ columns of the other rows are
   gravity's (no aerodynamic or engine force depends on the attitude). Left free, those
   entries came out 1–2 % off (θ̇ = 0.986 q − 0.004 α on the Cub).
5. An aircraft that departs under the multisine (`_departed`: an unstable spiral driven by
   its slowest lines; JSBSim's DHC-6 at 130 kt) is flown again, every realisation, held near
   its trim by a feedback designed on what it flew before it departed (`_hold`). The
   regression is the same: the data have no noise, so the feedback, which correlates the
   inputs with the states, biases nothing, and the multisine keeps them apart. A flight
   stops where it departs: flown on, the DHC-6 went into the ground and to NaN.

The check (`check`): the odd part of a doublet on each surface and of a throttle step, each
flown as a ± pair, against the truth driven by the same recorded positions; every output that
the test moves is held to TIC ≤ 0.05. An output counts for a test when that test moves it at
least a tenth as much as the test that moves it most. Aileron → airspeed, for instance, is
0.35 % of throttle → airspeed on the Cessna: a linear coupling below any sensor's noise.
Every test passes on the three benchmark aircraft, the worst at TIC 0.037 (the Cub's throttle
step; `benchmarks/truth_check.py`). That test failed at 0.11 before three timing fixes:
JSBSim's default Euler rotation (agent.sim.plant.INTEGRATORS), the regression's input timing
(step 4), and the check itself, which compared the truth's prediction two steps late.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace

import numpy as np
import scipy.linalg

from agent.ident.aircraft.kinematics import kinematic_jacobian
from agent.sim.plant import ENGINE_STATES, FT, INPUTS, Plant, PlantError

OUTPUTS = ("Vt", "alpha", "q", "theta", "beta", "p", "r", "phi")
BODY = (*OUTPUTS, "alt")  # the states every aircraft has; its engine's follow (states())
LONGITUDINAL, LATERAL = ("Vt", "alpha", "q", "theta"), ("beta", "p", "r", "phi")
# The multisine: its period (s), its band (Hz), harmonics per control, and the amplitude of each
# control's command (normalised; about 0.5–1° of surface and 3 % of throttle).
PERIOD_S = 300.0
BAND_HZ = (0.01, 2.0)
HARMONICS = 60
AMPLITUDE = 0.03
# Random-phase realisations of the multisine: the odd nonlinear distortions that remain (third
# order and up) differ between realisations and average out of the regression.
REALISATIONS = 4
# Entries known exactly (step 4 of the module docstring): these rows are kinematics alone, and
# these states reach the other rows only through gravity.
KNOWN_ROWS = ("theta", "phi", "alt")
ATTITUDE = ("theta", "phi")
# The check: each test's length (s), when its input starts (s), the doublet's half-period (s),
# the bound on TIC, and the share of an output's largest response below which a test does not
# count it.
CHECK_S, CHECK_START_S, DOUBLET_S = 20.0, 1.0, 1.0
CHECK_TIC = 0.05
COUNTED_SHARE = 0.1
# A truth flight has departed (`_departed`) beyond these deviations from the trim (rad, rad, share
# of the airspeed). The multisine moves the benchmark's aircraft by up to 20° of bank (the T-6's
# slow spiral), 3.8° of pitch and 9 % of airspeed (the glider's), none of which departs; the
# DHC-6 at 130 kt spiralled to 64° of bank 54 s in and into the ground at 56 s.
DEPARTED = {"phi": np.radians(30.0), "theta": np.radians(15.0), "Vt": 0.2}
# The hold's state weights against its controls' (`_hold`), tried in turn: the least that holds.
# Weighted at 1e-4 the DHC-6's hold (its spiral mirrored) still let its bank follow the
# multisine's slowest aileron lines past 20°; at 1e-2, within 1.4°.
HOLD_WEIGHTS = (1e-3, 1e-2, 1e-1, 1.0)
# A stretch before a departure shorter than this (s) is too little to design a hold on.
MIN_STRETCH_S = 5.0

_PROPERTIES = (
    ("velocities/vt-fps", FT),
    ("aero/alpha-rad", 1.0),
    ("velocities/q-rad_sec", 1.0),
    ("attitude/theta-rad", 1.0),
    ("aero/beta-rad", 1.0),
    ("velocities/p-rad_sec", 1.0),
    ("velocities/r-rad_sec", 1.0),
    ("attitude/phi-rad", 1.0),
    ("position/h-sl-meters", 1.0),
)


def states(kind: str) -> tuple[str, ...]:
    """The truth's states for an aircraft whose powerplant is of `kind` (ENGINE_STATES)."""
    return (*BODY, *(name for name, _ in ENGINE_STATES[kind]))


@dataclass(frozen=True)
class Truth:
    """ẋ = A x + B u about the trim: x in `states` (SI, and the engine's in JSBSim's units:
    rpm, inHg, percent), u in INPUTS as positions (throttle 0–1, surfaces in degrees)."""

    A: np.ndarray
    B: np.ndarray
    trim_state: np.ndarray
    trim_input: np.ndarray
    aircraft: str
    airspeed_kts: float
    conditions: dict  # the Plant's other settings at this trim (altitude, rate)
    states: tuple[str, ...] = states("piston")
    powerplant: str = "piston"  # ENGINE_STATES's kind
    hold: np.ndarray | None = None  # the feedback its flights were held by (`_hold`), if any

    def modes(self) -> dict[str, list[complex]]:
        """The aircraft's modes by name (one eigenvalue per pair, upper half-plane)."""
        return name_modes(self.A, self.trim_state, self.states)

    def eigenvalues(self) -> np.ndarray:
        return np.linalg.eigvals(self.A)

    def simulate(self, u: np.ndarray, dt: float) -> np.ndarray:
        """States (deviations from trim) driven by input deviations held over each step."""
        n, r = self.A.shape[0], self.B.shape[1]
        block = np.zeros((n + r, n + r))
        block[:n, :n], block[:n, n:] = self.A, self.B
        phi = scipy.linalg.expm(block * dt)
        Ad, Bd = phi[:n, :n], phi[:n, n:]
        x = np.zeros(n)
        out = np.empty((len(u), n))
        for k, row in enumerate(u):
            out[k] = x
            x = Ad @ x + Bd @ row
        return out


def _states(plant: Plant) -> np.ndarray:
    f = plant.fdm
    engine = [(prop, 1.0) for _, prop in ENGINE_STATES[plant.kind]]
    return np.array([float(f[name]) * scale for name, scale in (*_PROPERTIES, *engine)])


def _positions(plant: Plant) -> np.ndarray:
    s = plant.state()
    return np.array([s[name] for name in INPUTS])


def _fly(
    plant: Plant, commands: np.ndarray, hold: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Commands (normalised deltas, one row per integration step) in; states and positions
    after each step out. `hold` (inputs × states, normalised command per unit of state): a
    linear feedback on the state's deviation from the trim added to the commands (`_hold`).
    A flight that departs (`_departed`) stops there, its remaining rows NaN: flown on into
    the ground, JSBSim's DHC-6 went to NaN, and every DHC-6 the process made after it failed
    its trim (its engines' thrust NaN; other aircraft unaffected)."""
    x = np.full((len(commands), len(BODY) + len(ENGINE_STATES[plant.kind])), np.nan)
    u = np.full((len(commands), len(INPUTS)), np.nan)
    trim = _states(plant)
    now = trim
    for k, row in enumerate(commands):
        if hold is not None:
            row = row - hold @ (now - trim)
        plant.command(dict(zip(INPUTS, row, strict=True)))
        plant.step()
        now = _states(plant)
        x[k], u[k] = now, _positions(plant)
        if _departed(now[None], trim) is not None:
            break
    return x, u


def odd_response(aircraft: str, airspeed_kts: float, commands: np.ndarray, hold=None, **plant):
    """The odd part of JSBSim's response to `commands` from the trim: (states, positions) as
    deviations, and the trim (states, positions); `hold`: as `_fly`'s (a linear law: the
    negated flight is held by the same feedback, and the odd part is still the odd part)."""
    x, u, trim, _ = _odd(aircraft, airspeed_kts, commands, hold, **plant)
    return x, u, trim


def _odd(aircraft: str, airspeed_kts: float, commands: np.ndarray, hold=None, **plant):
    """`odd_response`, and the first step at which either flight departed (`_departed`;
    None: neither did)."""
    up = Plant(aircraft, airspeed_kts=airspeed_kts, linearise=False, **plant)
    trim = _states(up), _positions(up)
    xp, up_u = _fly(up, commands, hold)
    down = Plant(aircraft, airspeed_kts=airspeed_kts, linearise=False, **plant)
    xm, down_u = _fly(down, -commands, hold)
    gone = [k for k in (_departed(xp, trim[0]), _departed(xm, trim[0])) if k is not None]
    return (xp - xm) / 2, (up_u - down_u) / 2, trim, min(gone, default=None)


def _departed(x: np.ndarray, trim: np.ndarray) -> int | None:
    """The first step at which a flight's states left the small perturbation the truth is
    taken in (DEPARTED: bank, pitch attitude, airspeed), or stopped being numbers."""
    V, theta, phi = (BODY.index(s) for s in ("Vt", "theta", "phi"))
    with np.errstate(invalid="ignore"):
        out = (
            ~np.all(np.isfinite(x), axis=1)
            | (np.abs(x[:, phi] - trim[phi]) > DEPARTED["phi"])
            | (np.abs(x[:, theta] - trim[theta]) > DEPARTED["theta"])
            | (np.abs(x[:, V] - trim[V]) > DEPARTED["Vt"] * trim[V])
        )
    return int(np.argmax(out)) if out.any() else None


def excitation(
    rate_hz: float, realisation: int = 0, seconds: float = PERIOD_S, amplitude: float = AMPLITUDE
) -> np.ndarray:
    """The fitting multisine: each control its own log-spaced harmonics in BAND_HZ (disjoint
    between controls), random phases (seeded: the truth is deterministic), faded in over 2 s."""
    rng = np.random.default_rng(realisation)
    n = round(seconds * rate_hz)
    t = np.arange(n) / rate_hz
    u = np.zeros((n, len(INPUTS)))
    wanted = np.round(np.geomspace(*BAND_HZ, HARMONICS) * seconds)
    for j in range(len(INPUTS)):
        k = np.unique(len(INPUTS) * (wanted // len(INPUTS)) + j)
        k = k[k > 0]
        phases = rng.uniform(0, 2 * np.pi, k.size)
        s = np.sin(2 * np.pi * np.outer(t, k / seconds) + phases).sum(axis=1)
        u[:, j] = amplitude * s / np.abs(s).max()
    return u * np.minimum(t / 2.0, 1.0)[:, None]


@functools.lru_cache(maxsize=8)
def linear_truth(
    aircraft: str, airspeed_kts: float, amplitude: float = AMPLITUDE, **plant
) -> Truth:
    """JSBSim's best linear approximation at the trim (module docstring); about 10 s, so kept
    for the process (JSBSim is deterministic: the same trim gives the same truth).
    `amplitude`: of the multisine's commands (AMPLITUDE unless asked: the best linear
    approximation of a nonlinear aircraft moves with the amplitude it is taken at,
    `benchmarks/truth_check.py --amplitudes`). An aircraft that departs under the multisine
    (an unstable spiral) is flown again, held by a feedback designed on what it flew before
    it departed (`_hold`, module docstring step 5)."""
    rate = float(plant.get("integration_hz", 200.0))
    kind = Plant(aircraft, airspeed_kts=airspeed_kts, linearise=False, **plant).kind
    names = states(kind)
    commands = [excitation(rate, m, amplitude=amplitude) for m in range(REALISATIONS)]
    hold, gone, flights = None, None, []
    for c in commands:
        x, u, (x0, u0), gone = _odd(aircraft, airspeed_kts, c, **plant)
        if gone is not None:
            stretch = (x[:gone], u[:gone], c[:gone])
            break
        flights.append((x, u))
    # Departed: all flown again, held by the least feedback of HOLD_WEIGHTS that holds them.
    for weight in HOLD_WEIGHTS if gone is not None else ():
        hold = _hold(*stretch, x0, names, rate, weight)
        flights = []
        for c in commands:
            x, u, (x0, u0), gone = _odd(aircraft, airspeed_kts, c, hold, **plant)
            if gone is not None:
                break
            flights.append((x, u))
        if gone is None:
            break
    if gone is not None:
        raise PlantError(
            f"{aircraft} at {airspeed_kts:g} kt departs from its trim under the truth's "
            f"multisine, held or not ({gone / rate:.0f} s in): no linear truth"
        )
    A, B = _regression(flights, x0, names, rate)
    return Truth(A, B, x0, u0, aircraft, airspeed_kts, dict(plant), names, kind, hold)


def _regression(
    flights: list[tuple[np.ndarray, np.ndarray]], x0: np.ndarray, names: tuple[str, ...], rate
) -> tuple[np.ndarray, np.ndarray]:
    """Step 4 of the module docstring: ẋ = A x + B u from the odd responses (states,
    positions) by least squares, the kinematics held at their values."""
    derivatives, rows = [], []
    for x, u in flights:
        # x[k] is the state after step k, u[k] the positions held during it: the central
        # difference at k spans steps k and k + 1, so its inputs are their mean.
        derivatives.append((x[2:] - x[:-2]) * rate / 2)
        held = (u[1:-1] + u[2:]) / 2
        rows.append(np.hstack([x[1:-1], held, np.ones((len(x) - 2, 1))]))
    derivative, regressors = np.vstack(derivatives), np.vstack(rows)
    n, r = len(names), len(INPUTS)
    known = kinematic_rows(x0)
    attitude = [names.index(s) for s in ATTITUDE]
    rows_known = [names.index(s) for s in KNOWN_ROWS]
    free = [j for j in range(regressors.shape[1]) if j not in attitude]
    A, B = np.zeros((n, n)), np.zeros((n, r))
    A[rows_known] = known[rows_known]
    lhs = derivative - regressors[:, attitude] @ known[:, attitude].T
    scale = regressors[:, free].std(axis=0)
    scale[scale == 0] = 1.0
    theta, *_ = np.linalg.lstsq(regressors[:, free] / scale, lhs, rcond=None)
    theta = (theta / scale[:, None]).T  # (n, free)
    for i in range(n):
        if i in rows_known:
            continue
        row = np.zeros(regressors.shape[1])
        row[free] = theta[i]
        row[attitude] = known[i, attitude]
        A[i], B[i] = row[:n], row[n : n + r]
    return A, B


def _hold(
    x: np.ndarray,
    u: np.ndarray,
    commands: np.ndarray,
    x0: np.ndarray,
    names: tuple[str, ...],
    rate: float,
    weight: float,
) -> np.ndarray:
    """A feedback (inputs × states, normalised command per unit of state) that holds the
    aircraft near its trim under the multisine, designed on what it flew before it departed:
    the regression's model of that stretch (`_regression`), and the linear-quadratic
    regulator with each state weighted by `weight` over its spread there and each control by
    one over its reach there (as the weight tends to zero, the regulator moves each unstable
    pole to its mirror image and leaves the stable ones where they are: Anderson & Moore,
    *Optimal Control: Linear Quadratic Methods*, 1990). Each control's position per commanded
    unit, its least-squares gain over the stretch, turns the positions' feedback into
    commands. The held flights' regression is not biased by the feedback: their data have
    no noise, and the multisine keeps the inputs apart from the states."""
    if len(x) < MIN_STRETCH_S * rate:
        raise PlantError(
            f"the aircraft departs from its trim within {len(x) / rate:.1f} s of the truth's "
            "multisine: no linear truth"
        )
    A, B = _regression([(x, u)], x0, names, rate)
    # The altitude's column is the density's small effect: nothing a hold needs to act on.
    keep = [i for i, s in enumerate(names) if s != "alt"]
    A, B = A[np.ix_(keep, keep)], B[keep]
    spread = np.maximum(x[:, keep].std(axis=0), 1e-9)
    reach = np.maximum(np.abs(u).max(axis=0), 1e-9)
    Q = weight * np.diag(1.0 / spread**2)
    R = np.diag(1.0 / reach**2)
    try:
        P = scipy.linalg.solve_continuous_are(A, B, Q, R)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise PlantError(f"no hold for the truth's flight could be designed: {exc}") from exc
    K = np.linalg.solve(R, B.T @ P)  # positions per unit of state
    gain = (commands * u).sum(axis=0) / np.maximum((commands**2).sum(axis=0), 1e-12)
    if np.any(np.abs(gain) < 1e-9) or not np.all(np.isfinite(K)):
        raise PlantError("no hold for the truth's flight could be designed")
    out = np.zeros((len(INPUTS), len(names)))
    out[:, keep] = K / gain[:, None]
    return out


def climb_rate(x: np.ndarray) -> np.ndarray:
    """ḣ (m/s) of the eight aircraft states (..., 8) in OUTPUTS order, absolute, SI."""
    V, alpha, _, theta, beta, _, _, phi = np.moveaxis(x, -1, 0)
    u = V * np.cos(alpha) * np.cos(beta)
    v = V * np.sin(beta)
    w = V * np.sin(alpha) * np.cos(beta)
    return u * np.sin(theta) - v * np.sin(phi) * np.cos(theta) - w * np.cos(phi) * np.cos(theta)


def kinematic_rows(trim_state: np.ndarray) -> np.ndarray:
    """The kinematics' linear part at the trim in the truth's state order (n × n, BODY first,
    then the engine's): the rigid body's (agent.ident.aircraft.kinematics) in the first
    eight rows, the climb rate in the altitude's; zero where only forces act."""
    n = len(trim_state)
    out = np.zeros((n, n))
    x8 = np.asarray(trim_state[:8], dtype=float)
    out[:8, :8] = kinematic_jacobian(x8)
    step = 1e-6 * np.maximum(np.abs(x8), 1.0)
    for j in range(8):
        up, down = x8.copy(), x8.copy()
        up[j] += step[j]
        down[j] -= step[j]
        out[BODY.index("alt"), j] = (climb_rate(up) - climb_rate(down)) / (2 * step[j])
    return out


@dataclass(frozen=True)
class Check:
    """One test of the truth against JSBSim: TIC per output, and which outputs counted."""

    test: str
    tic: dict[str, float]
    rms: dict[str, float]
    counted: tuple[str, ...] = ()

    @property
    def worst(self) -> float:
        return max((self.tic[o] for o in self.counted), default=0.0)


def check_commands(name: str, rate_hz: float, amplitude: float = AMPLITUDE) -> np.ndarray:
    """One check's commands at the integration rate: a step on the throttle, a doublet on a
    surface."""
    t = np.arange(round(CHECK_S * rate_hz)) / rate_hz
    commands = np.zeros((len(t), len(INPUTS)))
    j = INPUTS.index(name)
    if name == "throttle":
        commands[t >= CHECK_START_S, j] = amplitude
    else:
        first = (t >= CHECK_START_S) & (t < CHECK_START_S + DOUBLET_S)
        second = (t >= CHECK_START_S + DOUBLET_S) & (t < CHECK_START_S + 2 * DOUBLET_S)
        commands[first, j], commands[second, j] = amplitude, -amplitude
    return commands


def check(truth: Truth, amplitude: float = AMPLITUDE) -> list[Check]:
    """A doublet on each surface and a throttle step, each as a ± pair (odd part), against the
    truth driven by the same positions; see the module docstring for which outputs count."""
    rate = float(truth.conditions.get("integration_hz", 200.0))
    checks = []
    for name in INPUTS:
        commands = check_commands(name, rate, amplitude)
        x, u, _ = odd_response(
            truth.aircraft, truth.airspeed_kts, commands, truth.hold, **truth.conditions
        )
        # The truth is driven by the positions: u[k] holds over step k, at whose end x[k] is
        # taken, so x[k] is the truth's state after k + 1 steps.
        predicted = truth.simulate(np.vstack([u, np.zeros(len(INPUTS))]), 1.0 / rate)[1:]
        tic = theil(x, predicted)
        rms = np.sqrt(np.mean(x**2, axis=0))
        checks.append(
            Check(
                name,
                {o: float(tic[k]) for k, o in enumerate(OUTPUTS)},
                {o: float(rms[k]) for k, o in enumerate(OUTPUTS)},
            )
        )
    largest = {o: max(c.rms[o] for c in checks) for o in OUTPUTS}
    return [
        replace(c, counted=tuple(o for o in OUTPUTS if c.rms[o] >= COUNTED_SHARE * largest[o]))
        for c in checks
    ]


def theil(y: np.ndarray, predicted: np.ndarray) -> np.ndarray:
    """Theil's inequality coefficient per column (0 where both are zero)."""
    num = np.sqrt(np.mean((y - predicted) ** 2, axis=0))
    den = np.sqrt(np.mean(y**2, axis=0)) + np.sqrt(np.mean(predicted**2, axis=0))
    return np.divide(num, den, out=np.zeros_like(num), where=den > 0)


def name_modes(
    A: np.ndarray, trim_state: np.ndarray, names: tuple[str, ...] = states("piston")
) -> dict[str, list[complex]]:
    """Short period, phugoid, Dutch roll, roll and spiral from the eigenvectors.

    Each state (`names`, the truth's) is scaled to a comparable size (airspeed by the trim
    airspeed, the engine's states by their trim values, altitude as the climb angle |λ| h / V
    it makes) and a mode belongs to the axis holding most of its scaled eigenvector. Modes
    mostly in the engine's states or the altitude are the engine's and the atmosphere's,
    not named. Longitudinal: the slowest oscillation is the phugoid; the short period is the
    fastest other oscillation or, when it is overdamped (the J-3 Cub), the two fastest real
    poles. Lateral: the oscillation is the Dutch roll, the fastest real pole the roll, and of
    the others the most purely lateral the spiral (the altitude's slow mode can lean lateral
    through the engine's torque)."""
    index = {s: k for k, s in enumerate(names)}
    engine = [k for k, s in enumerate(names) if s not in BODY]
    v0 = trim_state[index["Vt"]]
    scale = np.ones(len(names))
    scale[index["Vt"]] = scale[index["alt"]] = 1.0 / v0
    for k in engine:
        scale[k] = 1.0 / abs(trim_state[k]) if trim_state[k] else 1.0
    values, vectors = np.linalg.eig(A)
    groups: dict[str, list[complex]] = {"long": [], "lat": []}
    purity: dict[complex, float] = {}  # the share of its axis in each mode
    for lam, v in zip(values, vectors.T, strict=True):
        if lam.imag < -1e-9:
            continue
        w = np.abs(v) * scale
        w[index["alt"]] *= abs(lam)  # as a climb angle: ḣ / V
        share = {
            "long": np.linalg.norm(w[[index[s] for s in LONGITUDINAL]]),
            "lat": np.linalg.norm(w[[index[s] for s in LATERAL]]),
            "other": np.linalg.norm(w[[index["alt"], *engine]]),
        }
        axis = max(share, key=share.get)
        if axis != "other":
            groups[axis].append(complex(lam))
            purity[complex(lam)] = share[axis] / sum(share.values())
    named: dict[str, list[complex]] = {}
    pairs = sorted((s for s in groups["long"] if s.imag > 1e-9), key=abs)
    reals = sorted((s for s in groups["long"] if s.imag <= 1e-9), key=lambda s: -abs(s))
    if pairs:
        named["phugoid"] = [pairs[0]]
    named["short period"] = [pairs[-1]] if len(pairs) > 1 else reals[:2]
    lat_pairs = sorted((s for s in groups["lat"] if s.imag > 1e-9), key=abs)
    lat_reals = sorted((s for s in groups["lat"] if s.imag <= 1e-9), key=lambda s: -abs(s))
    if lat_pairs:
        named["Dutch roll"] = [lat_pairs[-1]]
    if lat_reals:
        named["roll"] = [lat_reals[0]]
    if len(lat_reals) > 1:  # the slow real pole that is most purely lateral
        named["spiral"] = [max(lat_reals[1:], key=lambda s: purity[s])]
    return named
