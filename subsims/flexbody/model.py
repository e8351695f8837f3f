"""Equations of motion of a flexible spacecraft, lumped-parameter idealization (Storch & Gates, CSDL-R-1582).

One rigid base (mass m_b, inertia I_b about its own mass centre, mass centre at s from the body origin O_g)
carries n particles (m_i at r_i, elastic displacement q_i in body axes) joined by massless structure of
stiffness K. All vectors are body components except R (inertial). Generalized accelerations
x = (Vdot, wdot, eta_ddot) solve A(t) x = F + U - (0; 0; Omega^2 eta) (8-1), with q = Phi eta (5-3).

The same code serves the unreduced equations in physical coordinates (3-2), (3-5), (3-9): take Phi = E_3n,
modal mass M and modal stiffness K (``physical_model``) - the report's Figure 3 with Phi = identity.

Deformation-dependent terms are split into the report's categories (chapter 4): 1 independent of q,
2 first order in q or qdot, 3 second order. ``mass_order`` keeps categories <= it in A, ``kin_order`` in U.

State vector: the report's Y (8-4) = (R, theta, eta, V, w, eta_dot), followed by the attitude quaternion
(w, x, y, z; body -> inertial). The quaternion is what is integrated; the theta slot holds the report's
1-2-3 Euler angles, re-derived from the quaternion after every step on their continuous branch (its
derivative slot is 0), so nothing is singular at cos(theta_2) = 0.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.linalg.lapack import dpotrf, dpotrs

from subsims.flexbody.kinematics import euler123_from_dcm, quat_rate, quat_to_dcm
from subsims.numerics import cross, rk4, skew, substeps

Loads = tuple[np.ndarray, np.ndarray, np.ndarray]  # (f0 (3,), tau0 (3,), fp (n, 3)), body axes


@dataclass(frozen=True, eq=False)
class FlexModel:
    """Constant data of the vehicle and its retained elastic coordinates (cached time-invariant terms)."""

    m_b: float
    I_b: np.ndarray  # (3, 3) about the base mass centre
    s: np.ndarray  # (3,) O_g -> base mass centre
    masses: np.ndarray  # (n,)
    r: np.ndarray  # (n, 3) undeformed particle positions from O_g
    Phi: np.ndarray  # (3n, t) q = Phi eta
    M_eta: np.ndarray  # (t, t) Phi^T M Phi (E_t for mass-normalized modes)
    K_eta: np.ndarray  # (t, t) Phi^T K Phi (Omega^2)
    C_eta: np.ndarray  # (t, t) modal damping 2 zeta_k w_k [EXT], zero by default
    mass_order: int = 3
    kin_order: int = 3
    # derived, category-1 ("time-invariant") terms
    n: int = field(init=False)
    t: int = field(init=False)
    m: float = field(init=False)
    mc0: np.ndarray = field(init=False)
    I1: np.ndarray = field(init=False)
    Phi_p: np.ndarray = field(init=False)
    Phi_pt: np.ndarray = field(init=False)
    A13: np.ndarray = field(init=False)
    Sr: np.ndarray = field(init=False)
    cmat: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        if self.mass_order not in (1, 2, 3) or self.kin_order not in (1, 2, 3):
            raise ValueError("mass_order and kin_order must each be 1, 2 or 3")
        mi, r = self.masses, self.r
        n, t = mi.size, self.Phi.shape[1]
        set_ = object.__setattr__
        set_(self, "I_b", 0.5 * (self.I_b + self.I_b.T))  # validated symmetric to 1e-12; make it exact
        set_(self, "n", n)
        set_(self, "t", t)
        set_(self, "m", float(self.m_b + mi.sum()))
        set_(self, "mc0", self.m_b * self.s + mi @ r)  # (3-4), category 1
        rr = np.einsum("i,ia,ib->ab", mi, r, r)
        rr = 0.5 * (rr + rr.T)
        set_(self, "cmat", rr)  # sum m_i r_i r_i^T (code "CMAT")
        # I1 = I_b - m_b s~ s~ - sum m_i r~ r~  (3-10), using -a~a~ = |a|^2 E - a a^T
        set_(self, "I1", self.I_b + self.m_b * (self.s @ self.s * np.eye(3) - np.outer(self.s, self.s))
             + np.trace(rr) * np.eye(3) - rr)
        Phi_p = self.Phi.reshape(n, 3, t)
        set_(self, "Phi_p", Phi_p)
        set_(self, "Phi_pt", np.ascontiguousarray(Phi_p.transpose(0, 2, 1)))  # (n, t, 3)
        set_(self, "A13", np.einsum("i,iat->at", mi, Phi_p))  # [m^1 ... m^n] Phi
        set_(self, "Sr", np.einsum("i,iab,ibt->at", mi, _skews(r), Phi_p))  # [m_i r_i~] Phi


def _skews(v: np.ndarray) -> np.ndarray:
    """Stack of skew matrices of the rows of v (k, 3) -> (k, 3, 3)."""
    z = np.zeros(v.shape[0])
    return np.stack(
        [np.stack([z, -v[:, 2], v[:, 1]], -1), np.stack([v[:, 2], z, -v[:, 0]], -1),
         np.stack([-v[:, 1], v[:, 0], z], -1)], 1)


def make_modal_model(
    m_b: float,
    I_b: np.ndarray,
    s: np.ndarray,
    masses: np.ndarray,
    r: np.ndarray,
    omega2: np.ndarray,
    Phi: np.ndarray,
    zeta: np.ndarray | None = None,
    mass_order: int = 3,
    kin_order: int = 3,
) -> FlexModel:
    """Truncated model (chapter 5): mass-normalized modes, Phi^T M Phi = E_t, Phi^T K Phi = Omega^2."""
    t = omega2.size
    zeta = np.zeros(t) if zeta is None else np.broadcast_to(np.asarray(zeta, dtype=np.float64), (t,))
    return FlexModel(
        float(m_b), np.asarray(I_b, float), np.asarray(s, float), np.asarray(masses, float), np.asarray(r, float),
        np.asarray(Phi, float).reshape(3 * len(masses), t), np.eye(t), np.diag(omega2),
        np.diag(2.0 * zeta * np.sqrt(omega2)), mass_order, kin_order,
    )


def physical_model(
    m_b: float, I_b: np.ndarray, s: np.ndarray, masses: np.ndarray, r: np.ndarray, K: np.ndarray,
    mass_order: int = 3, kin_order: int = 3,
) -> FlexModel:
    """Unreduced 6 + 3n model in physical coordinates (3-2), (3-5), (3-9): Phi = E, eta = q."""
    masses = np.asarray(masses, float)
    dof = 3 * masses.size
    return FlexModel(
        float(m_b), np.asarray(I_b, float), np.asarray(s, float), masses, np.asarray(r, float), np.eye(dof),
        np.diag(np.repeat(masses, 3)), np.asarray(K, float), np.zeros((dof, dof)), mass_order, kin_order,
    )


def deflections(model: FlexModel, eta: np.ndarray) -> np.ndarray:
    """Particle deflections q_i (n, 3) = Phi eta (5-3)."""
    return (model.Phi @ eta).reshape(model.n, 3)


# --------------------------------------------------------------------------------------------------
# Coefficient matrix A(t) (Figure 3) with the hierarchy of chapter 4.


def coefficient_matrix(model: FlexModel, q: np.ndarray, mass_order: int | None = None) -> np.ndarray:
    """A(t) of (8-1), symmetric positive definite when I_b is (chapter 6). q: (n, 3)."""
    order = model.mass_order if mass_order is None else mass_order
    mi, r = model.masses, model.r
    mc, inertia, A23 = model.mc0, model.I1, model.Sr  # category 1
    if order >= 2:
        mq = mi[:, None] * q
        mc = mc + mq.sum(0)  # mc_1
        rq = r.T @ mq  # sum m_i r_i q_i^T
        inertia = inertia + 2.0 * np.trace(rq) * np.eye(3) - (rq + rq.T)  # I_2 = -sum m_i (r~q~ + q~r~)
        A23 = A23 + cross(mq[:, None, :], model.Phi_pt).sum(0).T  # [m_i q_i~] Phi
        if order >= 3:
            qq = q.T @ mq
            inertia = inertia + np.trace(qq) * np.eye(3) - qq  # I_3 = -sum m_i q~q~
    t = model.t
    A = np.empty((6 + t, 6 + t))
    mc_x = skew(mc)
    A[:3, :3] = model.m * np.eye(3)
    A[:3, 3:6] = -mc_x
    A[3:6, :3] = mc_x
    A[3:6, 3:6] = 0.5 * (inertia + inertia.T)  # exact symmetry (BLAS sums may differ in the last bit)
    A[:3, 6:] = model.A13
    A[6:, :3] = model.A13.T
    A[3:6, 6:] = A23
    A[6:, 3:6] = A23.T  # = -Phi^T [m_i rho_i~] (5-4)
    A[6:, 6:] = model.M_eta
    return A


# --------------------------------------------------------------------------------------------------
# Nonlinear kinematic terms U (8-3), by category: (4-1)..(4-7).


def nonlinear_terms_by_category(
    model: FlexModel, V: np.ndarray, w: np.ndarray, q: np.ndarray, qd: np.ndarray
) -> dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """{category: (u_t (3,), u_r (3,), u_v (n, 3))} for categories 1, 2, 3 (u_t, u_v have none of order 3)."""
    mi, r = model.masses, model.r
    w2 = w @ w
    wxV = cross(w, V)
    mc1 = mi @ q
    mqd = mi @ qd
    w_x_qd = cross(w, qd)  # (n, 3)
    # (4-1), (4-2)
    ut1 = -model.m * wxV - (w @ model.mc0) * w + w2 * model.mc0
    ut2 = -2.0 * cross(w, mqd) - (w @ mc1) * w + w2 * mc1
    # (4-3), (4-4)
    uv1 = mi[:, None] * (-wxV[None, :] - np.outer(r @ w, w) + w2 * r)
    uv2 = mi[:, None] * (-2.0 * w_x_qd - np.outer(q @ w, w) + w2 * q)
    # (4-5), (4-6), (4-7)
    ur1 = (-cross(model.mc0, wxV) + cross(w, model.cmat @ w) - cross(w, model.I_b @ w)
           - model.m_b * (model.s @ w) * cross(model.s, w))
    rq_w = r.T @ (mi * (q @ w)) + q.T @ (mi * (r @ w))  # sum m_i (r_i q_i^T + q_i r_i^T) w
    ur2 = -cross(mc1, wxV) - 2.0 * mi @ cross(r, w_x_qd) + cross(w, rq_w)
    ur3 = -2.0 * mi @ cross(q, w_x_qd) + cross(w, q.T @ (mi * (q @ w)))
    zero3, zero_n = np.zeros(3), np.zeros_like(q)
    return {1: (ut1, ur1, uv1), 2: (ut2, ur2, uv2), 3: (zero3, ur3, zero_n)}


def nonlinear_terms(
    model: FlexModel, V: np.ndarray, w: np.ndarray, q: np.ndarray, qd: np.ndarray, kin_order: int | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(u_t, u_r, u_v) summed over categories <= kin_order: (3-6), (3-11), (3-3)."""
    order = model.kin_order if kin_order is None else kin_order
    if order == 3:
        return nonlinear_terms_full(model, V, w, q, qd)
    cats = nonlinear_terms_by_category(model, V, w, q, qd)
    ut, ur, uv = cats[1]
    for k in range(2, order + 1):
        ut, ur, uv = ut + cats[k][0], ur + cats[k][1], uv + cats[k][2]
    return ut, ur, uv


def nonlinear_terms_full(
    model: FlexModel, V: np.ndarray, w: np.ndarray, q: np.ndarray, qd: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """All three categories at once, in the compact forms with rho_i = r_i + q_i (3-3), (3-6), (3-11):

    u_t = -m w x V - 2 w x sum m_i qdot_i - (w.mc) w + |w|^2 mc
    u_v,i = m_i (-w x V - 2 w x qdot_i - (w.rho_i) w + |w|^2 rho_i)
    u_r = -mc x (w x V) + w x sum m_i rho_i (rho_i.w) - w x I_b w - m_b (s.w) s x w - 2 sum m_i rho_i x (w x qdot_i)
    """
    mi = model.masses
    rho = model.r + q
    mc = model.mc0 + mi @ q
    w2 = w @ w
    wxV = cross(w, V)
    w_x_qd = cross(w, qd)
    rho_w = rho @ w
    ut = -model.m * wxV - 2.0 * cross(w, mi @ qd) - (w @ mc) * w + w2 * mc
    uv = mi[:, None] * (-wxV - 2.0 * w_x_qd - rho_w[:, None] * w + w2 * rho)
    ur = (-cross(mc, wxV) + cross(w, (mi * rho_w) @ rho - model.I_b @ w) - model.m_b * (model.s @ w) * cross(model.s, w)
          - 2.0 * mi @ cross(rho, w_x_qd))
    return ut, ur, uv


def generalized_forces(model: FlexModel, q: np.ndarray, f0: np.ndarray, tau0: np.ndarray, fp: np.ndarray) -> np.ndarray:
    """F (8-2) = (f0 + sum f^i; tau0 + sum rho_i x f^i; Phi^T (f^1; ...; f^n))."""
    rho = model.r + q
    return np.concatenate([f0 + fp.sum(0), tau0 + cross(rho, fp).sum(0), model.Phi.T @ fp.ravel()])


def accelerations(
    model: FlexModel, V: np.ndarray, w: np.ndarray, eta: np.ndarray, eta_dot: np.ndarray, loads: Loads
) -> np.ndarray:
    """x = (Vdot, wdot, eta_ddot) from A x = F + U - (0; 0; Omega^2 eta + C eta_dot) (8-1) by Cholesky."""
    f0, tau0, fp = loads
    q = deflections(model, eta)
    qd = deflections(model, eta_dot)
    A = coefficient_matrix(model, q)
    ut, ur, uv = nonlinear_terms(model, V, w, q, qd)
    b = generalized_forces(model, q, f0, tau0, fp)
    b[:3] += ut
    b[3:6] += ur
    b[6:] += model.Phi.T @ uv.ravel() - model.K_eta @ eta - model.C_eta @ eta_dot
    return solve_spd(A, b)


def solve_spd(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve A x = b by Cholesky (the report's LEQT1P); LinAlgError if A is not positive definite."""
    c, info = dpotrf(A, lower=False, clean=False)
    if info != 0:
        raise np.linalg.LinAlgError(f"coefficient matrix A is not positive definite (Cholesky pivot {info})")
    x, info = dpotrs(c, b, lower=False)
    if info != 0:
        raise np.linalg.LinAlgError(f"Cholesky solve failed (info {info})")
    return x


# --------------------------------------------------------------------------------------------------
# First-order system (8-5) on the state (8-4) + quaternion.


def state_size(t: int) -> int:
    return 2 * t + 16


def split_state(Y: np.ndarray, t: int) -> tuple[np.ndarray, ...]:
    """(R, theta, eta, V, w, eta_dot, quat) views of Y."""
    return Y[0:3], Y[3:6], Y[6:6 + t], Y[6 + t:9 + t], Y[9 + t:12 + t], Y[12 + t:12 + 2 * t], Y[12 + 2 * t:]


def join_state(R, theta, eta, V, w, eta_dot, quat) -> np.ndarray:  # noqa: ANN001 - plain arrays
    return np.concatenate([R, theta, eta, V, w, eta_dot, quat]).astype(np.float64)


def state_derivative(model: FlexModel, Y: np.ndarray, loads: Loads) -> np.ndarray:
    """dY/dt (8-5): (R^14 V; 0 for the reported theta; eta_dot; A^-1[...]; 1/2 quat (x) (0, w))."""
    t = model.t
    R, theta, eta, V, w, eta_dot, quat = split_state(Y, t)
    x = accelerations(model, V, w, eta, eta_dot, loads)
    return np.concatenate([quat_to_dcm(quat) @ V, np.zeros(3), eta_dot, x, quat_rate(quat, w)])


def finish_step(Y: np.ndarray, t: int) -> np.ndarray:
    """Renormalize the quaternion and re-derive the continuous 1-2-3 angles from it (in a new array)."""
    Y = Y.copy()
    quat = Y[12 + 2 * t:]
    quat /= np.linalg.norm(quat)
    Y[3:6] = euler123_from_dcm(quat_to_dcm(quat), ref=Y[3:6])
    return Y


def integrate_samples(
    f: Callable[[float, np.ndarray, Any], np.ndarray],
    y0: np.ndarray,
    times: np.ndarray,
    h: float,
    finish: Callable[[np.ndarray], np.ndarray] | None = None,
    inputs: Callable[[np.ndarray], Sequence[Any]] | None = None,
) -> np.ndarray:
    """States at ``times`` (row 0 = y0) by the shared fixed-step RK4, steps of <= h landing on every sample time;
    ``f(t, y, row)`` with ``row`` from ``inputs(ts)`` (all RK times at once; None without)."""
    states, _, _ = rk4(f, np.array(y0, dtype=np.float64), times, substeps(times, h), inputs, finish=finish)
    return np.array(states)


def integrate(
    model: FlexModel,
    Y0: np.ndarray,
    times: np.ndarray,
    loads: Callable[[float, np.ndarray], Loads] | None,
    h: float,
    inputs: Callable[[np.ndarray], Sequence[Loads]] | None = None,
) -> np.ndarray:
    """Integrate (8-5) over ``times``: ``loads(t, Y)`` called at every RK stage (closed loop), or ``inputs(ts)``
    giving the loads at all the RK times ``ts`` at once (open loop, e.g. from a subsim's inputs)."""
    if inputs is None:
        def f(tt: float, y: np.ndarray, _: None) -> np.ndarray:
            return state_derivative(model, y, loads(tt, y))
    else:
        def f(tt: float, y: np.ndarray, row: Loads) -> np.ndarray:
            return state_derivative(model, y, row)
    return integrate_samples(f, Y0, times, h, lambda y: finish_step(y, model.t), inputs)


# --------------------------------------------------------------------------------------------------
# Energy and momenta (chapter 6).


def kinetic_energy(model: FlexModel, V: np.ndarray, w: np.ndarray, eta: np.ndarray, eta_dot: np.ndarray) -> float:
    """T = 1/2 U^T A U with U = (V, w, eta_dot) and the full (category 3) A."""
    U = np.concatenate([V, w, eta_dot])
    return 0.5 * float(U @ coefficient_matrix(model, deflections(model, eta), mass_order=3) @ U)


def kinetic_energy_direct(model: FlexModel, V: np.ndarray, w: np.ndarray, q: np.ndarray, qd: np.ndarray) -> float:
    """T = 1/2 m_b |V + w x s|^2 + 1/2 w.I_b w + 1/2 sum m_i |V + w x rho_i + qdot_i|^2 (chapter 6)."""
    vb = V + cross(w, model.s)
    vi = V[None, :] + cross(w, model.r + q) + qd
    return 0.5 * (model.m_b * vb @ vb + w @ model.I_b @ w + float(model.masses @ np.sum(vi * vi, axis=1)))


def elastic_energy(model: FlexModel, eta: np.ndarray) -> float:
    """1/2 eta^T Omega^2 eta (= 1/2 q^T K q without truncation)."""
    return 0.5 * float(eta @ model.K_eta @ eta)


def momenta(model: FlexModel, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inertial linear momentum P_I and angular momentum about the inertial origin H_O.

    The generalized momentum A U holds the body linear momentum p and the angular momentum h about O_g.
    """
    R, _, eta, V, w, eta_dot, quat = split_state(Y, model.t)
    U = np.concatenate([V, w, eta_dot])
    pu = coefficient_matrix(model, deflections(model, eta), mass_order=3) @ U
    C = quat_to_dcm(quat)
    P = C @ pu[:3]
    return P, cross(R, P) + C @ pu[3:6]
