"""Subsim adapter of the orbit dynamics (subsystem 1 of the paper; orbit.f mode 3)."""

from __future__ import annotations

import numpy as np

from cosim.subsim import InputFunction, Param, Port
from subsims.adapters import Advanced, ParamsSubsim, reports_physics_errors
from subsims.orbit.model import OrbitParams, integrate
from subsims.satellite import constants as C


class Orbit(ParamsSubsim):
    """Point-mass orbit, inverse-square gravity + aerodynamic force. State [R, V] inertial.

    Parameters (``params``; all optional, the paper's values by default): ``r0``/``v0`` (inertial), or when
    they are not set the circular start orbit of ``altitude_km``, ``rearth_km``, ``inclination_deg`` and ``mu``.
    """

    name = "orbit"
    inputs = {"f_aero": Port(3, "N", "aerodynamic force, inertial")}
    outputs = {
        "R": Port(3, "m", "orbit radius vector, Earth centre to c.m., inertial"),
        "V": Port(3, "m/s", "orbit velocity, inertial"),
    }

    params_type = OrbitParams
    params = {  # the names of model.PARAM_NAMES; defaults those of OrbitParams.from_mapping (spec §7.1, §7.2, §7.8)
        "mu": Param(C.GME, "m^3/s^2", "G M_E, Earth's gravitational parameter (also the circular start speed), >= 0"),
        "mass": Param(C.MASS, "kg", "satellite mass, > 0"),
        "idiv": Param(1, "", "RK4 steps per output sample, >= 1"),
        "r0": Param(None, "m", "initial orbit radius vector, inertial (3 numbers, not zero); not set: the circular "
                    "orbit of altitude_km, rearth_km, inclination_deg"),
        "v0": Param(None, "m/s", "initial orbit velocity, inertial (3 numbers); not set: the circular orbit's, "
                    "sqrt(mu / r) along inertial Y"),
        "altitude_km": Param(C.ALTITUDE_KM, "km", "altitude of the circular start orbit (when r0/v0 are not set)"),
        "rearth_km": Param(C.REARTH_KM, "km", "Earth radius under the circular start orbit, > 0"),
        "inclination_deg": Param(C.INCLINATION_DEG, "deg", "inclination of the circular start orbit; the start "
                                 "is its northernmost point, R in the inertial X-Z plane"),
    }

    @reports_physics_errors
    def advance(self, state: np.ndarray, times: np.ndarray, u: InputFunction) -> Advanced:
        samples, end = integrate(self.p, state.tolist(), times, lambda ts: u(ts)["f_aero"])  # u read once
        return {"R": samples[:, 0:3].copy(), "V": samples[:, 3:6].copy()}, np.array(end, dtype=np.float64)
