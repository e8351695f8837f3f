"""The flexible appendage alone, for coupling to a separate rigid-body simulator (spec §4.4-4.6 [DER/EXT]).

These are the particle rows of the report's Figure 3 (5-4) with the base's motion known, written with the
inertial acceleration of O_g, a_O = Vdot + w x V, so that V is not needed. Per particle (body axes)

    a_i = a_O + wdot x rho_i + w x (w x rho_i) + 2 w x qdot_i + qddot_i          (3-1)
    eta_ddot = Phi^T [f^i - m_i (a_i - a_O - qddot_i)] - A13^T a_O - Omega^2 eta   (5-4)

Mode C ("attitude"): the base's angular motion (w, wdot) comes from a rigid attitude simulator of the
*composite undeformed* vehicle about its mass centre c0 with inertia J; a_O is eliminated with the
translational rows (3-5). The appendage returns tau_flex about c0 with

    J wdot + w x J w = tau0 - c0 x f0 + tau_flex

exactly (no modelling error from the partition). Inertia split (C2): the attitude simulator uses J' = J - D
and receives tau_flex_split = tau_flex - D wdot - w x (D w), which removes the first-order algebraic loop.

Mode B ("base"): a_O, w, wdot are all prescribed; the appendage returns the loads it exerts on the bus.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from subsims.flexbody.kinematics import cross, skew
from subsims.flexbody.model import FlexModel, deflections, solve_spd


def inertia_split(model: FlexModel) -> dict[str, np.ndarray | float]:
    """Composite-body constants of mode C: c0, J (about c0), D, J - D and the loop gain mu = rho(J^-1 D).

    D = L_P M_ee^-1 L_P^T with L_P = sum m_i (r_i - c0)~ Phi_i and M_ee = E - A13^T A13 / m; D = d tau_flex / d wdot
    at q = qdot = 0, w = 0.
    """
    c0 = model.mc0 / model.m
    J = model.I1 - model.m * (c0 @ c0 * np.eye(3) - np.outer(c0, c0))  # parallel axis O_g -> c0
    L_P = model.Sr - skew(c0) @ model.A13
    M_ee = model.M_eta - model.A13.T @ model.A13 / model.m
    D = L_P @ np.linalg.solve(M_ee, L_P.T) if model.t else np.zeros((3, 3))
    D = 0.5 * (D + D.T)
    mu = float(np.max(np.abs(np.linalg.eigvals(np.linalg.solve(J, D)))))
    return {"c0": c0, "J": J, "D": D, "J_split": J - D, "mu": mu}


def _particle_accel_terms(model: FlexModel, q: np.ndarray, qd: np.ndarray, w: np.ndarray, wd: np.ndarray) -> np.ndarray:
    """e_i = wdot x rho_i + w x (w x rho_i) + 2 w x qdot_i (n, 3): a_i = a_O + e_i + qddot_i."""
    rho = model.r + q
    return cross(wd, rho) + cross(w, cross(w, rho)) + 2.0 * cross(w, qd)


def appendage_accelerations(
    model: FlexModel,
    eta: np.ndarray,
    eta_dot: np.ndarray,
    w: np.ndarray,
    wd: np.ndarray,
    fp: np.ndarray,
    F_bus: np.ndarray | None = None,
    a_O: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(a_O, eta_ddot). Mode B: give ``a_O``. Mode C: give ``F_bus`` (force on the base) and a_O is solved from

        | m E3    A13  | |a_O     |   | F_bus + sum f^i - wdot x mc - w x (w x mc) - 2 w x sum m_i qdot_i |
        | A13^T   E_t  | |eta_ddot| = | Phi^T [f^i - m_i e_i] - Omega^2 eta - C eta_dot                    |
    """
    q = deflections(model, eta)
    qd = deflections(model, eta_dot)
    mi = model.masses
    g = model.Phi.T @ (fp - mi[:, None] * _particle_accel_terms(model, q, qd, w, wd)).ravel()
    g -= model.K_eta @ eta + model.C_eta @ eta_dot
    if a_O is not None:
        return np.asarray(a_O, dtype=np.float64), solve_spd(model.M_eta, g - model.A13.T @ a_O)
    mc = model.mc0 + mi @ q
    rhs_t = F_bus + fp.sum(0) - cross(wd, mc) - cross(w, cross(w, mc)) - 2.0 * cross(w, mi @ qd)
    t = model.t
    A = np.empty((3 + t, 3 + t))
    A[:3, :3] = model.m * np.eye(3)
    A[:3, 3:] = model.A13
    A[3:, :3] = model.A13.T
    A[3:, 3:] = model.M_eta
    x = solve_spd(A, np.concatenate([rhs_t, g]))
    return x[:3], x[3:]


def appendage_loads(
    model: FlexModel,
    eta: np.ndarray,
    eta_dot: np.ndarray,
    eta_ddot: np.ndarray,
    a_O: np.ndarray,
    w: np.ndarray,
    wd: np.ndarray,
    fp: np.ndarray,
    D: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """Loads of the appendage, body axes.

    F_int, T_int: force and torque about O_g exerted by the appendage on the base (sum of f^i - m_i a_i).
    F_rig, T_rig: the same for the rigid undeformed appendage (q = qdot = qddot = 0); F_flex, T_flex: differences.
    tau_flex: about c0, sum (rho_i - c0) x f^i - sum m_i [(rho_i - c0) x a_i - (r_i - c0) x a_i^0]; with ``D``
    also tau_flex_split = tau_flex - D wdot - w x (D w).
    """
    q = deflections(model, eta)
    qd = deflections(model, eta_dot)
    qdd = deflections(model, eta_ddot)
    mi = model.masses[:, None]
    rho = model.r + q
    a = a_O + _particle_accel_terms(model, q, qd, w, wd) + qdd
    a0 = a_O + cross(wd, model.r) + cross(w, cross(w, model.r))
    load = fp - mi * a
    load0 = fp - mi * a0
    c0 = model.mc0 / model.m
    out = {
        "F_int": load.sum(0),
        "T_int": cross(rho, load).sum(0),
        "F_rig": load0.sum(0),
        "T_rig": cross(model.r, load0).sum(0),
        "tau_flex": (cross(rho - c0, fp) - mi * cross(rho - c0, a) + mi * cross(model.r - c0, a0)).sum(0),
        "cm_shift": model.masses @ q / model.m,
    }
    out["F_flex"] = out["F_int"] - out["F_rig"]
    out["T_flex"] = out["T_int"] - out["T_rig"]
    if D is not None:
        out["tau_flex_split"] = out["tau_flex"] - D @ wd - cross(w, D @ w)
    return out


def coupling_constants(params: Mapping[str, Any]) -> dict[str, Any]:
    """Mode-C constants for a scenario, from flexbody parameters: c0, J, D, J_split = J - D (the inertia to give
    the rigid attitude simulator when it receives ``tau_flex_split``), mu = rho(J^-1 D) (the plain C1 loop gain).
    Values as nested lists (TOML-ready) except mu."""
    from subsims.flexbody.config import build

    consts = inertia_split(build({**params, "mode": "free"}).model)
    return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in consts.items()}
