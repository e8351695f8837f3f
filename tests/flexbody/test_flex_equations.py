"""The assembled equations against an independent Newton-Euler residual (spec AT-2) and their structure."""

import numpy as np
import pytest

from subsims.flexbody import modal
from subsims.flexbody.config import build
from subsims.flexbody.model import (
    accelerations,
    coefficient_matrix,
    deflections,
    make_modal_model,
    nonlinear_terms,
    nonlinear_terms_by_category,
    physical_model,
    split_state,
    state_derivative,
)
from subsims.flexbody.vehicle import SAMPLE_VEHICLE


def random_geometry(rng, n):
    """A random vehicle: SPD I_b, offset s, n particles, random SPD stiffness."""
    a = rng.normal(size=(3, 3))
    I_b = a @ a.T + 0.5 * np.eye(3)
    masses = rng.uniform(0.2, 2.0, n)
    r = rng.normal(scale=5.0, size=(n, 3))
    b = rng.normal(size=(3 * n, 3 * n))
    K = 50.0 * (b @ b.T + 3 * n * np.eye(3 * n))
    return 3.0, I_b, rng.normal(size=3), masses, r, K


def newton_euler_residual(m, V, w, eta, eta_dot, x, loads, K):
    """Residuals of momentum balance for base + particles with accelerations x = (Vdot, wdot, eta_ddot)."""
    f0, tau0, fp = loads
    Vd, wd, eta_dd = x[:3], x[3:6], x[6:]
    q, qd, qdd = deflections(m, eta), deflections(m, eta_dot), deflections(m, eta_dd)
    rho = m.r + q
    a_O = Vd + np.cross(w, V)
    a_b = a_O + np.cross(wd, m.s) + np.cross(w, np.cross(w, m.s))
    a = a_O + np.cross(wd, rho) + np.cross(w, np.cross(w, rho)) + 2 * np.cross(w, qd) + qdd
    ma = m.masses[:, None] * a
    res_T = m.m_b * a_b + ma.sum(0) - f0 - fp.sum(0)
    res_R = (m.m_b * np.cross(m.s, a_b) + m.I_b @ wd + np.cross(w, m.I_b @ w) + np.cross(rho, ma).sum(0)
             - tau0 - np.cross(rho, fp).sum(0))
    res_P = m.Phi.T @ (ma - fp + (K @ q.ravel()).reshape(-1, 3)).ravel()
    return np.concatenate([res_T, res_R, res_P])


def random_case(rng, geometry, t):
    m_b, I_b, s, masses, r, K = geometry
    omega2, Phi = modal.constrained_modes(K, masses)
    model = make_modal_model(m_b, I_b, s, masses, r, omega2[:t], Phi[:, :t])
    n = masses.size
    state = (rng.normal(size=3), rng.normal(scale=0.5, size=3), rng.normal(scale=0.05, size=t),
             rng.normal(scale=0.1, size=t))
    loads = (rng.normal(size=3), rng.normal(size=3), rng.normal(size=(n, 3)))
    return model, K, state, loads


def sample_geometry():
    p = SAMPLE_VEHICLE
    K = modal.boom_stiffness(4, p["booms"], p["boom_L"], p["EI_x"], p["EI_z"], p["EA"])
    return p["m_b"], np.array(p["I_b"]), np.array(p["s"]), np.array(p["masses"]), np.array(p["r"]), K


@pytest.mark.parametrize("seed", range(10))
@pytest.mark.parametrize("which, t", [("sample", 2), ("sample", 12), ("random", 5), ("random", 9)])
def test_newton_euler_residual(seed, which, t):
    rng = np.random.default_rng(seed)
    geometry = sample_geometry() if which == "sample" else random_geometry(rng, 3)
    model, K, (V, w, eta, eta_dot), loads = random_case(rng, geometry, t)
    x = accelerations(model, V, w, eta, eta_dot, loads)
    res = newton_euler_residual(model, V, w, eta, eta_dot, x, loads, K)
    scale = 1.0 + max(np.abs(np.concatenate([loads[0], loads[1], loads[2].ravel()])).max(), 1.0)
    assert np.abs(res).max() <= 1e-9 * scale * max(1.0, np.abs(K).max() / 1e3)
    # A is exactly symmetric, positive definite, and the Jacobian of the residual w.r.t. x
    A = coefficient_matrix(model, deflections(model, eta))
    np.testing.assert_array_equal(A, A.T)
    assert np.linalg.eigvalsh(A).min() > 0
    r0 = newton_euler_residual(model, V, w, eta, eta_dot, np.zeros(6 + t), loads, K)
    jac = np.column_stack([newton_euler_residual(model, V, w, eta, eta_dot, e, loads, K) - r0 for e in np.eye(6 + t)])
    np.testing.assert_allclose(jac, A, atol=1e-10 * np.abs(A).max())


@pytest.mark.parametrize("seed", range(5))
def test_hierarchy_categories_sum_to_compact_terms(seed):
    rng = np.random.default_rng(seed)
    model, K, (V, w, eta, eta_dot), _ = random_case(rng, random_geometry(rng, 4), 7)
    q, qd = deflections(model, eta), deflections(model, eta_dot)
    cats = nonlinear_terms_by_category(model, V, w, q, qd)
    full = nonlinear_terms(model, V, w, q, qd)  # kin_order 3: compact forms (3-3), (3-6), (3-11)
    for k in range(3):
        split = cats[1][k] + cats[2][k] + cats[3][k]
        np.testing.assert_allclose(split, full[k], atol=1e-11 * (1 + np.abs(full[k]).max()))
    # category 3 of u_t and u_v is empty; categories 2, 3 vanish with q = qdot = 0
    assert not cats[3][0].any() and not cats[3][2].any()
    zero = nonlinear_terms_by_category(model, V, w, 0 * q, 0 * qd)
    assert all(not np.any(zero[c][k]) for c in (2, 3) for k in range(3))
    # lower orders drop terms
    lower = nonlinear_terms(model, V, w, q, qd, kin_order=1)
    assert np.abs(lower[1] - full[1]).max() > 1e-6


def test_mass_order_drops_deformation_terms_of_A():
    rng = np.random.default_rng(3)
    model, *_ = random_case(rng, random_geometry(rng, 3), 6)
    q = rng.normal(scale=0.1, size=(3, 3))
    A1, A2, A3 = (coefficient_matrix(model, q, mass_order=k) for k in (1, 2, 3))
    np.testing.assert_array_equal(A1, coefficient_matrix(model, 0 * q))
    assert np.abs(A2 - A1).max() > 1e-3 and np.abs(A3 - A2).max() > 1e-4
    # I_3 = -sum m_i q~ q~ is the only category-3 term
    d = A3 - A2
    assert np.abs(np.delete(np.delete(d, [3, 4, 5], 0), [3, 4, 5], 1)).max() == 0.0


@pytest.mark.parametrize("seed", range(5))
def test_all_modes_reproduce_unreduced_particle_equations(seed):
    """t = 3n: q_ddot = Phi eta_ddot and (Vdot, wdot) equal the physical-coordinate equations (3-2), (3-5), (3-9)."""
    rng = np.random.default_rng(seed)
    geometry = random_geometry(rng, 4)
    m_b, I_b, s, masses, r, K = geometry
    model, _, (V, w, eta, eta_dot), loads = random_case(rng, geometry, 12)
    phys = physical_model(m_b, I_b, s, masses, r, K)
    q, qd = model.Phi @ eta, model.Phi @ eta_dot
    x_modal = accelerations(model, V, w, eta, eta_dot, loads)
    x_phys = accelerations(phys, V, w, q, qd, loads)
    np.testing.assert_allclose(x_modal[:6], x_phys[:6], rtol=1e-9, atol=1e-10)
    np.testing.assert_allclose(model.Phi @ x_modal[6:], x_phys[6:], rtol=1e-9, atol=1e-10 * np.abs(x_phys).max())
    # and with fewer modes they differ (truncation is not exact)
    trunc, *_ = random_case(np.random.default_rng(seed), geometry, 4)
    x_trunc = accelerations(trunc, V, w, eta[:4], eta_dot[:4], loads)
    assert np.abs(x_trunc[:6] - x_phys[:6]).max() > 1e-8


def test_sample_initial_derivatives():
    """Spec §2.3: the sample run's derivatives at t = 0 (to 1e-9)."""
    setup = build({})
    model = setup.model
    zero = (np.zeros(3), np.zeros(3), np.zeros((4, 3)))
    dY = state_derivative(model, setup.Y0, zero)
    R_dot, _, eta_dot, x_V, x_w, eta_dd, _ = split_state(dY, 2)
    np.testing.assert_allclose(R_dot, [0, 4.98097349, 0.43577871], atol=1e-8)
    np.testing.assert_allclose(x_V, [-0.015230871, 0, 0.030461742], atol=1e-9)
    np.testing.assert_allclose(x_w, 0, atol=1e-12)
    np.testing.assert_allclose(eta_dd, 0, atol=1e-12)
    _, theta, eta, V, w, ed, _ = split_state(setup.Y0, 2)
    ut, ur, _ = nonlinear_terms(model, V, w, deflections(model, eta), deflections(model, ed))
    np.testing.assert_allclose(ut, [-0.12184697, 0, 0.24369394], atol=1e-8)
    np.testing.assert_allclose(ur, [0.12184697, 0, 0.06092348], atol=1e-8)
    # spec AT-1 mass properties
    assert model.m == 8.0
    np.testing.assert_allclose(model.mc0, [-4, 4, 8], rtol=1e-12)
    np.testing.assert_allclose(model.I1, [[652.8333333333334, 2, 4], [2, 12.083333333333334, -4],
                                          [4, -4, 645.5833333333334]], rtol=1e-12)
