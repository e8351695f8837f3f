"""RK-U, the paper's unified reference (spec §6; listing rku.f, ``sub`` and ``rksys``).

The 12-state system X = [R, V, phi, omega] (eq. 22) integrated by one RK4, the aerodynamics evaluated
from the stage's own V and phi at every RK stage. It reuses the stand-alone physics: ``orbit_derivative``,
``attitude_derivative``, ``facet_loads`` and ``torque_about_cm``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from subsims.aero.model import AeroParams, facet_loads, torque_about_cm
from subsims.attitude.model import AttitudeParams, EulerSingularityError, attitude_derivative
from subsims.numerics import dcm321, matTvec, matvec, rk4, vecnorm
from subsims.orbit.model import OrbitParams, orbit_derivative
from subsims.satellite.constants import R_CM
from subsims.satellite.parameters import as_int

CHUNK = 4096  # samples integrated per rk4 call (bounds the lists of Python floats held at once)


def unified_loads(x: Sequence[float], aero: AeroParams, facets: tuple, r_cm: Sequence[float],
                  physical: bool) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...], tuple]:
    """aerocomp + transfer in ``sub``: (F body, T about geometric origin, T about c.m., DCM) at state x.

    As in rku.f the inertial velocity is normalised first and then rotated to body axes.
    """
    amat = dcm321(x[6:9])
    vnorm, vmag = vecnorm(x[3:6])
    force_b, torque_g = facet_loads(matvec(amat, vnorm), vmag, aero.rho, aero.cd, facets)
    return force_b, torque_g, torque_about_cm(torque_g, force_b, r_cm, physical), amat


def unified_derivative(x: Sequence[float], orbit: OrbitParams, attitude: AttitudeParams, aero: AeroParams,
                       facets: tuple, r_cm: Sequence[float] = R_CM, physical: bool = False) -> list[float]:
    """sub: xdot of the 12-state system."""
    force_b, _, torque_cm, amat = unified_loads(x, aero, facets, r_cm, physical)
    f_aero = matTvec(amat, force_b)  # body -> inertial
    return [*orbit_derivative(x[0:6], f_aero, orbit.mu, orbit.mass),
            *attitude_derivative(x[6:12], x[0:3], torque_cm, attitude)]


def run_unified(orbit_params: Mapping[str, Any], attitude_params: Mapping[str, Any],
                aero_params: Mapping[str, Any], t_stop: float, dt: float, *, substeps: int = 1,
                r_cm: Sequence[float] = R_CM, physical_torque: bool = False,
                t_start: float = 0.0) -> dict[str, Any]:
    """Integrate RK-U from ``t_start`` to ``t_stop`` (rounded up to whole ``dt``), one output sample per ``dt``.

    Parameters are the subsims' parameter dicts (``Orbit``, ``Attitude``, ``Aero``; their ``idiv`` is
    ignored: ``substeps`` RK4 steps are taken per ``dt``). ``r_cm``/``physical_torque`` as in
    ``transforms.torque_to_cm``. Raises ``EulerSingularityError`` (a ``PhysicsError``) at phi_y = +-90 deg.

    Returns ``{"t": (n,), "orbit": {"R", "V"}, "attitude": {"phi", "omega", "omega_dot"},
    "aero": {"force", "torque"}}``, arrays (n, 3) at the samples, the same ports as the subsims'
    (aero force in body axes, torque about the geometric origin, evaluated at the sample state).
    """
    op = OrbitParams.from_mapping(orbit_params)
    ap = AttitudeParams.from_mapping(attitude_params)
    aero = AeroParams.from_mapping(aero_params)
    substeps = as_int(substeps, "substeps")
    if not (dt > 0.0 and math.isfinite(dt)):
        raise ValueError(f"dt must be a finite number > 0, got {dt!r}")
    nsteps = max(0, math.ceil((t_stop - t_start) / dt - 1e-9))
    facets = aero.facets
    r_cm = tuple(float(c) for c in r_cm)

    def deriv(t: float, x: list[float], _: None) -> list[float]:
        try:
            return unified_derivative(x, op, ap, aero, facets, r_cm, physical_torque)
        except EulerSingularityError as e:
            raise EulerSingularityError(f"at t = {t:.9g} s: {e}") from None

    times = t_start + dt * np.arange(nsteps + 1)
    states = np.empty((nsteps + 1, 12))
    xdots = np.empty((nsteps + 1, 12))
    y = op.initial_state().tolist() + ap.initial_state().tolist()
    states[0] = y
    for a in range(0, max(nsteps, 1), CHUNK):  # rksys: substeps RK4 steps of dt / substeps per sample
        b = min(a + CHUNK, nsteps)
        ys, fs, y = rk4(deriv, y, times[a:b + 1], substeps, h=dt / substeps, end_node=b == nsteps)
        states[a + 1:b + 1] = ys[1:]
        xdots[a:a + len(fs)] = fs
    force = np.empty((nsteps + 1, 3))
    torque = np.empty((nsteps + 1, 3))
    for k in range(nsteps + 1):
        force[k], torque[k], _, _ = unified_loads(states[k].tolist(), aero, facets, r_cm, physical_torque)
    return {
        "t": times,
        "orbit": {"R": states[:, 0:3].copy(), "V": states[:, 3:6].copy()},
        "attitude": {"phi": states[:, 6:9].copy(), "omega": states[:, 9:12].copy(),
                     "omega_dot": xdots[:, 9:12].copy()},
        "aero": {"force": force, "torque": torque},
    }
