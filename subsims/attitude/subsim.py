"""Subsim adapter of the attitude dynamics and control (subsystem 2 of the paper; attitude.f mode 3)."""

from __future__ import annotations

import numpy as np

from cosim.subsim import InputFunction, Port
from subsims.adapters import Advanced, ParamsSubsim, reports_physics_errors
from subsims.attitude.model import AttitudeParams, integrate
from subsims.numerics import input_rows


class Attitude(ParamsSubsim):
    """Rigid-body attitude, z-y-x Euler angles, gravity gradient, linear control, external torque input.

    Parameters (all optional, paper's case 1 by default): ``inertia`` (3 moments or 3x3, kg m^2), ``mu``,
    gains ``a0 a1 b0 b1 c0 c1``, ``idiv``, ``phi0`` (rad), ``omega0`` (rad/s), ``min_cos_phi_y``.
    Reports ``EulerSingularityError`` as a ``ModelError`` when phi_y reaches +-90 deg.
    """

    name = "attitude"
    params_type = AttitudeParams
    inputs = {  # in this order: the rows integrate() reads
        "R": Port(3, unit="m", doc="orbit radius vector, inertial (gravity gradient)"),
        "torque": Port(3, unit="N m", doc="external (aerodynamic) torque about the c.m., body"),
    }
    outputs = {
        "phi": Port(3, unit="rad", doc="Euler angles phi_x, phi_y, phi_z, inertial -> body, z-y-x sequence, unlimited"),
        "omega": Port(3, unit="rad/s", doc="body rates"),
        "omega_dot": Port(3, unit="rad/s^2", doc="body angular acceleration"),
    }

    @reports_physics_errors
    def advance(self, state: np.ndarray, times: np.ndarray, u: InputFunction) -> Advanced:
        # the inputs (R, torque) at all the RK times from one call of u, as Python floats
        samples, rates, end = integrate(self.p, state.tolist(), times, lambda ts: input_rows(u, ts, self.inputs, True))
        outputs = {"phi": samples[:, 0:3].copy(), "omega": samples[:, 3:6].copy(), "omega_dot": rates}
        return outputs, np.array(end, dtype=np.float64)
