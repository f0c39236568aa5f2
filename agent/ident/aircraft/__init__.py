"""Whole-aircraft identification in the frequency domain: decoupled longitudinal and lateral
state-space models, each state measured, from one simultaneous manoeuvre.

Why not OKID/ERA for the full aircraft: eight outputs, four inputs, an engine that lags the
throttle, and slow modes (phugoid, spiral) barely covered by a minute of data give ERA a
Hankel matrix with no clear order and OKID a regression with hundreds of unknowns. A flight-
test engineer knows the structure instead (Klein & Morelli, *Aircraft System Identification*,
AIAA 2006, ch. 7 and 9; Morelli's SIDPAC `fdoe`): the states are the measured outputs (C = I),
the longitudinal axis (V, α, q, θ) is driven by elevator and throttle, the lateral axis
(β, p, r, φ) by aileron and rudder, and each axis is a 4-state linear model
ẋ = A x + B u_eff, y = x + v, fitted where the excitation put its power.

One job per module, in the order the data flow through them:
- axes: the two axes' states and controls, found in a record by the channels' roles;
- kinematics, wind: what is known without fitting (the rigid body's kinematics and gravity;
  the gusts, measured from the INS's velocities);
- prepare: the batch made ready (kinematic forcing, measured gusts and the known nonlinear
  terms as inputs);
- transforms: the records' Fourier transforms at the analysis bins, each axis's excited bins;
- problem, fit: one axis's output-error problem and its fit, covariance and coupling tests;
- model: the axes fitted, coupled and assembled into one model, its modes and report.
"""

from agent.ident.aircraft.axes import AXES, LATERAL, LONGITUDINAL, axes_present
from agent.ident.aircraft.model import fitted_axes, identify

__all__ = ["AXES", "LATERAL", "LONGITUDINAL", "axes_present", "fitted_axes", "identify"]
