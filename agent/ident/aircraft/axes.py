"""The aircraft's two axes as the method sees them: the four measured states and the controls of
each (Klein & Morelli, *Aircraft System Identification*, AIAA 2006, ch. 7), found in a
record by the channels' roles."""

from __future__ import annotations

from collections.abc import Sequence

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
