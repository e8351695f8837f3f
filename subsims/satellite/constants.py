"""Physical constants of the paper's satellite (spec §7; orbit.f, attitude.f, aerodyn.f, rku.f mode 1).

Nominal double-precision values. The FORTRAN listings promote some REAL*4 literals; their exact
promoted values are in ``FORTRAN_LITERALS`` (spec §7.9) for bit-level experiments only.
"""

from __future__ import annotations

import math

# --- Earth and gravitation (spec §7.1, orbit.f mode 1) -------------------------------------------
GRAVCONST = 6.673e-11  # G, m^3/(kg s^2), "CRC, page 6"
REARTH_KM = 6367.65  # Earth's radius, (polar+equatorial)/2, km
DEARTH = 5522.0  # mean density of the Earth, kg/m^3


def earth_gm(gravconst: float = GRAVCONST, rearth_km: float = REARTH_KM, dearth: float = DEARTH) -> float:
    """gme = G * M_E with M_E = density * volume, computed in the listing's order (orbit.f)."""
    volume = (4.0 / 3.0) * math.pi * (rearth_km * 1000.0) ** 3
    xmearth = dearth * volume
    return gravconst * xmearth


GME = earth_gm()  # 3.985140974547934e14 m^3/s^2 (3.985140958624097e14 with the REAL*4 1.0e-11)

# --- Orbit initial conditions (spec §7.8) -----------------------------------------------------------
ALTITUDE_KM = 300.0
INCLINATION_DEG = 30.0  # start at the northernmost point, initial R in the inertial X-Z plane

# --- Mass properties (spec §7.4, attitude.f mode 1) ------------------------------------------------
MASS = 10000.0  # kg
IXX = 11250.0  # kg m^2, 3 m x 15 m uniform cylinder
IYY = 193125.0
IZZ = 0.9 * IYY  # "IZZ=.9*IYY"
INERTIA = ((IXX, 0.0, 0.0), (0.0, IYY, 0.0), (0.0, 0.0, IZZ))
R_CM = (1.0, 0.1, 0.1)  # c.m. in geometric body coordinates, m

# --- Control gains, case 1 (spec §7.5, attitude.f) ------------------------------------------------
GAINS_FULL = {"a0": 1000.0, "a1": 100.0, "b0": 1000.0, "b1": 100.0, "c0": 1000.0, "c1": 100.0}

# --- Aerodynamics (spec §7.6, aerodyn.f mode 1) ---------------------------------------------------
RHO = 1.95e-11  # kg/m^3, constant ("Wertz ... 300 km, mean value")
CD = 2.25  # same for all facets
BOX_LENGTH = 15.0  # x, m
BOX_WIDTH = 4.0  # y, m
BOX_HEIGHT = 3.0  # z, m

# --- Listing literals as the compiler promoted them (spec §7.9) -----------------------------------
FORTRAN_LITERALS = {
    "gme": earth_gm(gravconst=6.673 * 9.999999960041972e-12),  # 3.985140958624097e14
    "izz": 193125.0 * 0.8999999761581421,  # 173812.4953955412
    "rho": 1.950000057260315e-11,
    "r_cm_rku": (1.0, 0.10000000149011612, 0.10000000149011612),
}
