"""Orbit dynamics (spec §7.2; paper eqs. 11-12; listing orbit.f / sub1 / rksys1).

Point mass in an Earth-centred inertial frame, inverse-square gravity plus an external (aerodynamic)
force given in inertial coordinates. State x = [R (m), V (m/s)], inertial.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from subsims.numerics import PhysicsError, Vec, as_table, rk4, vecnorm
from subsims.satellite import constants as C
from subsims.satellite.parameters import as_float, as_int, as_vec3

PARAM_NAMES = ("mu", "mass", "idiv", "r0", "v0", "altitude_km", "rearth_km", "inclination_deg")


def circular_orbit(mu: float = C.GME, altitude_km: float = C.ALTITUDE_KM, rearth_km: float = C.REARTH_KM,
                   inclination_deg: float = C.INCLINATION_DEG) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Initial R, V of the paper's run (spec §7.8, orbit.f mode 2): circular, start at the northernmost point."""
    cvdr = math.pi / 180.0
    rmag = (rearth_km + altitude_km) * 1000.0
    if not rmag > 0.0:  # (sqrt(mu / rmag) below: "math domain error" named nothing)
        raise ValueError(f"the start orbit's radius rearth_km + altitude_km must be > 0 km, got {rearth_km!r} + "
                         f"{altitude_km!r}")
    vmag = math.sqrt(mu / rmag)
    r = (rmag * math.cos(inclination_deg * cvdr), 0.0, rmag * math.sin(inclination_deg * cvdr))
    return r, (0.0, vmag, 0.0)


@dataclass(frozen=True)
class OrbitParams:
    """Constants of the orbit subsystem (orbit.f mode 1) and its initial conditions (mode 2)."""

    r0: tuple[float, float, float]
    v0: tuple[float, float, float]
    mu: float = C.GME  # gme = G M_E, m^3/s^2
    mass: float = C.MASS  # xmass, kg
    idiv: int = 1  # RK4 steps per output sample (spec §3.2)

    @classmethod
    def from_mapping(cls, params: Mapping[str, Any]) -> OrbitParams:
        """Build from a parameter dict; defaults are the paper's. Unknown names raise ValueError.

        ``r0``/``v0`` (inertial, m and m/s) override the circular orbit built from ``altitude_km``,
        ``rearth_km``, ``inclination_deg`` and ``mu``.
        """
        unknown = sorted(set(params) - set(PARAM_NAMES))
        if unknown:
            raise ValueError(f"unknown orbit parameter(s) {unknown}; known: {', '.join(PARAM_NAMES)}")
        mu = as_float(params.get("mu", C.GME), "mu", nonnegative=True)
        r, v = circular_orbit(mu,
                              as_float(params.get("altitude_km", C.ALTITUDE_KM), "altitude_km"),
                              as_float(params.get("rearth_km", C.REARTH_KM), "rearth_km", positive=True),
                              as_float(params.get("inclination_deg", C.INCLINATION_DEG), "inclination_deg"))
        r0 = as_vec3(params["r0"], "r0") if "r0" in params else r
        v0 = as_vec3(params["v0"], "v0") if "v0" in params else v
        if r0 == (0.0, 0.0, 0.0):
            raise ValueError("parameter 'r0' must not be the zero vector")
        return cls(r0=r0, v0=v0, mu=mu, mass=as_float(params.get("mass", C.MASS), "mass", positive=True),
                   idiv=as_int(params.get("idiv", 1), "idiv"))

    def initial_state(self) -> np.ndarray:
        return np.array(self.r0 + self.v0, dtype=np.float64)


def orbit_derivative(x: Vec, f_aero: Vec, mu: float, mass: float) -> list[float]:
    """sub1: xdot = [V, (F_grav + F_aero)/m] with F_grav = -(mu m / R^2) R_hat (eqs. 11-12)."""
    rnorm, rmag = vecnorm(x[0:3])
    if rmag == 0.0:
        raise PhysicsError("orbit radius is zero: inverse-square gravity is undefined")
    gmag = mu * mass / rmag**2
    im = 1.0 / mass
    return [x[3], x[4], x[5],
            im * (-gmag * rnorm[0] + f_aero[0]),
            im * (-gmag * rnorm[1] + f_aero[1]),
            im * (-gmag * rnorm[2] + f_aero[2])]


def integrate(p: OrbitParams, x0: Vec, times: Sequence[float],
              f_aero: Callable[[np.ndarray], Any] | None = None) -> tuple[np.ndarray, list[float]]:
    """orbit mode 3: RK4 over ``times`` with ``p.idiv`` steps per sample, F_aero read at every RK stage time.

    ``f_aero(ts)``: the aerodynamic force (inertial, N) at all the RK times ``ts`` (k,) in one call, shape
    (k, 3), or (3,) if constant; None: no force. Returns (samples (n, 6) with row 0 = x0, state at times[-1]).
    """
    mu, mass = p.mu, p.mass

    def deriv(t: float, x: list[float], force: Vec) -> list[float]:
        return orbit_derivative(x, force, mu, mass)

    def forces(ts: np.ndarray) -> list[list[float]]:
        return as_table((0.0, 0.0, 0.0) if f_aero is None else f_aero(ts), ts.size, 3, "f_aero").tolist()

    states, _, end = rk4(deriv, [float(v) for v in x0], times, p.idiv, forces)
    return np.array(states, dtype=np.float64), end
