"""The appendage alone for coupling to a rigid attitude simulator (spec §4.4-4.6): mode C exactness (AT-12), the
inertia split constants, mode B spin equilibrium (AT-11), the heavy-bus monolithic reference (AT-13), and a
Gauss-Seidel recursive-feedback run of mode C against that reference (the attitude side is a plain rigid-body RK4
written here, standing in for the project's attitude subsim configured with inertia J - D)."""

import numpy as np
import pytest

from subsims.flexbody import modal
from subsims.flexbody.appendage import appendage_accelerations, appendage_loads, inertia_split
from subsims.flexbody.config import build
from subsims.flexbody.kinematics import cross
from subsims.flexbody.model import accelerations
from subsims.flexbody.reference import heavy_bus_slew_reference
from subsims.flexbody.subsim import FlexBody
from subsims.flexbody.vehicle import BANG_BANG_SLEW, HEAVY_BUS
from subsims.flexbody_control.law import ControlParams, bang_bang_torque


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("nt", [2, 12])
def test_mode_c_reproduces_free_vehicle(seed, nt):
    """Feeding mode F's wdot into mode C gives mode F's eta_ddot and a_O, and J wdot + w x J w =
    tau0 - c0 x f0 + tau_flex (the partition adds no modelling error)."""
    rng = np.random.default_rng(seed)
    model = build({"n_modes": nt}).model
    V, w = rng.normal(size=3), rng.normal(scale=0.3, size=3)
    eta, eta_dot = rng.normal(scale=0.02, size=nt), rng.normal(scale=0.05, size=nt)
    f0, tau0, fp = rng.normal(size=3), rng.normal(size=3), rng.normal(size=(4, 3))
    x = accelerations(model, V, w, eta, eta_dot, (f0, tau0, fp))
    a_O, eta_dd = appendage_accelerations(model, eta, eta_dot, w, x[3:6], fp, F_bus=f0)
    np.testing.assert_allclose(eta_dd, x[6:], atol=1e-10 * max(1.0, np.abs(x[6:]).max()))
    np.testing.assert_allclose(a_O, x[:3] + cross(w, V), atol=1e-11)
    split = inertia_split(model)
    J, c0 = split["J"], split["c0"]
    loads = appendage_loads(model, eta, eta_dot, eta_dd, a_O, w, x[3:6], fp, split["D"])
    lhs = J @ x[3:6] + cross(w, J @ w)
    np.testing.assert_allclose(lhs, tau0 - cross(c0, f0) + loads["tau_flex"], atol=1e-8)
    # split form: (J - D) wdot + w x (J - D) w = tau_ext + tau_flex_split
    Jp = split["J_split"]
    rhs = tau0 - cross(c0, f0) + loads["tau_flex_split"]
    np.testing.assert_allclose(Jp @ x[3:6] + cross(w, Jp @ w), rhs, atol=1e-8)


def test_inertia_split_constants_of_the_sample():
    """Spec §4.5: J = diag(642.8333, 2.0833, 641.5833); D and mu for NT = 2, 4, 12."""
    expect = {2: ([0, 0, 617.1038], 0.96185), 4: ([617.1038, 0, 617.1038], 0.96185), 12: ([640.75, 0, 640.75], 0.99870)}
    for nt, (d, mu) in expect.items():
        split = inertia_split(build({"n_modes": nt}).model)
        np.testing.assert_allclose(split["J"], np.diag([642.8333333, 2.0833333, 641.5833333]), atol=1e-6)
        np.testing.assert_allclose(split["D"], np.diag(d), atol=1e-4)
        assert abs(split["mu"] - mu) < 1e-5
        assert np.linalg.eigvalsh(split["J_split"]).min() > 0
    assert abs(inertia_split(build({**HEAVY_BUS, "n_modes": 2}).model)["mu"] - 0.2337) < 1e-4


def test_tau_flex_is_D_wdot_at_rest():
    model = build({"n_modes": 4}).model
    D = inertia_split(model)["D"]
    zero_t, zero_p = np.zeros(4), np.zeros((4, 3))
    rng = np.random.default_rng(0)
    for wd in rng.normal(size=(5, 3)):
        a_O, edd = appendage_accelerations(model, zero_t, zero_t, np.zeros(3), wd, zero_p, F_bus=np.zeros(3))
        tau = appendage_loads(model, zero_t, zero_t, edd, a_O, np.zeros(3), wd, zero_p, D)
        np.testing.assert_allclose(tau["tau_flex"], D @ wd, rtol=1e-12, atol=1e-12 * np.abs(D @ wd).max())
        assert np.abs(tau["tau_flex_split"]).max() < 1e-11
    a_O, edd = appendage_accelerations(model, zero_t, zero_t, np.zeros(3), np.zeros(3), zero_p, F_bus=np.zeros(3))
    assert not np.any(appendage_loads(model, zero_t, zero_t, edd, a_O, np.zeros(3), np.zeros(3), zero_p)["tau_flex"])


def test_mode_b_spinning_base_equilibrium():
    """Spec AT-11: base spinning at 1 rad/s about body x through O_g, NT = 12, static deflection in equilibrium."""
    model = build({"n_modes": 12}).model
    K = modal.boom_stiffness(4, [[1, 2], [3, 4]], 10.0, 1e4, 4e4, 1e6)
    M = modal.particle_mass_matrix(model.masses)
    P = np.kron(np.eye(4), np.diag([0.0, 1.0, 1.0]))
    q = np.linalg.solve(K - M @ P, M @ P @ model.r.ravel())  # (K - W^2 M P) q = W^2 M P r, W = 1
    np.testing.assert_allclose(q.reshape(4, 3)[1], [0, 3.2001e-4, 0.05645475], atol=1e-8)
    eta = model.Phi.T @ M @ q
    w, zero3, zero_t = np.array([1.0, 0, 0]), np.zeros(3), np.zeros(12)
    a_O, eta_dd = appendage_accelerations(model, eta, zero_t, w, zero3, np.zeros((4, 3)), a_O=zero3)
    assert np.abs(eta_dd).max() < 1e-10
    loads = appendage_loads(model, eta, zero_t, eta_dd, a_O, w, zero3, np.zeros((4, 3)))
    np.testing.assert_allclose(loads["F_int"], [0, 1.500025, 3.0954559], atol=1e-6)
    np.testing.assert_allclose(loads["T_int"], [0, 1.547728, -0.750013], atol=1e-6)
    np.testing.assert_allclose(loads["F_rig"], [0, 1.5, 3.0], atol=1e-12)


# ---- heavy-bus bang-bang slew: monolithic reference and recursive-feedback mode C ------------------------

DT, NS, H_WIN = 0.01, 11, 0.1  # sample step, samples per window, window (spec AT-13)


@pytest.fixture(scope="module")
def mono():
    return heavy_bus_slew_reference(np.arange(2001) * DT, h=0.01)


def test_heavy_bus_monolithic_reference_values(mono):
    """Spec AT-13 table (7 digits): theta_3 (deg), omega_3 (deg/s), q_2x (ft) at t = 5, 10, 20 s, to the table's
    rounding (5e-8; measured 2.2e-8 to 4.5e-8, i.e. every printed digit)."""
    table = {5: (2.7211734, 1.1078985, 0.0152806), 10: (5.4221176, -0.0513986, -0.0034971),
             20: (5.4303216, 0.0487018, 0.0103159)}
    for t, (th3, w3, q2x) in table.items():
        k = int(round(t / DT))
        assert abs(np.degrees(mono["euler123"][k, 2]) - th3) <= 5e-8
        assert abs(np.degrees(mono["omega"][k, 2]) - w3) <= 5e-8
        assert abs(mono["q"][k, 3] - q2x) <= 5e-8
    np.testing.assert_allclose(mono["q"][:, 3], -mono["q"][:, 9], rtol=0, atol=1e-15)  # mirror; measured 1.4e-16


def rigid_attitude(J, w0, times, torque, h=0.01):
    """Stand-in attitude subsim: J wdot + w x J w = torque(t); outputs w and wdot at the samples."""
    Jinv = np.linalg.inv(J)

    def f(t, w):
        return Jinv @ (torque(t) - np.cross(w, J @ w))

    ws, w = [w0], w0.copy()
    for a, b in zip(times[:-1], times[1:]):
        n = max(1, int(np.ceil((b - a) / h - 1e-9)))
        hs = (b - a) / n
        for j in range(n):
            t = a + j * hs
            k1 = f(t, w)
            k2 = f(t + hs / 2, w + hs / 2 * k1)
            k3 = f(t + hs / 2, w + hs / 2 * k2)
            k4 = f(t + hs, w + hs * k3)
            w = w + hs / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        ws.append(w)
    ws = np.array(ws)
    return ws, np.array([f(t, w) for t, w in zip(times, ws)])


def linear(times, values):
    return lambda t: np.stack([np.interp(t, times, v) for v in values.T], axis=-1)  # t (k,) -> (k, m)


def run_stage(fb, y, J, w, times, control, tau):
    """One Gauss-Seidel stage: attitude with the torque guess, then the appendage with its w, wdot."""
    tau_in = linear(times, tau)
    ws, wds = rigid_attitude(J, w, times, lambda t: control + tau_in(t))
    u_w, u_wd = linear(times, ws), linear(times, wds)
    zeros = {"F_bus": np.zeros(3), "fp": np.zeros(12)}
    out, y_end = fb.advance(y, times, lambda t: {"omega": u_w(t), "omega_dot": u_wd(t), **zeros})
    return ws, out, y_end


def cosimulate_mode_c(t_end, split):
    """Gauss-Seidel recursive feedback, attitude -> flexbody, on tau_flex_split (C2) or tau_flex (C1)."""
    fb = FlexBody()
    y = fb.initial_state({**HEAVY_BUS, "mode": "attitude", "n_modes": 2})
    consts = inertia_split(fb.model)
    J = consts["J_split"] if split else consts["J"]
    port = "tau_flex_split" if split else "tau_flex"
    cp = ControlParams.from_mapping(BANG_BANG_SLEW)
    w, tau_last = np.zeros(3), np.zeros(3)
    log_w, log_q, stages = [], [], []
    for k in range(int(round(t_end / H_WIN))):
        times = (k * (NS - 1) + np.arange(NS)) * DT
        control = bang_bang_torque(cp, times[0] + H_WIN / 2)  # switches fall on window boundaries
        tau, stage, change = np.tile(tau_last, (NS, 1)), 0, np.inf
        while change > 1e-9 + 1e-9 * np.abs(tau).max():
            stage += 1
            assert stage < 60, f"window {k}: no convergence"
            ws, out, y_end = run_stage(fb, y, J, w, times, control, tau)
            change = np.abs(out[port] - tau).max()
            tau = out[port]
        stages.append(stage)
        w, y, tau_last = ws[-1], y_end, tau[-1]
        log_w.append(ws[:-1])
        log_q.append(out["q"][:-1])
    return np.concatenate(log_w), np.concatenate(log_q), stages


@pytest.mark.parametrize("split, t_end, max_stages", [(True, 6.0, 5), (False, 1.0, 17)])
def test_mode_c_recursive_feedback_matches_monolithic(mono, split, t_end, max_stages):
    """Spec AT-13 heavy bus: C2 (inertia split) over 0-6 s, through the torque reversal at 5 s, converges in <= 5
    stages per window (measured max 5, mean 4.0); C1 (no split, loop gain mu = 0.234) needs <= 17 (measured 15,
    run over 0-1 s only). Both stay within 5e-7 rad/s of the monolithic omega and 2e-5 ft of its q (measured
    C2: 1.0e-7 rad/s, 2.0e-6 ft)."""
    w, q, stages = cosimulate_mode_c(t_end, split)
    n = w.shape[0]
    assert max(stages) <= max_stages, max(stages)
    assert np.abs(w - mono["omega"][:n]).max() <= 5e-7
    assert np.abs(q - mono["q"][:n]).max() <= 2e-5


def test_coupling_constants_for_scenarios():
    from subsims.flexbody.appendage import coupling_constants

    c = coupling_constants(HEAVY_BUS)
    np.testing.assert_allclose(np.array(c["J_split"]), np.diag([2640.75, 2000.0, 2640.75 - 617.1038]), atol=1e-4)
    assert isinstance(c["J"], list) and abs(c["mu"] - 0.2337) < 1e-4
