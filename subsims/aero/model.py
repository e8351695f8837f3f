"""Aerodynamics of the six-facet box (spec §7.6-7.7; paper eqs. 18-21; listing aerodyn.f / aerocompr / aerocomp).

Algebraic: drag of each exposed facet, F_i = -q C_d (a_i . v_hat)+ v_hat with q = rho V^2 / 2, applied at the
facet's centre of pressure. Force and torque are in the geometric frame (axes parallel to the body axes,
origin at the box centre); the torque is about that origin.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

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
