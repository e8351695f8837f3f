"""Aerodynamics of the six-facet box (spec §7.6-7.7; paper eqs. 18-21; listing aerodyn.f / aerocompr / aerocomp).

Algebraic: drag of each exposed facet, F_i = -q C_d (a_i . v_hat)+ v_hat with q = rho V^2 / 2, applied at the
facet's centre of pressure. Force and torque are in the geometric frame (axes parallel to the body axes,
origin at the box centre); the torque is about that origin.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from subsims.numerics import Vec, cross3, vecnorm
from subsims.satellite import constants as C
from subsims.satellite.parameters import as_float

PARAM_NAMES = ("rho", "cd", "length", "width", "height")

Facet = tuple[tuple[float, float, float], tuple[float, float, float]]  # (outward area vector m^2, c.p. m)


def box_facets(length: float, width: float, height: float) -> tuple[Facet, ...]:
    """aerodyn mode 1 facet numbering: front (+x), right (+y), bottom (+z), rear, left, top."""
    ax, ay, az = width * height, length * height, length * width
    return (((ax, 0.0, 0.0), (length / 2.0, 0.0, 0.0)),
            ((0.0, ay, 0.0), (0.0, width / 2.0, 0.0)),
            ((0.0, 0.0, az), (0.0, 0.0, height / 2.0)),
            ((-ax, 0.0, 0.0), (-length / 2.0, 0.0, 0.0)),
            ((0.0, -ay, 0.0), (0.0, -width / 2.0, 0.0)),
            ((0.0, 0.0, -az), (0.0, 0.0, -height / 2.0)))


@dataclass(frozen=True)
class AeroParams:
    """aerodyn mode 1 constants: density (constant), drag coefficient, box dimensions."""

    rho: float = C.RHO  # kg/m^3
    cd: float = C.CD
    length: float = C.BOX_LENGTH  # x, m
    width: float = C.BOX_WIDTH  # y, m
    height: float = C.BOX_HEIGHT  # z, m

    @property
    def facets(self) -> tuple[Facet, ...]:
        return box_facets(self.length, self.width, self.height)

    @classmethod
    def from_mapping(cls, params: Mapping[str, Any]) -> AeroParams:
        """Build from a parameter dict; defaults are the paper's. Unknown names raise ValueError."""
        unknown = sorted(set(params) - set(PARAM_NAMES))
        if unknown:
            raise ValueError(f"unknown aero parameter(s) {unknown}; known: {', '.join(PARAM_NAMES)}")
        return cls(rho=as_float(params.get("rho", C.RHO), "rho", nonnegative=True),
                   cd=as_float(params.get("cd", C.CD), "cd", nonnegative=True),
                   length=as_float(params.get("length", C.BOX_LENGTH), "length", positive=True),
                   width=as_float(params.get("width", C.BOX_WIDTH), "width", positive=True),
                   height=as_float(params.get("height", C.BOX_HEIGHT), "height", positive=True))


def facet_loads(vnorm_b: Vec, vmag: float, rho: float, cd: float,
                facets: tuple[Facet, ...]) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """aerocompr core, eqs. 18-20: (force, torque about the geometric origin), both geometric frame.

    ``vnorm_b``: unit flow-relative velocity in body axes; ``vmag``: its magnitude (m/s).
    """
    fac = 0.5 * rho * vmag**2 * cd
    fx = fy = fz = 0.0
    tx = ty = tz = 0.0
    for area, cp in facets:
        aproj = area[0] * vnorm_b[0] + area[1] * vnorm_b[1] + area[2] * vnorm_b[2]  # projected area
        if aproj <= 0.0:  # "negative projection implies ith facet not exposed"
            continue
        drag = fac * aproj
        facefor = (-drag * vnorm_b[0], -drag * vnorm_b[1], -drag * vnorm_b[2])  # eq. 18
        fx, fy, fz = fx + facefor[0], fy + facefor[1], fz + facefor[2]  # eq. 19
        facetor = cross3(cp, facefor)  # eq. 20
        tx, ty, tz = tx + facetor[0], ty + facetor[1], tz + facetor[2]
    return (fx, fy, fz), (tx, ty, tz)


Vec3 = tuple[float, float, float]


def aero_loads(vel_b: Vec, p: AeroParams, facets: tuple[Facet, ...] | None = None) -> tuple[Vec3, Vec3]:
    """aerocompr (RF): loads from the body-frame velocity; zero velocity gives zero loads (vecnorm guard)."""
    vnorm_b, vmag = vecnorm(vel_b)
    return facet_loads(vnorm_b, vmag, p.rho, p.cd, p.facets if facets is None else facets)


@functools.lru_cache(maxsize=8)
def _facet_arrays(facets: tuple[Facet, ...]) -> tuple[np.ndarray, np.ndarray]:
    """(area vectors (m, 3), centres of pressure (m, 3)) of ``facets`` (kept: a subsim has one box)."""
    return tuple(np.array(x, dtype=np.float64) for x in zip(*facets))  # type: ignore[return-value]


def aero_loads_batch(vel_b: np.ndarray, p: AeroParams,
                     facets: tuple[Facet, ...] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`aero_loads` of every row of ``vel_b`` (n, 3) at once: (force (n, 3), torque (n, 3)).

    The same operations in the same order, on (sample, facet) arrays, so each row equals the scalar result bit
    for bit (an unexposed facet adds -0.0, which changes no sum); a subsim evaluates 65 samples in one call."""
    v = np.asarray(vel_b, dtype=np.float64)
    mag = np.sqrt(v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1] + v[:, 2] * v[:, 2])
    moving = ~(mag <= 0.0)  # vecnorm's guard: the zero vector gives zero loads (NaN goes on as NaN)
    vnorm = np.where(moving[:, None], v / np.where(moving, mag, 1.0)[:, None], 0.0)  # (n, 3)
    # vmag**2 as the scalar form computes it: Python's float power (C pow) is not always x*x, NumPy's ** 2 is
    vmag2 = np.array([m**2 for m in np.where(moving, mag, 0.0).tolist()], dtype=np.float64)
    fac = 0.5 * p.rho * vmag2 * p.cd
    area, cp = _facet_arrays(p.facets if facets is None else facets)  # (m, 3) each
    aproj = area[:, 0] * vnorm[:, :1] + area[:, 1] * vnorm[:, 1:2] + area[:, 2] * vnorm[:, 2:]  # (n, m)
    exposed = ~(aproj <= 0.0)[:, :, None]  # "negative projection implies ith facet not exposed"
    facefor = np.where(exposed, -(fac[:, None] * aproj)[:, :, None] * vnorm[:, None, :], -0.0)  # eq. 18 (n, m, 3)
    facetor = np.where(exposed, np.stack(cross3(cp.T, facefor.transpose(2, 0, 1)), axis=2), -0.0)  # eq. 20
    force, torque = np.zeros((2, v.shape[0], 3))
    for i in range(area.shape[0]):  # eq. 19, facet by facet as in the listing
        force, torque = force + facefor[:, i], torque + facetor[:, i]
    return force, torque


def torque_about_cm(torque_g: Vec, force: Vec, r_cm: Vec = C.R_CM, physical: bool = False) -> tuple[Any, Any, Any]:
    """Aero torque about the c.m. from the torque about the geometric origin and the force there.

    ``physical=False``: the listings' T + r_cm x F (coupler, coupler3, sub). ``physical=True``: eq. 21,
    T - r_cm x F, the correct moment about the c.m. of a force acting at the geometric origin.
    By components: each a float, or an array (a column of samples; ``transforms.torque_to_cm``).
    """
    rxf = cross3(r_cm, force)
    if physical:
        return torque_g[0] - rxf[0], torque_g[1] - rxf[1], torque_g[2] - rxf[2]
    return torque_g[0] + rxf[0], torque_g[1] + rxf[1], torque_g[2] + rxf[2]
