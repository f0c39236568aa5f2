"""The aircraft's two axes as the method sees them: the four measured states and the controls of
each (Klein & Morelli, *Aircraft System Identification*, AIAA 2006, ch. 7), found in a
record by the channels' roles."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.ndimage

from agent.channels import POWER_ROLES
from agent.ident.aircraft import noise

# A measured rpm or thrust is the longitudinal axis's engine input where the record has one
# (agent.channels.POWER_ROLES): it acts at once, and the throttle's command is then set aside.
LONGITUDINAL = (("airspeed", "alpha", "q", "theta"), ("elevator", "throttle", "rpm", "thrust"))
LATERAL = (("beta", "p", "r", "phi"), ("aileron", "rudder"))
AXES = {"longitudinal": LONGITUDINAL, "lateral": LATERAL}
# The states whose equations are kinematics alone (no aerodynamic parameter): their rows of A
# and their columns elsewhere are fixed (`AxisProblem`) and the nonlinear rest of their
# kinematics is a known forcing (`prepare`).
ATTITUDE = ("theta", "phi")


def columns(names: Sequence[str | None], roles: Sequence[str]) -> list[int] | None:
    """Column of each role, or None when one is missing."""
    out = []
    for role in roles:
        if role not in names:
            return None
        out.append(list(names).index(role))
    return out


def axes_present(input_roles, output_roles) -> dict[str, tuple[list[int], list[int]]]:
    """The axes whose four outputs and at least one input the record carries."""
    present = {}
    for axis, (outs, ins) in AXES.items():
        states = columns(output_roles, outs)
        inputs = [list(input_roles).index(r) for r in ins if r in input_roles]
        if states is not None and inputs:
            present[axis] = (states, inputs)
    return present


# A control the record moved: somewhere below its noise floor's band its periodogram,
# smoothed over MOVED_BINS bins a side, stands MOVED times above its noise floor
# (agent.ident.aircraft.noise). A measured surface left at trim is its
# potentiometer's white noise, whose periodogram smoothed over 17 bins stays within about
# twice its floor at its largest; a manoeuvre's lines stand orders of magnitude above it
# (docs/identification.md).
MOVED = 10.0
MOVED_BINS = 8


def movement(columns: Sequence[np.ndarray]) -> float:
    """How far a control's records stand above their noise floor at best (`MOVED`): 0 for a
    control constant in every record, inf for one moved without noise (a command)."""
    best = 0.0
    for u in columns:
        if u.size < 4 or np.ptp(u) == 0:
            continue
        P = np.abs(np.fft.rfft(u - u.mean())) ** 2
        split = int(noise.FLOOR_FROM * P.size)
        floor = noise.floor(P)
        smooth = scipy.ndimage.uniform_filter1d(P[1:split], 2 * MOVED_BINS + 1, mode="nearest")
        peak = float(smooth.max()) if smooth.size else 0.0
        best = max(best, peak / floor if floor > 0 else np.inf if peak > 0 else 0.0)
    return best


@dataclass(frozen=True)
class Moved:
    """What of a record the method identifies: the controls it moved, the axes they drive
    (`present`, as `axes_present`'s), and for what it leaves out, why."""

    present: dict[str, tuple[list[int], list[int]]]
    controls_left_out: dict[int, str]  # input column → why
    axes_left_out: dict[str, str]  # axis → why


def moved_axes(
    batch: Sequence,
    input_names: Sequence[str],
    input_roles: Sequence[str | None],
    present: dict[str, tuple[list[int], list[int]]],
) -> Moved:
    """The axes of `present` with the controls the batch moved (`movement` ≥ MOVED). A control
    left at trim is left out (its effect cannot be identified; as an input it would be fitted
    to its sensor's noise); an axis none of whose controls moved is left out whole: a
    longitudinal manoeuvre moves the lateral states only through coupling and noise, and
    modes fitted to those are wrong with standard errors that say otherwise
    (docs/identification.md). A measured rpm or thrust is the engine's response, not a
    control: it is kept, and its moving counts as the axis's excitation (the throttle moved it)."""
    kept: dict[str, tuple[list[int], list[int]]] = {}
    controls_left_out: dict[int, str] = {}
    axes_left_out: dict[str, str] = {}
    for axis, (states, inputs) in present.items():
        moves = {j: movement([np.asarray(e.u)[:, j] for e in batch]) for j in inputs}
        if all(moves[j] < MOVED for j in inputs):
            names = ", ".join(input_names[j] for j in inputs)
            axes_left_out[axis] = (
                f"the {axis} controls ({names}) moved no more than their sensors' noise (at "
                f"most {max(moves.values()):.2g}× its floor, {MOVED:g}× needed)"
            )
            continue
        quiet = [j for j in inputs if moves[j] < MOVED and input_roles[j] not in POWER_ROLES]
        for j in quiet:
            how = "constant" if moves[j] == 0 else f"at most {moves[j]:.2g}× its noise floor"
            controls_left_out[j] = (
                f"{input_names[j]} not moved by this record ({how}; {MOVED:g}× needed): left "
                "out of the model, its effect not identified"
            )
        kept[axis] = (states, [j for j in inputs if j not in quiet])
    return Moved(kept, controls_left_out, axes_left_out)
