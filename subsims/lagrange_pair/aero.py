"""Aerodynamics of the SRB and its drogue parachute (Watts, NASA TP-3220, 1992, appendix listing).

Pure functions shared by the pair model (built-in aero) and by the separate algebraic
``lagrange_pair_aero`` subsim, so that both compute exactly the same loads from the same
kinematics.

Model (listing, "BEGIN AERO SECTION"): no wind, so airspeed is the body-frame CM velocity.
Coefficients are tabulated in "missile" axes against the total angle of attack; a positive
rotation by the aero roll angle about the roll (x) axis takes them to body axes. The moment
reference point is the CM. Density is looked up at the SRB altitude for *both* bodies, as in
the listing (a simplification of the paper, kept for fidelity).

Table end behaviour (the paper does not list TBLXY): linear interpolation, clamped to the end
values outside the table (``np.interp``). This matters for the parachute table, which ends at 25 deg.

Units: ft, s, lbf, slug/ft^3, angles in radians at the interface (tables are in degrees).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

RAD2DEG = 57.2957795  # CNV of the listing, deg/rad


@dataclass(frozen=True)
class AeroTable:
    """Missile-axis coefficients of one body versus total angle of attack, and its references."""

    alpha_deg: np.ndarray  # ALxTL
    ca: np.ndarray  # CAMxTL, axial force
    cn: np.ndarray  # CNMxTL, normal force
    cm: np.ndarray  # CMMxTL, pitch moment
    s_ref: float  # SREFx, ft^2
    l_ref: float  # LREFx, ft
    # CYM, CWM, CRM (side force, yaw and roll moment) are 0.0 in the listing for both bodies.


def _ro(values: list[float]) -> np.ndarray:
    a = np.array(values, dtype=np.float64)
    a.setflags(write=False)
    return a


# SRB, listing DATA ALBTL / CAMBTL / CNMBTL / CMMBTL and SREFB, LREFB
SRB_TABLE = AeroTable(
    alpha_deg=_ro([0.0, 20.0, 40.0, 60.0, 90.0, 120.0, 147.0, 160.0, 180.0]),
    ca=_ro([0.0, 0.0, 0.0, 0.50, 1.40, -1.35, -3.65, -3.00, -2.20]),
    cn=_ro([0.0, 0.0, 0.0, 9.00, 9.00, 9.00, 4.10, 1.80, 0.00]),
    cm=_ro([0.0, 0.0, 0.0, 15.5, 5.00, -3.30, -1.90, -1.10, 0.00]),
    s_ref=116.26,
    l_ref=12.1667,
)

# Parachute, listing DATA ALCTL / CAMCTL / CNMCTL / CMMCTL and SREFC, LREFC
CHUTE_TABLE = AeroTable(
    alpha_deg=_ro([0.0, 5.0, 10.0, 15.0, 25.0]),
    ca=_ro([0.62, 0.62, 0.62, 0.61, 0.56]),
    cn=_ro([0.000, 0.0100, 0.032, 0.090, 0.170]),
    cm=_ro([0.000, -0.0133, -0.037, -0.091, -0.175]),
    s_ref=2289.1,  # as printed (pi*54^2/4 would be 2290.2)
    l_ref=54.00,
)

# Density, listing DATA RHOALT / RHOTL ("ENGLISH SYSTEM"): altitude ft -> slug/ft^3
RHO_ALT = _ro([0.0, 5000.0, 8224.0, 8803.0, 14000.0, 20000.0, 30000.0, 40000.0])
RHO_TAB = _ro([0.0022964, 0.0019909, 0.0018053, 0.0017735, 0.0015086, 0.0012483, 0.0009024, 0.0006306])


def density(altitude: float) -> float:
    """Atmospheric density (slug/ft^3) at ``altitude`` (ft); TBLXY as linear, clamped at the ends."""
    return float(np.interp(altitude, RHO_ALT, RHO_TAB))


def ztan2(y: float, x: float) -> float:
    """ZTAN2 of the listing: atan2 with the 0/0 case returning 0."""
    if y == 0.0 and x == 0.0:
        return 0.0
    return float(np.arctan2(y, x))


def incidence(v_body: np.ndarray) -> tuple[float, float, float]:
    """Speed (ft/s), total angle of attack (rad, 0..pi) and aero roll angle (rad, -pi..pi) of a body velocity."""
    speed = float(np.sqrt(v_body[0] ** 2 + v_body[1] ** 2 + v_body[2] ** 2))  # VMAG
    if speed == 0.0:
        return 0.0, 0.0, 0.0
    # The listing's ALPHA = ACOS(V(1)/|V|), written as atan2(|V_lateral|, V(1)): equal in exact arithmetic,
    # but ACOS turns a 1-ulp error of V(1)/|V| into an angle error of 1e-16/sin(alpha), which near 0 and
    # 180 deg (the drogue and the SRB after about 30 s) is round-off noise in the loads of 1e-5 lbf*ft,
    # enough to stall a coupled iteration that checks them. atan2 keeps full relative precision.
    lateral = float(np.sqrt(v_body[1] ** 2 + v_body[2] ** 2))
    alpha = float(np.arctan2(lateral, v_body[0]))
    phia = ztan2(v_body[1], v_body[2])  # PHIA = ZTAN2(V(2), V(3))
    return speed, alpha, phia


def body_aero_loads(v_body: np.ndarray, rho: float, table: AeroTable) -> tuple[np.ndarray, np.ndarray]:
    """Aero force (lbf) and moment about the CM (lbf*ft), both in body axes, for one body."""
    speed, alpha, phia = incidence(v_body)
    qs = 0.5 * rho * speed * speed * table.s_ref  # QBRS = QBAR*SREF
    qsl = qs * table.l_ref  # QBRSL
    a_deg = alpha * RAD2DEG
    cam = float(np.interp(a_deg, table.alpha_deg, table.ca))  # TBLXY
    cnm = float(np.interp(a_deg, table.alpha_deg, table.cn))
    cmm = float(np.interp(a_deg, table.alpha_deg, table.cm))
    cym = cwm = crm = 0.0
    sp, cp = np.sin(phia), np.cos(phia)
    # missile axes -> body axes, positive rotation phia about the roll axis
    ca = cam
    cy = cym * cp - cnm * sp
    cn = cnm * cp + cym * sp
    cr = crm
    cm = cmm * cp + cwm * sp
    cw = cwm * cp - cmm * sp
    # loads at the CM with the sign change for CA and CN (FL(1..6) / FL(7..12))
    force = np.array([-qs * ca, qs * cy, -qs * cn])
    moment = np.array([qsl * cr, qsl * cm, qsl * cw])
    return force, moment


def pair_aero_loads(
    altitude_b: float, v_b: np.ndarray, v_c: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The listing's [FL]: (force_B, moment_B) in B axes and (force_C, moment_C) in C axes.

    ``altitude_b`` is the SRB altitude (-RIBI(3)); its density is used for both bodies.
    ``v_b`` is V_B in B axes, ``v_c`` is V_C in C axes (ft/s).
    """
    rho = density(altitude_b)
    f_b, m_b = body_aero_loads(v_b, rho, SRB_TABLE)
    f_c, m_c = body_aero_loads(v_c, rho, CHUTE_TABLE)
    return f_b, m_b, f_c, m_c
