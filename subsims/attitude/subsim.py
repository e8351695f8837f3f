"""Subsim adapter of the attitude dynamics and control (subsystem 2 of the paper; attitude.f mode 3)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from cosim.subsim import InputFunction, ModelError, Port, Subsim
from subsims.attitude.model import AttitudeParams, integrate
from subsims.numerics import PhysicsError, input_rows

INPUTS = (("R", 3), ("torque", 3))


class Attitude(Subsim):
    """Rigid-body attitude, z-y-x Euler angles, gravity gradient, linear control, external torque input.

    Parameters (all optional, paper's case 1 by default): ``inertia`` (3 moments or 3x3, kg m^2), ``mu``,
    gains ``a0 a1 b0 b1 c0 c1``, ``idiv``, ``phi0`` (rad), ``omega0`` (rad/s), ``min_cos_phi_y``.
    Raises ``EulerSingularityError`` (a ``ModelError``) when phi_y reaches +-90 deg.
    """

    name = "attitude"
    inputs = {
        "R": Port(3, "m", "orbit radius vector, inertial (gravity gradient)"),
        "torque": Port(3, "N m", "external (aerodynamic) torque about the c.m., body"),
    }
    outputs = {
        "phi": Port(3, "rad", "Euler angles phi_x, phi_y, phi_z, inertial -> body, z-y-x sequence, unlimited"),
        "omega": Port(3, "rad/s", "body rates"),
        "omega_dot": Port(3, "rad/s^2", "body angular acceleration"),
    }

    def initial_state(self, params: Mapping[str, Any]) -> np.ndarray:
        self.p = AttitudeParams.from_mapping(params)
        return self.p.initial_state()

    def advance(
        self, state: np.ndarray, times: np.ndarray, u: InputFunction
    ) -> tuple[dict[str, np.ndarray], np.ndarray]:
        try:
            samples, rates, end = integrate(self.p, state.tolist(), times,
                                            lambda ts: input_rows(u, ts, INPUTS, lists=True))
        except PhysicsError as exc:
            raise ModelError(str(exc)) from exc
        outputs = {"phi": samples[:, 0:3].copy(), "omega": samples[:, 3:6].copy(), "omega_dot": rates}
        return outputs, np.array(end, dtype=np.float64)
