"""JSBSim as the plant: trimmed flight, surface commands in, aircraft states out, and its own
linearisation as the truth an identified model is measured against.

JSBSim (Berndt et al., https://jsbsim.sourceforge.net; the `jsbsim` pip package carries the
aircraft) integrates here at 200 Hz, a whole multiple of the 50 and 100 Hz record rates. The
J-3 Cub is the default aircraft: the nearest relative of the thesis's Super Cub in JSBSim's
fleet. Commands are JSBSim's normalised ones
(−1 … 1; throttle 0 … 1) held over each step, added to the trim values found by JSBSim's
trim routine. Outputs follow agent.channels in SI units: airspeed Vt (m/s), α, β, θ, φ (rad),
p, q, r (rad/s).

Turbulence is JSBSim's MIL-F-8785C Dryden model (turb-type 3), seeded through
`simulation/randomseed` so runs repeat. `turbulence` is an intensity in units of light
turbulence: a wind of 5 ft/s at 20 ft (W20), so `turbulence=1` is
W20 = 5 ft/s and σ_w = 0.1·W20 = 0.5 ft/s at low altitude. Below 1000 ft above the ground
(where the sim flies) the Dryden intensities depend on W20 alone; JSBSim's severity index,
which only acts above 1000 ft, is set to light (1) up to `turbulence=1` and grows with it.
MIL-F-8785C's own "light" category is W20 = 15 kt (25.3 ft/s): `turbulence≈5`.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from agent.channels import INPUT_ROLES

FT = 0.3048
KT = 0.514444
# The inputs are agent.channels's input roles, each on JSBSim's normalised command of its name.
INPUTS = INPUT_ROLES
COMMAND_PROPERTY = {name: f"fcs/{name}-cmd-norm" for name in INPUTS}
# Output channel → (JSBSim property, scale to SI).
OUTPUT_PROPERTY = {
    "Vt": ("velocities/vt-fps", FT),
    "alpha": ("aero/alpha-rad", 1.0),
    "q": ("velocities/q-rad_sec", 1.0),
    "theta": ("attitude/theta-rad", 1.0),
    "beta": ("aero/beta-rad", 1.0),
    "p": ("velocities/p-rad_sec", 1.0),
    "r": ("velocities/r-rad_sec", 1.0),
    "phi": ("attitude/phi-rad", 1.0),
}
OUTPUTS = tuple(OUTPUT_PROPERTY)
# JSBSim's linearisation states and inputs that correspond to our channels.
LINEAR_STATES = {
    "Vt": "Vt",
    "alpha": "Alpha",
    "q": "Q",
    "theta": "Theta",
    "beta": "Beta",
    "p": "P",
    "r": "R",
    "phi": "Phi",
}
LINEAR_INPUTS = {"throttle": "ThtlCmd", "elevator": "DeCmd", "aileron": "DaCmd", "rudder": "DrCmd"}
# JSBSim integrates the body rates and the attitude by rectangular Euler by default (1), which
# makes the sampled attitude lag the sampled rates by half a step. On the J-3 Cub that
# is 2.5 ms at 200 Hz, and the state-derivative regression of the truth read it as
# θ̇ = 1.018 q + 0.060 α instead of θ̇ = q. A real aircraft has no such lag. The second-order
# Adams–Bashforth methods (3) are what JSBSim already uses for the translational rates.
INTEGRATORS = {
    "simulation/integrator/rate/rotational": 3,
    "simulation/integrator/position/rotational": 3,
}
LIGHT_TURBULENCE_WIND_FPS = 5.0  # light turbulence: W20 = 5 ft/s
# The powerplant's kinds, told from the properties JSBSim gives the first engine: a piston engine
# (engine speed and manifold pressure), a turboprop (a gas generator's N1 driving a propeller),
# a turbine's direct thrust (spools N1 and N2, no propeller), or none (a glider). Each kind's
# slow states, for the truth's regression (agent.sim.truth): (name, property).
ENGINE_STATES = {
    "piston": (("rpm", "propulsion/engine/engine-rpm"), ("map", "propulsion/engine/map-inhg")),
    "turboprop": (("rpm", "propulsion/engine/engine-rpm"), ("n1", "propulsion/engine/n1")),
    # JSBSim's turbine moves its spools at a limited rate toward the throttle's setting: a 3 %
    # step is reached in 70 ms (the T-6 at 150 kt), so its thrust follows the throttle at once
    # and the spools are no slow state (as states, the truth's throttle check scored TIC 0.11).
    "turbine": (),
    "none": (),
}
# An unpowered aircraft flies a steady glide, found by Newton's method on the longitudinal
# accelerations (JSBSim's own trim needs a throttle for u̇): the iterations allowed, and the
# residual accepted (ft/s², and rad/s² for q̇).
GLIDE_ITERATIONS = 30
GLIDE_RESIDUAL = 1e-6
# JSBSim's accelerations the trims drive to zero (its `accelerations/` properties).
LONGITUDINAL_ACCELERATIONS = ("udot-ft_sec2", "wdot-ft_sec2", "qdot-rad_sec2")
LATERAL_ACCELERATIONS = ("vdot-ft_sec2", "pdot-rad_sec2", "rdot-rad_sec2")
# JSBSim's own trim does not trim every powered aircraft. Its steady-state search runs the
# engines without refreshing their inputs from the flight controls (JSBSim issue 1440, "udot
# doesn't appear to be trimmable"), and its turboprop engine (FGTurboProp) gives no power while
# time is frozen and drops its gas generator to idle at the first step after any frozen
# evaluation (FGTurboProp::Calculate, JSBSim 1.3: the PC-7's trim fails, and the DHC-6's left it
# at idle power, 9 kt slower within 6 s). Such aircraft are trimmed here (`_trim_powered`):
# Newton's method on α, elevator, throttle, aileron, rudder and β (the propeller's torque and
# slipstream) for level flight, each residual read with the engines settled, the fuel frozen;
# accepted below POWERED_RESIDUAL (ft/s², rad/s²), from START_THROTTLE.
START_THROTTLE = 0.6
POWERED_RESIDUAL = 1e-5
MAX_TRIM_STEP = np.array([2.0, 0.1, 0.1, 0.1, 0.1, 2.0])
# The engines run to their steady state with the airframe held: JSBSim's four integrators off
# (0), so time passes for the engines, the propellers and the flight controls, not for the
# motion. Steady: the total thrust moved by less than ENGINE_STEADY of it (of 100 lbf at least)
# over ENGINE_CHECK_S, tight enough for the trim's finite differences; ENGINE_SETTLE_S at most
# (the PC-7's gas generator takes about 20 s from idle).
ENGINE_CHECK_S = 1.0
ENGINE_STEADY = 1e-9
ENGINE_SETTLE_S = 120.0
HELD_INTEGRATORS = (
    "simulation/integrator/rate/rotational",
    "simulation/integrator/rate/translational",
    "simulation/integrator/position/rotational",
    "simulation/integrator/position/translational",
)
# What a trim found by the plant must leave, read with the engines running after it (ft/s² for
# u̇, v̇, ẇ; rad/s² for ṗ, q̇, ṙ): 0.002 g, and a pitch or roll rate of 0.1°/s gained per second.
TRIM_CHECK = (0.05, 0.0017)
# The surfaces' positions as state() reads them, per control (see `_position_maps`).
POSITION_PROPERTIES = {
    "throttle": ("fcs/throttle-pos-norm",),
    "elevator": ("fcs/elevator-pos-deg",),
    "aileron": ("fcs/left-aileron-pos-deg", "fcs/right-aileron-pos-deg"),
    "rudder": ("fcs/rudder-pos-deg",),
}
MAP_POINTS = 81
# The throttles a multi-engine aircraft starts its trim from (the plant's constructor).
TWIN_START_THROTTLE = 0.6


@contextlib.contextmanager
def _stdout_to_stderr():
    """Point file descriptor 1 at 2 for a while: JSBSim's C++ prints its banner with printf,
    below Python's sys.stdout, so only the descriptor itself can move it."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        os.dup2(2, 1)
        yield
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


class PlantError(RuntimeError):
    """JSBSim could not load, trim or linearise the aircraft."""


def powerplant(fdm) -> tuple[str, int]:
    """The kind of the aircraft's engines (ENGINE_STATES) and how many there are."""
    engines = int(fdm.get_propulsion().get_num_engines())
    if engines == 0:
        return "none", 0
    names = {k.split(" ")[0] for k in fdm.get_property_catalog()}
    if "propulsion/engine/map-inhg" in names:
        return "piston", engines
    if "propulsion/engine/propeller-rpm" in names:
        return "turboprop", engines
    return "turbine", engines


@dataclass(frozen=True)
class Linearisation:
    """JSBSim's own linear model at the trim point (continuous, its units and state order)."""

    A: np.ndarray
    B: np.ndarray
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]

    def eigenvalues(
        self, exclude: tuple[str, ...] = ("Psi", "Latitude", "Longitude")
    ) -> np.ndarray:
        """Eigenvalues of the dynamics without the states nothing depends on (heading and
        position: pure integrators that no identification from body-axis data can see)."""
        keep = [i for i, n in enumerate(self.state_names) if n not in exclude]
        return np.linalg.eigvals(self.A[np.ix_(keep, keep)])


class Plant:
    """One JSBSim aircraft in trimmed straight and level flight."""

    def __init__(
        self,
        aircraft: str = "J3Cub",
        *,
        airspeed_kts: float = 60.0,
        altitude_ft: float = 1000.0,
        turbulence: float = 0.0,
        seed: int = 0,
        heading_deg: float = 0.0,
        integration_hz: float = 200.0,
        linearise: bool = True,
    ):
        import jsbsim  # imported here: the identification core does not need it

        # JSBSim raises its own errors (a model that reads a property only FlightGear
        # provides fails at its initial conditions: the Dr.I's pushback, the L-17's flaps).
        self._jsbsim_error = jsbsim.BaseError
        with _stdout_to_stderr():  # JSBSim's banner and complaints: stdout is for `--json`
            try:
                self._load(jsbsim, aircraft, integration_hz, seed, altitude_ft, airspeed_kts)
                self._heading(heading_deg)
                self._start(aircraft, airspeed_kts)
                # FGLinearization at the trim (slow on some aircraft: ten seconds for the
                # PA-28); agent.sim.truth explains why it is not the truth identified models
                # are judged by. JSBSim 1.3.3's FGLinearization crashes the process (a
                # segmentation fault) on an aircraft without engines: a glider has none.
                self.linearisation = self._linearise() if linearise and self.engines else None
                self._finish_trim(aircraft, airspeed_kts)
            except jsbsim.BaseError as exc:
                text = str(exc).strip()
                if "does not exist" in text:  # a property only FlightGear provides
                    text += (
                        " (a model that needs FlightGear's properties does not fly in JSBSim alone)"
                    )
                raise PlantError(f"JSBSim could not fly {aircraft}: {text}") from exc
        self.trim = {
            name: float(self.fdm[self.commands[name][0]]) if name in self.commands else 0.0
            for name in COMMAND_PROPERTY
        }
        # The true airspeed at the trim (m/s): what the air data measure, above the calibrated
        # airspeed the trim was asked for by the density's ratio (5 % at 3000 ft).
        self.true_airspeed = float(self.fdm["velocities/vt-fps"]) * FT
        # Each command's ramp (from, to) over _ramp_steps steps, _ramp_done of them flown
        # (set_normalised); _settled: the surfaces are where the ramps have them now.
        self._ramp = {name: (value, value) for name, value in self.trim.items()}
        self._ramp_steps, self._ramp_done, self._settled = 1, 1, True
        self._positions: dict[str, float] | None = None  # where `_settle` put the surfaces
        if turbulence > 0:
            self.fdm["atmosphere/turb-type"] = 3
            self.fdm["atmosphere/turbulence/milspec/severity"] = int(
                np.clip(np.ceil(turbulence), 1, 7)
            )
            self.fdm["atmosphere/turbulence/milspec/windspeed_at_20ft_AGL-fps"] = (
                LIGHT_TURBULENCE_WIND_FPS * turbulence
            )
            # A mean wind too small to matter, so that JSBSim keeps the turbulence axes' azimuth
            # (with none it resets it to north) and `step` can align them with the aircraft.
            self.fdm["atmosphere/wind-mag-fps"] = 1e-6
        self.turbulence = turbulence
        # Time from the trim: the engines may have run before it (`_settle_engines`).
        self._t0 = float(self.fdm.get_sim_time())

    def _load(self, jsbsim, aircraft, integration_hz, seed, altitude_ft, airspeed_kts) -> None:
        self.fdm = jsbsim.FGFDMExec(None)
        self.fdm.set_debug_level(0)
        if not self.fdm.load_model(aircraft):
            raise PlantError(f"JSBSim has no aircraft {aircraft!r}")
        self.fdm.set_dt(1.0 / integration_hz)
        for prop, method in INTEGRATORS.items():
            self.fdm[prop] = method
        self.fdm["simulation/randomseed"] = seed
        self.fdm["atmosphere/randomseed"] = seed
        self.fdm["ic/h-sl-ft"] = altitude_ft
        self.fdm["ic/vc-kts"] = airspeed_kts
        self.fdm["ic/gamma-deg"] = 0.0
        self.kind, self.engines = powerplant(self.fdm)
        names = {k.split(" ")[0] for k in self.fdm.get_property_catalog()}
        # JSBSim's turboprop engine (FGTurboProp, the only engine with a torque limiter) drops
        # to idle after a frozen evaluation: the plant trims it itself and never leaves it one.
        self._frozen_idles = "propulsion/engine/ielu_intervent" in names
        # The controls this aircraft has (a glider has no throttle), each on its JSBSim
        # commands: the throttle on every engine's, as one lever moves them all.
        self.commands = {
            name: (prop,) for name, prop in COMMAND_PROPERTY.items() if name != "throttle"
        }
        if self.engines:
            self.commands["throttle"] = tuple(
                f"fcs/throttle-cmd-norm[{k}]" if k else "fcs/throttle-cmd-norm"
                for k in range(self.engines)
            )

    def _heading(self, heading_deg: float) -> None:
        self.fdm["ic/psi-true-deg"] = heading_deg
        if not self.fdm.run_ic():
            raise PlantError("JSBSim rejected the initial conditions")
        self.dt = self.fdm.get_delta_t()

    def _start(self, aircraft: str, airspeed_kts: float) -> None:
        """The engines running and the aircraft trimmed: JSBSim's trim where it can, the
        plant's own where it cannot (module constants above), a glide without engines."""
        self.glide_deg, self._own_trim = None, False
        if not self.engines:
            self._trim_glide(aircraft, airspeed_kts)
            return
        # Every engine's mixture rich, and on a multi-engine aircraft every throttle open to
        # TWIN_START_THROTTLE (the trim moves it from there): JSBSim starts the second engine
        # lean and closed, dead at the trim, which then fails. A turboprop's pitch lever
        # (advance) forward, to its governor's highest speed: at JSBSim's default (0) the
        # PC-7's propeller windmills at 150 kt whatever the throttle.
        for k in range(self.engines):
            self.fdm[f"fcs/mixture-cmd-norm[{k}]"] = 1.0
            if self._frozen_idles:
                self.fdm[f"fcs/advance-cmd-norm[{k}]"] = 1.0
            if self.engines > 1:
                self.fdm[f"fcs/throttle-cmd-norm[{k}]"] = TWIN_START_THROTTLE
        self.fdm["propulsion/set-running"] = -1
        self.fdm.run()
        if self._frozen_idles:
            self._trim_powered(aircraft, airspeed_kts)
            return
        try:
            self.fdm["simulation/do_simple_trim"] = 1
        except self._jsbsim_error:  # JSBSim raises its own TrimFailureException
            self._trim_powered(aircraft, airspeed_kts)

    def _finish_trim(self, aircraft: str, airspeed_kts: float) -> None:
        """After a trim of the plant's own: the surfaces' maps where a frozen evaluation idles
        the engine, then the engines run to their steady state at the trim (the airframe
        held), and the trim is checked with them running."""
        self._maps = self._position_maps() if self._frozen_idles else None
        if not self._own_trim:
            return
        self._settle_engines()
        linear = np.abs(self._accelerations(("udot-ft_sec2", "vdot-ft_sec2", "wdot-ft_sec2")))
        angular = np.abs(self._accelerations(("pdot-rad_sec2", "qdot-rad_sec2", "rdot-rad_sec2")))
        if max(linear) > TRIM_CHECK[0] or max(angular) > TRIM_CHECK[1]:
            raise PlantError(
                f"could not trim {aircraft} at {airspeed_kts:g} kt: with the engines running "
                f"the trim leaves accelerations u̇, v̇, ẇ {np.round(linear, 3).tolist()} ft/s², "
                f"ṗ, q̇, ṙ {np.round(angular, 4).tolist()} rad/s²"
            )

    def _throttle(self, value: float) -> None:
        for prop in self.commands["throttle"]:
            self.fdm[prop] = value

    def _settle_engines(self, strict: bool = True) -> float:
        """Run the engines to their steady state at the present flight condition, the
        airframe held (HELD_INTEGRATORS off); returns the total thrust (lbf). Not `strict`:
        where they do not settle, they stop at ENGINE_SETTLE_S (the trim's search goes on from
        there; the trim found is checked strictly, and a PlantError says how far they were
        from steady)."""
        f = self.fdm
        saved = {prop: float(f[prop]) for prop in HELD_INTEGRATORS}
        check = max(1, round(ENGINE_CHECK_S / self.dt))
        thrust = [f"propulsion/engine[{k}]/thrust-lbs" for k in range(self.engines)]
        for prop in HELD_INTEGRATORS:
            f[prop] = 0
        try:
            last = None
            for _ in range(round(ENGINE_SETTLE_S / ENGINE_CHECK_S)):
                for _ in range(check):
                    if not f.run():
                        raise PlantError("JSBSim stopped")
                total = sum(float(f[prop]) for prop in thrust)
                if last is not None and abs(total - last) <= ENGINE_STEADY * max(abs(total), 100.0):
                    return total
                before, last = last if last is not None else total, total
        finally:
            for prop, method in saved.items():
                f[prop] = method
        if not strict:
            return total
        raise PlantError(
            f"the engines did not settle within {ENGINE_SETTLE_S:g} s (thrust {total:.0f} lbf, "
            f"moving {total - before:+.2g} lbf/s)"
        )

    def _steady(self, x: np.ndarray, airspeed_kts: float) -> np.ndarray:
        """The accelerations u̇, ẇ, q̇ (ft/s², rad/s²) of the aircraft set at `x` = (α, γ in
        degrees, elevator) at the airspeed, time frozen."""
        f = self.fdm
        f["ic/alpha-deg"], f["ic/gamma-deg"] = x[0], x[1]
        f["ic/vc-kts"] = airspeed_kts
        f["fcs/elevator-cmd-norm"] = x[2]
        if not f.run_ic():
            raise PlantError("JSBSim rejected the initial conditions")
        self._frozen()  # the flight controls at the command, time frozen
        return self._accelerations(LONGITUDINAL_ACCELERATIONS)

    def _accelerations(self, names: tuple[str, ...]) -> np.ndarray:
        return np.array([float(self.fdm[f"accelerations/{name}"]) for name in names])

    def _newton(self, x: np.ndarray, airspeed_kts: float) -> np.ndarray | None:
        """Newton's method (central-difference Jacobian) from `x` on `_steady`; the solution,
        the aircraft left there, or None where it does not converge within bounds."""
        step, bound = np.array([1e-3, 1e-3, 1e-4]), np.array([20.0, 30.0, 1.0])
        for _ in range(GLIDE_ITERATIONS):
            r = self._steady(x, airspeed_kts)
            if np.max(np.abs(r)) < GLIDE_RESIDUAL:
                return x
            J = np.empty((len(x), len(x)))
            for j in range(len(x)):
                d = np.zeros(len(x))
                d[j] = step[j]
                J[:, j] = (
                    self._steady(x + d, airspeed_kts) - self._steady(x - d, airspeed_kts)
                ) / (2 * step[j])
            try:
                x = x - np.linalg.solve(J, r)
            except np.linalg.LinAlgError:
                return None
            if not np.all(np.isfinite(x)) or np.any(np.abs(x) > bound):
                return None
        return x if np.max(np.abs(self._steady(x, airspeed_kts))) < GLIDE_RESIDUAL else None

    def _trim_glide(self, aircraft: str, airspeed_kts: float) -> None:
        """A steady wings-level glide at the airspeed: α, the flight-path angle γ and the
        elevator such that u̇, ẇ and q̇ vanish (`_newton`); the aircraft is assumed symmetric
        (no lateral trim). Left at the solution."""
        self._own_trim = False
        x = self._newton(np.array([2.0, -3.0, 0.0]), airspeed_kts)
        if x is None:
            last = self._accelerations(LONGITUDINAL_ACCELERATIONS)
            raise PlantError(
                f"could not trim {aircraft} in a steady glide at {airspeed_kts:g} kt "
                f"(residual accelerations {np.array2string(last, precision=3)})"
            )
        self.glide_deg = float(x[1])

    def _trim_powered(self, aircraft: str, airspeed_kts: float) -> None:
        """Straight and level flight with the engines as they run (module constants above):
        Newton's method on α, elevator, throttle, aileron, rudder and β for u̇, ẇ, q̇, v̇, ṗ, ṙ
        at γ = 0, each read after the engines settle at the flight condition (`_running`).
        Left at the solution, the engines settled."""
        self._own_trim = True
        f = self.fdm
        frozen_fuel = float(f["propulsion/fuel_freeze"])
        f["propulsion/fuel_freeze"] = 1  # the same mass at every evaluation
        try:
            y = np.array([2.0, 0.0, START_THROTTLE, 0.0, 0.0, 0.0])
            step = np.array([1e-3, 1e-4, 1e-3, 1e-4, 1e-4, 1e-3])
            low = np.array([-20.0, -1.0, 0.0, -1.0, -1.0, -20.0])
            high = np.array([20.0, 1.0, 1.0, 1.0, 1.0, 20.0])
            for _ in range(GLIDE_ITERATIONS):
                r = self._running(y, airspeed_kts)
                if np.max(np.abs(r)) < POWERED_RESIDUAL:
                    return
                J = np.empty((6, 6))
                for j in range(6):
                    d = np.zeros(6)
                    d[j] = step[j]
                    ahead, behind = (
                        self._running(y + d, airspeed_kts),
                        self._running(y - d, airspeed_kts),
                    )
                    J[:, j] = (ahead - behind) / (2 * step[j])
                try:
                    change = np.linalg.solve(J, r)
                except np.linalg.LinAlgError:
                    break
                # Damped: no step beyond MAX_TRIM_STEP in any unknown (a throttle pushed to
                # its stop can hold an engine's torque limiter in a limit cycle: the DHC-6).
                change *= min(
                    1.0, float(np.min(MAX_TRIM_STEP / np.maximum(np.abs(change), 1e-300)))
                )
                y = np.clip(y - change, low, high)
                if not np.all(np.isfinite(y)):
                    break
            r = self._running(y, airspeed_kts)
            if np.max(np.abs(r)) >= POWERED_RESIDUAL:
                throttle = "full throttle" if y[2] >= 1.0 else "idle" if y[2] <= 0.0 else ""
                raise PlantError(
                    f"could not trim {aircraft} at {airspeed_kts:g} kt in level flight "
                    f"(JSBSim's own trim failed too)"
                    f"{': it needs beyond ' + throttle if throttle else ''}"
                    f"; residual accelerations {np.array2string(r, precision=4)}"
                )
        finally:
            f["propulsion/fuel_freeze"] = frozen_fuel

    def _running(self, y: np.ndarray, airspeed_kts: float) -> np.ndarray:
        """The accelerations (u̇, ẇ, q̇, v̇, ṗ, ṙ: ft/s², rad/s²) of the aircraft in level flight
        at the airspeed with y = (α°, elevator, throttle, aileron, rudder, β°), read with the
        engines settled there (`_settle_engines`: the airframe held)."""
        f = self.fdm
        f["ic/alpha-deg"], f["ic/gamma-deg"], f["ic/beta-deg"] = y[0], 0.0, y[5]
        f["ic/vc-kts"] = airspeed_kts
        f["fcs/elevator-cmd-norm"] = y[1]
        self._throttle(float(y[2]))
        f["fcs/aileron-cmd-norm"], f["fcs/rudder-cmd-norm"] = y[3], y[4]
        if not f.run_ic():
            raise PlantError("JSBSim rejected the initial conditions")
        self._settle_engines(strict=False)
        return self._accelerations(LONGITUDINAL_ACCELERATIONS + LATERAL_ACCELERATIONS)

    def _position_maps(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Each control's surface positions (POSITION_PROPERTIES) as JSBSim's flight controls
        give them across the command's range, the others at the trim, by frozen evaluations:
        where one idles the engine (FGTurboProp), `_settle` reads the surfaces from these
        instead. Checked with every control moved at once (flight controls that mix the
        commands, or that depend on anything else, would fail it)."""
        f = self.fdm
        at_trim = {name: float(f[props[0]]) for name, props in self.commands.items()}
        maps = {}
        for name in self.commands:
            grid = np.linspace(0.0 if name == "throttle" else -1.0, 1.0, MAP_POINTS)
            values = np.empty((MAP_POINTS, len(POSITION_PROPERTIES[name])))
            for i, command in enumerate(grid):
                self._set(name, command)
                self._frozen()
                values[i] = [float(f[prop]) for prop in POSITION_PROPERTIES[name]]
            self._set(name, at_trim[name])
            maps[name] = (grid, values)
        moved = {name: float(np.clip(v + 0.37, -1.0, 1.0)) for name, v in at_trim.items()}
        for name, value in moved.items():
            self._set(name, value)
        self._frozen()
        for name, (grid, values) in maps.items():
            for j, prop in enumerate(POSITION_PROPERTIES[name]):
                mapped = np.interp(moved[name], grid, values[:, j])
                if abs(mapped - float(f[prop])) > 1e-6 * max(np.ptp(values[:, j]), 1.0):
                    raise PlantError(
                        f"{prop} is not a fixed function of the {name} command alone, which "
                        "the plant needs of an aircraft with JSBSim's turboprop engine"
                    )
        for name, value in at_trim.items():
            self._set(name, value)
        self._frozen()
        return maps

    def _frozen(self) -> None:
        """JSBSim's models evaluated at the present commands and states, time frozen."""
        self.fdm.suspend_integration()
        try:
            if not self.fdm.run():
                raise PlantError("JSBSim stopped")
        finally:
            self.fdm.resume_integration()

    def _linearise(self) -> Linearisation:
        import jsbsim

        lin = jsbsim.FGLinearization(self.fdm)
        # FGLinearization leaves the integration step at 0 (a frozen simulation): restore it.
        self.fdm.set_dt(self.dt)
        return Linearisation(
            A=np.array(lin.system_matrix),
            B=np.array(lin.input_matrix),
            state_names=tuple(lin.x_names),
            input_names=tuple(lin.u_names),
        )

    @property
    def on_ground(self) -> bool:
        """The aircraft is on or below the ground: a gear unit carries weight, or its centre of
        gravity is below the terrain (JSBSim flies on through it after a hard impact)."""
        return bool(self.fdm["gear/wow"]) or float(self.fdm["position/h-agl-ft"]) <= 0.0

    @property
    def time(self) -> float:
        return float(self.fdm.get_sim_time()) - self._t0

    def command(self, deltas: Mapping[str, float]) -> None:
        """Set each command to trim + delta (normalised units), clipped to JSBSim's range, at
        once (held over the following steps)."""
        for name, delta in deltas.items():
            value = self._clip(name, self.trim[name] + delta)
            self._ramp[name] = (value, value)
            self._set(name, value)

    def set_normalised(self, commands: Mapping[str, float], steps: int = 1) -> None:
        """Move commands to absolute normalised values (servo outputs), clipped to range,
        over the next `steps` integration steps.

        A servo moves its surface continuously, not in a jump at the autopilot's tick, and
        a potentiometer samples where the surface is. So each command ramps from where it is
        to its new value. Every step holds the ramp's value at the step's middle: a
        staircase centred on the ramp, which the surface follows to second order. `state()`
        reads the surfaces where the ramp has them at that instant. Held over the tick
        instead, with the position read at its end, the surfaces would act half a tick
        (5 ms) before the record says. Identification takes sampled positions at face value,
        and on the J-3 Cub, whose short period is two real poles close together, that moved
        them by 30 %."""
        if steps < 1:
            raise PlantError(f"a ramp takes at least one step, not {steps}")
        now = self._fraction()
        for name, value in commands.items():
            self._ramp[name] = (self._value(name, now), self._clip(name, value))
        self._ramp_steps, self._ramp_done, self._settled = steps, 0, False

    def _set(self, name: str, value: float) -> None:
        """One control's JSBSim commands (none: the aircraft has no such control)."""
        for prop in self.commands.get(name, ()):
            self.fdm[prop] = value

    @staticmethod
    def _clip(name: str, value: float) -> float:
        return float(np.clip(value, 0.0 if name == "throttle" else -1.0, 1.0))

    def _fraction(self) -> float:
        return min(self._ramp_done / self._ramp_steps, 1.0)

    def _value(self, name: str, fraction: float) -> float:
        start, end = self._ramp[name]
        return start + (end - start) * min(fraction, 1.0)

    def _settle(self) -> None:
        """Put the surfaces where the ramps have them now: JSBSim's flight controls evaluated
        at the commands' present values without integrating (time and states stay)."""
        if self._settled:
            return
        now = self._fraction()
        for name in self._ramp:
            self._set(name, self._value(name, now))
        if self._maps is None:
            self._frozen()
        else:  # a frozen evaluation would idle the engine: the positions from the maps
            self._positions = {
                prop: float(np.interp(self._value(name, now), grid, values[:, j]))
                for name, (grid, values) in self._maps.items()
                for j, prop in enumerate(POSITION_PROPERTIES[name])
            }
        self._settled = True

    def state(self) -> dict[str, float]:
        """The truth the sensors measure: attitude, rates, air data, position, velocity,
        body accelerations (m/s², specific force), surface positions (deg), engine RPM."""
        self._settle()
        f = self.fdm
        held = self._positions or {}

        def position(prop: str) -> float:
            return held[prop] if prop in held else float(f[prop])

        values = {name: float(f[prop]) * scale for name, (prop, scale) in OUTPUT_PROPERTY.items()}
        values.update(
            psi=float(f["attitude/psi-rad"]),
            alt=float(f["position/h-sl-meters"]),
            agl=float(f["position/h-agl-ft"]) * FT,
            lat=float(f["position/lat-geod-deg"]),
            lon=float(f["position/long-gc-deg"]),
            vn=float(f["velocities/v-north-fps"]) * FT,
            ve=float(f["velocities/v-east-fps"]) * FT,
            vd=float(f["velocities/v-down-fps"]) * FT,
            ax=float(f["accelerations/a-pilot-x-ft_sec2"]) * FT,
            ay=float(f["accelerations/a-pilot-y-ft_sec2"]) * FT,
            az=float(f["accelerations/a-pilot-z-ft_sec2"]) * FT,
            # Eq. 3.1 with JSBSim's signs: δA = ½(δA_R − δA_L) from its left/right positions.
            aileron_left=position("fcs/left-aileron-pos-deg"),
            aileron_right=position("fcs/right-aileron-pos-deg"),
            elevator=position("fcs/elevator-pos-deg"),
            rudder=position("fcs/rudder-pos-deg"),
            throttle=position("fcs/throttle-pos-norm") if self.engines else 0.0,
        )
        if self.kind in ("piston", "turboprop"):  # the surface box's tachometer
            values["rpm"] = float(f["propulsion/engine/engine-rpm"])
        values["aileron"] = 0.5 * (values["aileron_right"] - values["aileron_left"])
        return values

    def step(self) -> None:
        if self.turbulence > 0:
            # MIL-F-8785C's Dryden gusts are defined along and across the flight path, and its
            # rotational gusts about the body axes: q_g from the vertical gust's gradient along
            # the path, p_g (independent) across it. JSBSim generates them in the mean wind's
            # axes, north without wind, and turns p_g, q_g as a north/east vector into body
            # axes. An aircraft heading 59° then felt 86 % of the random roll gust as a pitch
            # gust (body q_g: 18 % explained by s·α_g/(1 + τs), 99 % with the axes aligned). So
            # the axes follow the heading: −ψ in JSBSim's sign for this angle, which puts the
            # u gust along the body's x.
            self.fdm["atmosphere/psiw-rad"] = float(-self.fdm["attitude/psi-rad"]) % (2 * np.pi)
        middle = (self._ramp_done + 0.5) / self._ramp_steps
        for name in self._ramp:
            self._set(name, self._value(name, middle))
        self._ramp_done += 1
        self._settled = middle >= 1.0  # the step held the ramp's end: the surfaces are there
        self._positions = None
        try:
            running = self.fdm.run()
        except self._jsbsim_error as exc:
            raise PlantError(f"JSBSim stopped: {str(exc).strip()}") from exc
        if not running:
            raise PlantError("JSBSim stopped")

    def outputs(self) -> np.ndarray:
        """The aircraft's outputs in OUTPUTS order, SI units."""
        return np.array([float(self.fdm[prop]) * scale for prop, scale in OUTPUT_PROPERTY.values()])

    def fly(self, inputs: np.ndarray, sample_time: float) -> np.ndarray:
        """Play `inputs` (samples × INPUTS, deltas from trim) at `sample_time`, holding each
        sample, and return the outputs sampled at the same instants (before the sample acts)."""
        steps = round(sample_time / self.dt)
        if steps < 1 or abs(steps * self.dt - sample_time) > 1e-9:
            raise PlantError(
                f"sample time {sample_time} s is not a whole number of {self.dt} s steps"
            )
        out = np.empty((inputs.shape[0], len(OUTPUTS)))
        for k, row in enumerate(inputs):
            out[k] = self.outputs()
            self.command(dict(zip(INPUTS, row, strict=True)))
            for _ in range(steps):
                self.step()
        return out
