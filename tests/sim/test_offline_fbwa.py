"""The offline flight (agent.sim.offline.fly) with the plan on the sticks and the emulated
ArduPlane's FBWA laws flying the surfaces: the closed-loop record the benchmark identifies
(benchmarks/closed_loop_check.py)."""

from __future__ import annotations

import numpy as np
import pytest

from agent.excitation.plan import preset
from agent.sim.offline import INPUT_CHANNELS, fly
from agent.sim.plant import OUTPUTS


def test_in_fbwa_the_plan_is_a_bank_demand_and_the_laws_move_the_surfaces():
    plan = preset("lateral", controls=("aileron", "rudder"))
    manual = fly(plan, noise=False)
    closed = fly(plan, noise=False, fbwa=True)
    ail, phi = INPUT_CHANNELS.index("aileron"), OUTPUTS.index("phi")
    bank = np.degrees(closed.y[:, phi] - closed.y[0, phi])
    # The 4° aileron doublet's ±80 µs of stick asks ±9° of bank (ArduPlane's ±400 µs for
    # ROLL_LIMIT_DEG 45°): the laws fly toward it, with the aileron they choose, each way in
    # turn (the pulse is shorter than ArduPlane's default gains take to get there).
    assert 3.0 < np.max(bank) < 9.5
    assert -9.5 < np.min(bank) < -3.0
    moved = np.ptp(closed.u[:, ail])
    assert moved > 0.5
    # Open loop, the surface plays the doublet itself: ±4° commanded, through the Cub's
    # linkage (0.7 of it at the potentiometer: JSBSim's geometry).
    assert np.ptp(manual.u[:, ail]) == pytest.approx(8.0 * 0.71, rel=0.1)
    assert not np.allclose(closed.u[:, ail], manual.u[:, ail], atol=0.5)
