"""Physics of the swivel pair: analytic cases, the listing's own diagnostics, tables and initialization."""

from __future__ import annotations

import math

import numpy as np
import pytest

from subsims.lagrange_pair import aero
from subsims.lagrange_pair import model as m


def _spin_pair(omega: float = 0.7, gravity: bool = False) -> tuple[m.PairModel, np.ndarray, dict[str, float]]:
    """Spec §6.2 A1: a dumbbell spinning about z through the system CM, loads off, body frames aligned with I."""
    m_b, m_c, d_b, d_c = 100.0, 25.0, 3.0, 5.0
    pm = m.PairModel(
        m_b=m_b, i_b=m.inertia_matrix(40.0, 60.0, 70.0), m_c=m_c, i_c=m.inertia_matrix(10.0, 12.0, 15.0),
        l_b=np.array([d_b, 0.0, 0.0]), l_c=np.array([-d_c, 0.0, 0.0]), aero=False, gravity=gravity,
    )
    r_b = m_c * (d_b + d_c) / (m_b + m_c)
    r_c = m_b * (d_b + d_c) / (m_b + m_c)
    w = np.array([0.0, 0.0, omega])
    x = m.pack_state(pm, np.eye(3), np.eye(3), np.array([0.0, -omega * r_b, 0.0]), w, w, np.array([-r_b, 0.0, 0.0]))
    return pm, x, {"mu": m_b * m_c / (m_b + m_c), "d": d_b + d_c, "r_b": r_b, "r_c": r_c}


def test_spinning_pair_multiplier_is_mu_omega2_d() -> None:
    omega = 0.7
    pm, x, g = _spin_pair(omega)
    ev = m.evaluate(pm, x)
    expected = np.array([g["mu"] * omega**2 * g["d"], 0.0, 0.0])  # 78.4 lbf: pulls B toward the centre (+x)
    assert expected[0] == pytest.approx(78.4)
    np.testing.assert_allclose(ev.lam, expected, rtol=0, atol=1e-12 * expected[0])
    np.testing.assert_allclose(ev.R_C, [g["r_c"], 0.0, 0.0], atol=1e-14)
    np.testing.assert_allclose(ev.V_C, [0.0, omega * g["r_c"], 0.0], atol=1e-14)
    np.testing.assert_allclose(ev.DOm, np.zeros(12), atol=1e-13)  # relative equilibrium: body-frame rates constant


def test_spinning_pair_stays_in_relative_equilibrium_for_one_revolution() -> None:
    omega = 0.7
    pm, x, g = _spin_pair(omega)
    period = 2.0 * math.pi / omega
    lam_x = g["mu"] * omega**2 * g["d"]
    lams: list[np.ndarray] = []
    samples, _ = m.integrate(pm, x, np.linspace(0.0, period, 9), dt=0.01, hook=lambda t, ev: lams.append(ev.lam))
    # at the samples the joint force is unchanged; inside an RK step the stage attitudes are off SO(3) by
    # O((omega h)^2) = 1e-5, which bounds the stage values of the multiplier
    assert max(np.max(np.abs(ev.lam - [lam_x, 0.0, 0.0])) for ev in samples) <= 3e-13 * lam_x  # measured 3.5e-14
    assert max(np.max(np.abs(lam - [lam_x, 0.0, 0.0])) for lam in lams) <= 3e-6 * lam_x  # measured 3e-7
    # RK4 only has to rotate the attitude: after one period the SRB is back where it started
    np.testing.assert_allclose(samples[-1].R_B, [-g["r_b"], 0.0, 0.0], rtol=0, atol=1e-8)  # measured 9.7e-10
    np.testing.assert_allclose(samples[4].R_B, [g["r_b"], 0.0, 0.0], rtol=0, atol=1e-8)  # half a turn; 6.8e-10


def _swivel_force_newton_euler(m_b, i_b, l_b, w_b, m_c, i_c, l_c, w_c) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Force on B at the swivel (all vectors and inertias in one inertial frame), loads off, from Newton-Euler alone.

    Each body: a = f/m, alpha = I^-1 (l x f - w x I w); the swivel point accelerates at
    a + alpha x l + w x (w x l). The two swivel points must accelerate alike (C carries -f): three
    linear equations in f. Written without the model's [A], [ADOT] or [M]. Returns (f, alpha_B, alpha_C).
    """

    def gap(f: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        a_b = np.linalg.solve(i_b, np.cross(l_b, f) - np.cross(w_b, i_b @ w_b))
        a_c = np.linalg.solve(i_c, np.cross(l_c, -f) - np.cross(w_c, i_c @ w_c))
        acc_b = f / m_b + np.cross(a_b, l_b) + np.cross(w_b, np.cross(w_b, l_b))
        acc_c = -f / m_c + np.cross(a_c, l_c) + np.cross(w_c, np.cross(w_c, l_c))
        return acc_b - acc_c, a_b, a_c

    g0 = gap(np.zeros(3))[0]
    jac = np.column_stack([gap(e)[0] - g0 for e in np.eye(3)])  # gap is affine in f
    f = np.linalg.solve(jac, -g0)
    _, a_b, a_c = gap(f)
    return f, a_b, a_c


def test_tumbling_dumbbell_multiplier_and_accelerations_match_newton_euler() -> None:
    """Bodies turning at different rates about different axes, attitudes apart: [ADOT][Omega] = 5 ft/s^2 here.

    The spinning pair above has [ADOT] = 0 (both bodies turn together), so it cannot see the
    [ADOT][Omega] term of eq. 18; this state can: without it lambda is off by ~80 lbf (of 10).
    Measured: lambda to 1.1e-15 relative, [DOmega] to 4.4e-16 absolute (|DOmega| 1.7).
    """
    pm = m.PairModel(m_b=100.0, i_b=m.inertia_matrix(40.0, 60.0, 70.0, 3.0, -2.0, 1.5), m_c=25.0,
                     i_c=m.inertia_matrix(10.0, 12.0, 15.0, -1.0, 0.5, 2.0),
                     l_b=np.array([3.0, 0.2, -0.1]), l_c=np.array([-5.0, 0.3, 0.4]), aero=False, gravity=False)
    abi, aci = m.dcm_321(0.5, -0.35, 0.2), m.dcm_321(-0.7, 0.9, 0.1)
    v_b, w_b, w_c = np.array([3.0, -1.0, 2.0]), np.array([0.3, -0.2, 0.7]), np.array([1.1, 0.4, -0.5])
    ev = m.evaluate(pm, m.pack_state(pm, abi, aci, v_b, w_b, w_c, np.array([10.0, -5.0, -9000.0])))
    assert np.linalg.norm(ev.ADOT @ ev.Om) > 5.0  # the term is exercised
    aib, aic = abi.T, aci.T
    f, alpha_b, alpha_c = _swivel_force_newton_euler(
        pm.m_b, aib @ pm.i_b @ abi, aib @ pm.l_b, aib @ w_b, pm.m_c, aic @ pm.i_c @ aci, aic @ pm.l_c, aic @ w_c)
    lam = aci @ f  # the swivel force on B, C axes
    np.testing.assert_allclose(ev.lam, lam, rtol=0, atol=1e-14 * np.abs(lam).max())
    v_c = ev.V_C  # eq. 20; checked against the swivel-point velocity below
    np.testing.assert_allclose(aic @ v_c, aib @ (v_b + np.cross(w_b, pm.l_b)) - aic @ np.cross(w_c, pm.l_c),
                               rtol=0, atol=1e-14)
    dom = np.concatenate([abi @ f / pm.m_b - np.cross(w_b, v_b), abi @ alpha_b,  # body-axis rates of V and W
                          -aci @ f / pm.m_c - np.cross(w_c, v_c), aci @ alpha_c])
    np.testing.assert_allclose(ev.DOm, dom, rtol=0, atol=4e-15)


def test_uniform_gravity_does_not_change_the_spin_multiplier() -> None:
    omega = 0.7
    pm, x, g = _spin_pair(omega, gravity=True)
    lam = m.evaluate(pm, x).lam
    np.testing.assert_allclose(lam, [g["mu"] * omega**2 * g["d"], 0.0, 0.0], atol=1e-11)


def test_free_fall_gives_zero_multiplier() -> None:
    """Spec A2: gravity only, no rotation; both bodies fall together, the swivel carries nothing."""
    p = m.merged_params({"aero": False, "gravity": True})
    pm = m.build_model(p)
    abi = m.dcm_321(0.5, -0.35, 0.2)
    aci = m.dcm_321(-0.7, 0.9, 0.1)
    x = m.pack_state(pm, abi, aci, abi @ np.array([120.0, 20.0, -50.0]), np.zeros(3), np.zeros(3),
                     np.array([10.0, -5.0, -9000.0]))
    mg = pm.m_b * pm.g
    evs: list[m.Evaluation] = []
    m.integrate(pm, x, np.array([0.0, 10.0]), dt=0.05, hook=lambda t, ev: evs.append(ev))
    assert max(np.max(np.abs(ev.lam)) for ev in evs) <= 1e-12 * mg
    ev = evs[0]
    np.testing.assert_allclose(ev.DOm[0:3], abi @ [0.0, 0.0, pm.g], atol=1e-12)  # VDOT_B = ABI g
    np.testing.assert_allclose(ev.DOm[6:9], aci @ [0.0, 0.0, pm.g], atol=1e-12)
    np.testing.assert_allclose(ev.DOm[[3, 4, 5, 9, 10, 11]], 0.0, atol=1e-15)


def test_mass_matrix_times_inverse_is_identity() -> None:
    """The listing prints [M][MINV] as a check (L378-L387); use non-zero products of inertia."""
    pm = m.build_model(m.merged_params({"inertia_B": (9.5e4, 9.5e6, 9.4e6, 1.2e3, -2.5e3, 7e2),
                                        "inertia_C": (2.0e4, 1.5e4, 1.6e4, 300.0, 150.0, -80.0)}))
    np.testing.assert_allclose(pm.M @ pm.MINV, np.eye(12), rtol=0, atol=1e-12)
    assert pm.M[3, 4] == -1.2e3 and pm.M[9, 11] == -150.0  # IMATRX sign convention (assumed)


def _listing_a_and_adot(acb: np.ndarray, omb: np.ndarray, omc: np.ndarray, labb: np.ndarray,
                        lacc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """[A] and [ADOT] written element by element as in the listing (1-based there, 0-based here)."""
    a = np.zeros((3, 12))
    ad = np.zeros((3, 12))
    a[:, 0:3] = acb
    for i in range(3):
        a[i, 3] = -a[i, 1] * labb[2] + a[i, 2] * labb[1]
        a[i, 4] = +a[i, 0] * labb[2] - a[i, 2] * labb[0]
        a[i, 5] = -a[i, 0] * labb[1] + a[i, 1] * labb[0]
    a[0, 6] = a[1, 7] = a[2, 8] = -1.0
    a[0, 10], a[0, 11] = -lacc[2], +lacc[1]
    a[1, 9], a[1, 11] = +lacc[2], -lacc[0]
    a[2, 9], a[2, 10] = -lacc[1], +lacc[0]
    def A(i: int, j: int) -> float:  # noqa: N802 - the listing's 1-based A(I,J)
        return a[i - 1, j - 1]

    omb_, omc_ = np.concatenate([[0.0], omb]), np.concatenate([[0.0], omc])  # OMB(1..3), OMC(1..3)
    OMB, OMC = omb_.__getitem__, omc_.__getitem__  # noqa: N806
    ad[0, 0] = +OMC(3) * A(2, 1) - OMC(2) * A(3, 1) + OMB(3) * A(1, 2) - OMB(2) * A(1, 3)
    ad[0, 1] = +OMC(3) * A(2, 2) - OMC(2) * A(3, 2) - OMB(3) * A(1, 1) + OMB(1) * A(1, 3)
    ad[0, 2] = +OMC(3) * A(2, 3) - OMC(2) * A(3, 3) + OMB(2) * A(1, 1) - OMB(1) * A(1, 2)
    ad[1, 0] = -OMC(3) * A(1, 1) + OMC(1) * A(3, 1) + OMB(3) * A(2, 2) - OMB(2) * A(2, 3)
    ad[1, 1] = -OMC(3) * A(1, 2) + OMC(1) * A(3, 2) - OMB(3) * A(2, 1) + OMB(1) * A(2, 3)
    ad[1, 2] = -OMC(3) * A(1, 3) + OMC(1) * A(3, 3) + OMB(2) * A(2, 1) - OMB(1) * A(2, 2)
    ad[2, 0] = +OMC(2) * A(1, 1) - OMC(1) * A(2, 1) + OMB(3) * A(3, 2) - OMB(2) * A(3, 3)
    ad[2, 1] = +OMC(2) * A(1, 2) - OMC(1) * A(2, 2) - OMB(3) * A(3, 1) + OMB(1) * A(3, 3)
    ad[2, 2] = +OMC(2) * A(1, 3) - OMC(1) * A(2, 3) + OMB(2) * A(3, 1) - OMB(1) * A(3, 2)
    for i in range(3):
        ad[i, 3] = -ad[i, 1] * labb[2] + ad[i, 2] * labb[1]
        ad[i, 4] = +ad[i, 0] * labb[2] - ad[i, 2] * labb[0]
        ad[i, 5] = -ad[i, 0] * labb[1] + ad[i, 1] * labb[0]
    return a, ad


def test_constraint_matrices_match_listing_element_formulas() -> None:
    pm = m.build_model(m.merged_params({"attach_B": (70.0, 2.0, -3.0), "attach_C": (150.0, -4.0, 6.0)}))
    _, _, _, x = m.setup({"attach_B": (70.0, 2.0, -3.0), "attach_C": (150.0, -4.0, 6.0),
                          "rates_B_deg": (3.0, 5.0, -2.0), "rates_C_deg": (10.0, -10.0, 5.0)})
    ev = m.evaluate(pm, x)
    a, ad = _listing_a_and_adot(ev.ACB, ev.W_B, ev.W_C, pm.l_b, pm.l_c)
    np.testing.assert_allclose(ev.A, a, rtol=0, atol=1e-13)
    np.testing.assert_allclose(ev.ADOT, ad, rtol=0, atol=1e-13)
    assert np.array_equal(ev.A[:, 6:12], a[:, 6:12])  # constant cells: exactly the listed entries


def test_acceleration_constraint_holds_at_every_evaluation() -> None:
    """The listing's diagnostic pair ADOMEG = -ADOTOM (eq. 13), over 5 s of the aero case, every RK stage."""
    pm, dt, _, x0 = m.setup({})
    worst = [0.0]

    def check(t: float, ev: m.Evaluation) -> None:
        adomeg, adotom = ev.A @ ev.DOm, ev.ADOT @ ev.Om
        worst[0] = max(worst[0], float(np.max(np.abs(adomeg + adotom)) / max(1.0, np.max(np.abs(adomeg)))))

    m.integrate(pm, x0, np.array([0.0, 5.0]), dt=dt, hook=check)
    assert worst[0] <= 1e-9


def test_constraint_loads_obey_third_law_and_act_at_the_swivel() -> None:
    pm, dt, _, x0 = m.setup({})
    samples, _ = m.integrate(pm, x0, np.array([0.0, 1.0, 2.0]), dt=dt)
    for ev in samples:
        scale = np.linalg.norm(ev.lam)
        f_b, f_c = ev.FA[0:3], ev.FA[6:9]
        np.testing.assert_allclose(ev.ABI.T @ f_b + ev.ACI.T @ f_c, 0.0, atol=1e-9 * scale)
        np.testing.assert_allclose(ev.FA[3:6], m.cross(pm.l_b, f_b), atol=1e-9 * scale * 70.0)
        np.testing.assert_allclose(ev.FA[9:12], m.cross(pm.l_c, f_c), atol=1e-9 * scale * 150.0)
        np.testing.assert_array_equal(f_c, -ev.lam)


def test_external_loads_switch_zeroes_aero_and_gravity() -> None:
    """IFE = 0 (L899-L904): aero=False, gravity=False."""
    pm, _, _, x0 = m.setup({"aero": False, "gravity": False})
    ev = m.evaluate(pm, x0)
    assert not ev.FL.any() and not ev.FG.any() and not ev.FE.any()
    pm_on, _, _, _ = m.setup({})
    ev_on = m.evaluate(pm_on, x0)
    assert np.abs(ev_on.FL).max() > 1e4 and np.abs(ev_on.FG).max() > 1e4


def test_initial_conditions_follow_the_listing() -> None:
    """Spec P7/P8: alpha_B, phia_B, |V_B| and R_B at TSTART; XXD(30) = VIBI(3)."""
    pm, _, _, x0 = m.setup({"phia_B_deg": 25.0, "bank_B_deg": 10.0, "azimuth_B_deg": 30.0})
    ev = m.evaluate(pm, x0)
    speed, alpha, phia = aero.incidence(ev.V_B)
    assert speed == pytest.approx(300.0, abs=1e-12)
    assert alpha == pytest.approx(160.0 * m.DEG, abs=1e-12)
    assert phia == pytest.approx(25.0 * m.DEG, abs=1e-12)
    np.testing.assert_array_equal(x0[27:30], [0.0, 0.0, -15000.0])
    xdot = m.derivative(pm, ev)
    vibi = 300.0 * np.array([math.cos(-60 * m.DEG) * math.cos(30 * m.DEG), math.cos(-60 * m.DEG) * math.sin(30 * m.DEG),
                             -math.sin(-60 * m.DEG)])
    np.testing.assert_allclose(xdot[27:30], vibi, atol=1e-12)
    np.testing.assert_allclose(m.euler_321(ev.ACI), [0.0, -60.0 * m.DEG, 0.0], atol=1e-15)


def test_tables_reproduce_listing_nodes() -> None:
    """Spec P10: at a node the lookup returns the node value."""
    assert float(np.interp(147.0, aero.SRB_TABLE.alpha_deg, aero.SRB_TABLE.ca)) == -3.65
    assert float(np.interp(15.0, aero.CHUTE_TABLE.alpha_deg, aero.CHUTE_TABLE.ca)) == 0.61
    assert aero.density(14000.0) == 0.0015086
    assert aero.density(-100.0) == 0.0022964 and aero.density(50000.0) == 0.0006306  # clamped ends (assumed)


def test_aero_signs_oppose_motion() -> None:
    """Positive CA is drag when flying nose first; the SRB near alpha 180 deg (CA < 0) is pushed along +x."""
    f, _ = aero.body_aero_loads(np.array([300.0, 0.0, 0.0]), 0.002, aero.CHUTE_TABLE)
    assert f[0] < 0.0 and f[1] == 0.0 and f[2] == 0.0
    f, _ = aero.body_aero_loads(np.array([-300.0, 0.0, 0.0]), 0.002, aero.SRB_TABLE)
    assert f[0] > 0.0
    f, mo = aero.body_aero_loads(np.array([300.0, 0.0, 30.0]), 0.002, aero.CHUTE_TABLE)  # alpha ~ 5.7 deg, phia 0
    assert f[2] < 0.0 and mo[1] < 0.0  # normal force opposes w; pitch moment restoring (statically stable)
    f, mo = aero.body_aero_loads(np.zeros(3), 0.002, aero.SRB_TABLE)
    assert not f.any() and not mo.any()
