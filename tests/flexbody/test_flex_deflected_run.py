"""The free vehicle with its booms deflected and vibrating, spinning about all three axes and loaded, through the
adapter (RK4), against a second integration of independently written equations.

The sample run (test_flex_sample_run.py) has q = 0 throughout, so it says nothing about the flexible terms. Here
the reference is Newton-Euler for the base and each particle in the body frame (the accelerations of a point
at rho = r + q: a_O + wdot x rho + w x (w x rho) + 2 w x qdot + qddot), projected on the retained modes, solved
for (Vdot, wdot, eta_ddot) and integrated by scipy's DOP853 at rtol 1e-12 with the attitude as a direction
cosine matrix (Cdot = C w~) instead of the model's quaternion. Nothing of the model's coefficient matrix A,
its nonlinear terms U or its integrator is used; the vehicle data (masses, r, Phi, Omega^2) are the inputs.
A dropped Coriolis term (any of the three 2 w x qdot terms) or a dropped deflection-dependent term moves
the result by far more than the RK4 error the bounds allow, and does not shrink with the step.
"""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from subsims.flexbody.config import build
from subsims.flexbody.kinematics import euler123_to_dcm, quat_to_dcm
from subsims.flexbody.subsim import FlexBody

Q0 = np.zeros((4, 3))
Q0[1] = [0.5, 0.0, 0.25]  # tip of boom A displaced along x and z (spec AT-7)
QD0 = np.zeros((4, 3))
QD0[3] = [-0.2, 0.0, 0.3]  # tip of boom B moving
PARAMS = {"n_modes": 4, "omega_deg_s": [3.0, 10.0, -5.0], "V0": [0.5, 5.0, -1.0], "q0": Q0.tolist(),
          "q_dot0": QD0.tolist()}
TIMES = np.arange(0.0, 5.0 + 1e-9, 0.25)
H = (0.005, 0.0025)  # RK4 steps of the two adapter runs
BOUNDS = {"R": 1.5e-7, "C": 1.5e-7, "V": 3e-6, "omega": 3e-6, "eta": 3e-6, "eta_dot": 6e-5}
TAU0 = np.array([0.3, -0.2, 0.5])  # lbf ft about O_g, body axes


def loads(t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(f0, tau0, fp): a steady torque, a swept force at O_g, and a force on the tip of boom B."""
    fp = np.zeros((4, 3))
    fp[3] = [0.1 * np.sin(1.3 * t), 0.0, 0.05 * np.cos(0.7 * t)]
    return np.array([0.2 * np.cos(0.5 * t), 0.0, 0.1]), TAU0, fp


def newton_euler_rates(setup, t: float, z: np.ndarray) -> np.ndarray:
    """d/dt of z = (R, C (9, row-major), V, w, eta, eta_dot) from momentum balance of base and particles."""
    m = setup.model
    nt = m.t
    C = z[3:12].reshape(3, 3)
    V, w, eta, eta_dot = z[12:15], z[15:18], z[18:18 + nt], z[18 + nt:]
    Phi = m.Phi.reshape(m.n, 3, nt)
    q, qd = Phi @ eta, Phi @ eta_dot
    rho = m.r + q
    f0, tau0, fp = loads(t)
    K = m.K_eta

    def residual(x: np.ndarray) -> np.ndarray:
        """Momentum-balance residuals for a batch of candidate accelerations x (k, 6 + t)."""
        Vd, wd, eta_dd = x[:, :3], x[:, 3:6], x[:, 6:]
        a_O = Vd + np.cross(w, V)  # inertial acceleration of O_g, body axes
        a_b = a_O + np.cross(wd, m.s) + np.cross(w, np.cross(w, m.s))
        a = (a_O[:, None, :] + np.cross(wd[:, None, :], rho) + np.cross(w, np.cross(w, rho)) + 2.0 * np.cross(w, qd)
             + np.einsum("iat,kt->kia", Phi, eta_dd))
        ma = m.masses[:, None] * a
        res_t = m.m_b * a_b + ma.sum(1) - f0 - fp.sum(0)
        res_r = (m.m_b * np.cross(m.s, a_b) + wd @ m.I_b.T + np.cross(w, m.I_b @ w) + np.cross(rho, ma).sum(1)
                 - tau0 - np.cross(rho, fp).sum(0))
        # modal equations: Phi^T (M a - f) + Omega^2 eta = 0 (mass-normalized modes)
        res_p = np.einsum("iat,kia->kt", Phi, ma - fp) + K @ eta
        return np.concatenate([res_t, res_r, res_p], axis=1)

    r = residual(np.vstack([np.zeros(6 + nt), np.eye(6 + nt)]))  # the residual is affine in x
    x = np.linalg.solve((r[1:] - r[0]).T, -r[0])
    w_x = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    return np.concatenate([C @ V, (C @ w_x).ravel(), x[:3], x[3:6], eta_dot, x[6:]])


def adapter_run(h: float) -> dict[str, np.ndarray]:
    fb = FlexBody()
    y0 = fb.initial_state({**PARAMS, "h": h})

    def u(t: float | np.ndarray) -> dict[str, np.ndarray]:  # a time, or an array of them (one row each)
        if np.ndim(t):
            rows = [u(float(x)) for x in t]
            return {k: np.array([r[k] for r in rows]) for k in rows[0]}
        f0, tau0, fp = loads(t)
        return {"f0": f0, "tau0": tau0, "fp": fp.ravel()}

    return fb.advance(y0, TIMES, u)[0]


def errors(setup, out: dict[str, np.ndarray], z: np.ndarray) -> dict[str, float]:
    nt = setup.model.t
    return {
        "R": np.abs(out["R"] - z[:, 0:3]).max(),
        "C": max(np.abs(quat_to_dcm(qq) - zz[3:12].reshape(3, 3)).max() for qq, zz in zip(out["quat"], z)),
        "V": np.abs(out["V"] - z[:, 12:15]).max(),
        "omega": np.abs(out["omega"] - z[:, 15:18]).max(),
        "eta": np.abs(out["eta"] - z[:, 18:18 + nt]).max(),
        "eta_dot": np.abs(out["eta_dot"] - z[:, 18 + nt:]).max(),
    }


@pytest.fixture(scope="module")
def runs():
    setup = build(PARAMS)
    nt = setup.model.t
    z0 = np.concatenate([setup.Y0[0:3], euler123_to_dcm(setup.Y0[3:6]).ravel(),
                         setup.Y0[6 + nt:12 + nt], setup.eta0, setup.eta_dot0])
    ref = solve_ivp(lambda t, z: newton_euler_rates(setup, t, z), (TIMES[0], TIMES[-1]), z0, method="DOP853",
                    t_eval=TIMES, rtol=1e-12, atol=1e-13)
    assert ref.success
    return setup, {h: adapter_run(h) for h in H}, ref.y.T


def test_the_case_deflects_and_vibrates(runs):
    """The flexible terms are exercised: deflections and rates of 0.1 ft and ft/s and more, all three body rates."""
    _, outs, _ = runs
    out = outs[H[0]]
    assert np.abs(out["q"]).max() > 0.1 and np.abs(out["q_dot"]).max() > 0.1
    assert np.all(np.abs(out["omega"]).max(axis=0) > 0.01)


def test_deflected_run_matches_a_second_integration(runs):
    """RK4 at h = 2.5 ms against DOP853, over 5 s: measured R 4.8e-8 ft, C 4.9e-8, V 1.1e-6 ft/s, omega 1.1e-6 rad/s,
    eta 1.0e-6, eta_dot 1.9e-5 (bounds 3x); halving h from 5 ms cuts every error 14.5-17x (required: > 12x), so
    the difference is RK4 truncation error, not a difference between the two sets of equations."""
    setup, outs, z = runs
    coarse, fine = errors(setup, outs[H[0]], z), errors(setup, outs[H[1]], z)
    for key, bound in BOUNDS.items():
        assert fine[key] <= bound, (key, fine)
        assert coarse[key] > 12.0 * fine[key], (key, coarse, fine)
