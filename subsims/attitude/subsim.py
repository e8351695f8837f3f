"""Subsim adapter of the attitude dynamics and control (subsystem 2 of the paper; attitude.f mode 3)."""

from __future__ import annotations

import numpy as np

from cosim.subsim import InputFunction, Param, Port
from subsims.adapters import Advanced, ParamsSubsim, reports_physics_errors
from subsims.attitude.model import GAIN_NAMES, MIN_COS_PHI_Y, AttitudeParams, integrate
from subsims.numerics import input_rows
from subsims.satellite import constants as C

_AXIS = {"a": "x", "b": "y", "c": "z"}
_GAIN = {"0": ("N m/rad", "position (angle)"), "1": ("N m s/rad", "rate")}


class Attitude(ParamsSubsim):
    """Rigid-body attitude, z-y-x Euler angles, gravity gradient, linear control, external torque input.

    Parameters (``params``; all optional, the paper's case 1 by default).
    Reports ``EulerSingularityError`` as a ``ModelError`` when phi_y reaches +-90 deg.
    """

    name = "attitude"
    params_type = AttitudeParams
    params = {  # the names of model.PARAM_NAMES; defaults those of AttitudeParams.from_mapping (spec §7.3-7.5, §7.8)
        "inertia": Param([list(row) for row in C.INERTIA], "kg m^2", "inertia about the c.m., body axes: 3 principal "
                         "moments or a symmetric positive definite 3x3 matrix"),
        "mu": Param(C.GME, "m^3/s^2", "G M_E, Earth's gravitational parameter of the gravity-gradient torque, >= 0"),
        "idiv": Param(1, "", "RK4 steps per output sample, >= 1"),
        "phi0": Param([0.0, 0.0, 0.0], "rad", "initial Euler angles phi_x, phi_y, phi_z (z-y-x sequence), "
                      "phi_y inside (-pi/2, pi/2)"),
        "omega0": Param([0.0, 0.0, 0.0], "rad/s", "initial body rates"),
        "min_cos_phi_y": Param(MIN_COS_PHI_Y, "", "singularity margin, > 0: the run stops (EulerSingularityError) "
                               "when cos phi_y falls below it"),
        **{g: Param(C.GAINS_FULL[g], _GAIN[g[1]][0], f"{_AXIS[g[0]]} {_GAIN[g[1]][1]} control gain, eq. 16")
           for g in GAIN_NAMES},
    }
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
