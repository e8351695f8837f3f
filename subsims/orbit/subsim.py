"""Subsim adapter of the orbit dynamics (subsystem 1 of the paper; orbit.f mode 3)."""

from __future__ import annotations

import numpy as np

from cosim.subsim import InputFunction, Port
from subsims.adapters import Advanced, ParamsSubsim, reports_physics_errors
from subsims.orbit.model import OrbitParams, integrate


class Orbit(ParamsSubsim):
    """Point-mass orbit, inverse-square gravity + aerodynamic force. State [R, V] inertial.

    Parameters (all optional, paper's values by default): ``mu`` (m^3/s^2), ``mass`` (kg), ``idiv``
    (RK4 steps per output sample), ``r0``/``v0`` (inertial) or ``altitude_km``, ``rearth_km``,
    ``inclination_deg`` for the circular start orbit.
    """

    name = "orbit"
    inputs = {"f_aero": Port(3, "N", "aerodynamic force, inertial")}
    outputs = {
        "R": Port(3, "m", "orbit radius vector, Earth centre to c.m., inertial"),
        "V": Port(3, "m/s", "orbit velocity, inertial"),
    }

    params_type = OrbitParams

    @reports_physics_errors
    def advance(self, state: np.ndarray, times: np.ndarray, u: InputFunction) -> Advanced:
        samples, end = integrate(self.p, state.tolist(), times, lambda ts: u(ts)["f_aero"])  # u read once
        return {"R": samples[:, 0:3].copy(), "V": samples[:, 3:6].copy()}, np.array(end, dtype=np.float64)
