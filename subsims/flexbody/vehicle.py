"""The report's example vehicle (Storch & Gates, appendix B, Figure 5) as default parameters.

Units are the report's: slug, ft, lbf, s (angles in the parameters in degrees, as in its NAMELIST input).
The model itself is unit-agnostic; ``units`` only labels the ports ("slug-ft-lbf-s" or "kg-m-N-s").

Geometry (appendix B, b = 1 ft, h = 2 ft, L = 10 ft): a b x b x h box base of 5 slug with O_g at a corner,
s = (-b/2, b/2, h/2); two booms leave the faces y = b and y = 0 along +y and -y at x = -b/2, z = h/2, each
with a 1 slug particle at L and a 0.5 slug particle at 2L from the face:
r^1 = (-b/2, b + L, h/2), r^2 = (-b/2, b + 2L, h/2), r^3 = (-b/2, -L, h/2), r^4 = (-b/2, -2L, h/2).
I_b = (m_b/12) diag(b^2 + h^2, b^2 + h^2, 2 b^2), exact (the NAMELIST rounds it to 2.083, 0.833).

Stiffness: the report gives none (it reads K from FORTRAN unit 8). This uses the spec's documented choice
(spec §2.4 [EXT]): each boom is a massless uniform cantilevered Euler-Bernoulli beam clamped at its face,
EI_x = 1e4 lbf ft^2 (deflection along x), EI_z = 4e4 lbf ft^2 (along z), EA = 1e6 lbf (axial, along y).
Its constrained frequencies are 0.3971267, 0.7942535, 2.045636, 4.091272, 38.52031, 92.99626 Hz, each
twice (booms A and B). NT = 2 (the report's choice) keeps the two first x-bending modes.

Parameters (all optional; missing keys take these defaults):

- ``mode``: "free" (the report's vehicle, 6 + t DOF; spec mode F), "attitude" (appendage only, driven by
  the base's angular motion, returns the flexible torque about the composite mass centre; spec mode C) or
  "base" (appendage driven by prescribed base motion, returns interface loads; spec mode B).
- ``units``: "slug-ft-lbf-s" | "kg-m-N-s", port labels only.
- ``m_b``, ``I_b`` (3x3, about the base mass centre), ``s`` (3): rigid base.
- ``masses`` (n), ``r`` (n x 3): particles, undeformed positions from O_g, body axes.
- Stiffness, first match wins: ``K`` (3n x 3n); or ``omega2`` (t) with ``Phi`` (3n x t) mass-normalized
  modes; or the boom builder ``booms`` (particle numbers 1..n, root to tip), ``boom_L``, ``EI_x``, ``EI_z``, ``EA``.
- ``n_modes``: t retained constrained modes, 0 <= t <= 3n (t = 3n: no truncation; t = 0: rigid vehicle).
- ``mass_order``, ``kin_order``: 1 | 2 | 3, the report's categories (chapter 4) kept in A and in U.
- ``modal_damping``: zeta_k (scalar or t values) [EXT, not in the report], default 0.
- Initial conditions (&KIN): ``R0`` (inertial), ``euler123_deg`` (the report's 1-2-3 THETA), ``V0`` (body
  UVW), ``omega_deg_s`` (body OMEGA, deg/s); elastic: ``q0``, ``q_dot0`` (n x 3 physical, projected as
  eta = Phi^T M q) or ``eta0``, ``eta_dot0`` (t); default zero as in the report's INITL.
- ``h``: fixed RK4 step (the report's DT = 0.01 s).
- ``t_end``, ``print_dt``, ``plot_dt``: the report's &RUN values for the scenario; not read by the model, so not
  declared by the subsim either (a scenario sets its own ``stop``; given as subsim parameters they are refused).
"""

from __future__ import annotations

from typing import Any

B, H, L = 1.0, 2.0, 10.0
M_BASE = 5.0

SAMPLE_VEHICLE: dict[str, Any] = {
    "mode": "free",
    "units": "slug-ft-lbf-s",
    # &INPUT
    "m_b": M_BASE,
    "I_b": [[M_BASE / 12 * (B**2 + H**2), 0.0, 0.0], [0.0, M_BASE / 12 * (B**2 + H**2), 0.0],
            [0.0, 0.0, M_BASE / 12 * 2 * B**2]],
    "s": [-B / 2, B / 2, H / 2],
    "masses": [1.0, 0.5, 1.0, 0.5],
    "r": [[-B / 2, B + L, H / 2], [-B / 2, B + 2 * L, H / 2], [-B / 2, -L, H / 2], [-B / 2, -2 * L, H / 2]],
    "n_modes": 2,
    # spec §2.4 stiffness [EXT]
    "booms": [[1, 2], [3, 4]],
    "boom_L": L,
    "EI_x": 1.0e4,
    "EI_z": 4.0e4,
    "EA": 1.0e6,
    "mass_order": 3,
    "kin_order": 3,
    "modal_damping": 0.0,
    # &KIN
    "R0": [1.0e3, 2.0e3, 3.0e3],
    "euler123_deg": [5.0, 20.0, 0.0],
    "V0": [0.0, 5.0, 0.0],
    "omega_deg_s": [0.0, 10.0, 0.0],
    # &RUN
    "h": 0.01,
    "t_end": 60.0,
    "print_dt": 6.0,
    "plot_dt": 0.6,
}

# Spec AT-13 heavy-bus variant: the sample with m_b = 100 slug and I_b = 2000 E_3 slug ft^2, starting from rest
# at the origin; composite-to-appendage coupling mu = 0.2337, free-free frequencies 0.40155 and 0.45365 Hz.
HEAVY_BUS: dict[str, Any] = {
    **SAMPLE_VEHICLE,
    "m_b": 100.0,
    "I_b": [[2000.0, 0.0, 0.0], [0.0, 2000.0, 0.0], [0.0, 0.0, 2000.0]],
    "R0": [0.0, 0.0, 0.0],
    "euler123_deg": [0.0, 0.0, 0.0],
    "V0": [0.0, 0.0, 0.0],
    "omega_deg_s": [0.0, 0.0, 0.0],
    "t_end": 20.0,
}

# Spec AT-10 bang-bang slew (open loop), torque at O_g in body axes: +10 ft lbf about z for 0 <= t < 5 s,
# -10 for 5 <= t < 10 s, then 0. Parameters of subsims.flexbody_control.
BANG_BANG_SLEW: dict[str, Any] = {"law": "bang_bang", "torque": [0.0, 0.0, 10.0], "t_switch": 5.0, "t_off": 10.0}
