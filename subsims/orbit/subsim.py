"""Subsim adapter of the orbit dynamics (subsystem 1 of the paper; orbit.f mode 3)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from cosim.subsim import InputFunction, ModelError, Port, Subsim
from subsims.numerics import PhysicsError
from subsims.orbit.model import OrbitParams, integrate


class Orbit(Subsim):
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

    def initial_state(self, params: Mapping[str, Any]) -> np.ndarray:
        self.p = OrbitParams.from_mapping(params)
        return self.p.initial_state()

    def advance(
        self, state: np.ndarray, times: np.ndarray, u: InputFunction
    ) -> tuple[dict[str, np.ndarray], np.ndarray]:
        try:
            samples, end = integrate(self.p, state.tolist(), times, lambda ts: u(ts)["f_aero"])
        except PhysicsError as exc:
            raise ModelError(str(exc)) from exc
        return {"R": samples[:, 0:3].copy(), "V": samples[:, 3:6].copy()}, np.array(end, dtype=np.float64)
