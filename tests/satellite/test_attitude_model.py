"""Attitude dynamics: DCM (eq. 15), Euler rates (eq. 14), torques (eqs. 16-17), conservation, singularity."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.subsim import ModelError
from subsims.attitude.model import (
    AttitudeParams,
    EulerSingularityError,
    attitude_derivative,
    dcm2ang321,
    dcm321,
    dcm321_batch,
    euler_rates,
)
from subsims.attitude.subsim import Attitude
from subsims.satellite import constants as C

ZERO_GAINS = {g: 0.0 for g in ("a0", "a1", "b0", "b1", "c0", "c1")}


def eq15(phi: np.ndarray) -> np.ndarray:
    """The paper's eq. 15 written out as its three factors."""
    x, y, z = phi
    r1 = np.array([[1, 0, 0], [0, math.cos(x), math.sin(x)], [0, -math.sin(x), math.cos(x)]])
    r2 = np.array([[math.cos(y), 0, -math.sin(y)], [0, 1, 0], [math.sin(y), 0, math.cos(y)]])
    r3 = np.array([[math.cos(z), math.sin(z), 0], [-math.sin(z), math.cos(z), 0], [0, 0, 1]])
    return r1 @ r2 @ r3


def skew(w: np.ndarray) -> np.ndarray:
    return np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20011001)


def test_dcm_orthonormal_and_eq15(rng: np.random.Generator) -> None:
    phis = rng.uniform(-math.pi, math.pi, size=(200, 3))
    phis[:, 1] /= 2.0
    batch = dcm321_batch(phis)
    for phi, ab in zip(phis, batch):
        a = np.array(dcm321(phi))
        np.testing.assert_allclose(a, eq15(phi), rtol=0, atol=1e-15)
        np.testing.assert_allclose(a @ a.T, np.eye(3), rtol=0, atol=1e-15)
        assert np.linalg.det(a) == pytest.approx(1.0, abs=1e-14)
        np.testing.assert_array_equal(ab, a)
        # inverse for output limiting: round trip inside the principal ranges
        np.testing.assert_allclose(dcm2ang321(a), phi, rtol=0, atol=1e-12)
    # inertial -> body: a body rotated by +phi_z about z sees the inertial x axis at -phi_z
    a = np.array(dcm321([0.0, 0.0, 0.3]))
    np.testing.assert_allclose(a @ [1.0, 0.0, 0.0], [math.cos(0.3), -math.sin(0.3), 0.0], atol=1e-16)


def test_euler_rates_match_dcm_kinematics(rng: np.random.Generator) -> None:
    """Eq. 14 is consistent with eq. 15: dA/dt = -[omega x] A for body rates omega."""
    for _ in range(50):
        phi = rng.uniform(-1.4, 1.4, 3)
        omega = rng.normal(size=3)
        phidot = np.array(euler_rates(phi, omega))
        eps = 1e-6
        da = (np.array(dcm321(phi + eps * phidot)) - np.array(dcm321(phi - eps * phidot))) / (2 * eps)
        np.testing.assert_allclose(da, -skew(omega) @ np.array(dcm321(phi)), rtol=0, atol=1e-8)


def test_euler_singularity_raises() -> None:
    with pytest.raises(EulerSingularityError, match="phi_y"):
        euler_rates([0.1, math.pi / 2, 0.2], [0.0, 0.0, 0.0])
    with pytest.raises(EulerSingularityError):  # jumped over +90 deg: phi_y = 91 deg
        euler_rates([0.0, math.radians(91.0), 0.0], [0.0, 0.01, 0.0])
    sim = Attitude()
    x0 = sim.initial_state({**ZERO_GAINS, "mu": 0.0, "phi0": [0.0, math.radians(89.9), 0.0],
                            "omega0": [0.0, 0.05, 0.0]})
    with pytest.raises(ModelError, match="singular"):  # reaches 90 deg after 0.035 s
        sim.advance(x0, np.linspace(0.0, 0.4, 5), lambda t: {"R": np.zeros(3), "torque": np.zeros(3)})
    with pytest.raises(ValueError, match="phi0"):
        Attitude().initial_state({"phi0": [0.0, math.pi / 2, 0.0]})


def test_torque_free_body_conserves_momentum_and_energy() -> None:
    """No gravity (R = 0 guard), no control, no torque: inertial angular momentum and energy constant."""
    q = np.array(dcm321([0.2, -0.1, 0.3]))
    full = q @ np.diag([11250.0, 193125.0, 173812.5]) @ q.T  # a non-principal inertia matrix
    for inertia, omega0 in ((C.INERTIA, [0.02, 0.003, -0.004]), (full.tolist(), [0.01, -0.004, 0.002])):
        sim = Attitude()
        x0 = sim.initial_state({**ZERO_GAINS, "inertia": inertia, "omega0": omega0, "phi0": [0.1, 0.2, -0.3]})
        times = 0.1 * np.arange(6001)
        out, _ = sim.advance(x0, times, lambda t: {"R": np.zeros(3), "torque": np.zeros(3)})
        i_mat = np.array(inertia)
        w = out["omega"]
        energy = 0.5 * np.einsum("ni,ij,nj->n", w, i_mat, w)
        h_inertial = np.einsum("nji,nj->ni", dcm321_batch(out["phi"]), w @ i_mat.T)
        assert np.ptp(out["phi"][:, 0]) > 1.0  # it really rotated
        assert np.max(np.abs(energy / energy[0] - 1.0)) < 1e-9
        assert np.max(np.linalg.norm(h_inertial - h_inertial[0], axis=1)) / np.linalg.norm(h_inertial[0]) < 1e-9
        # omega_dot output is the Euler equation: I w_dot = -w x I w
        np.testing.assert_allclose(out["omega_dot"] @ i_mat.T, -np.cross(w, w @ i_mat.T), rtol=0, atol=1e-12)


def test_gravity_gradient_factor_three_and_sign() -> None:
    p = AttitudeParams.from_mapping({})
    rmag, theta = 6.7e6, 0.4
    rad = [rmag * math.cos(theta), rmag * math.sin(theta), 0.0]
    d = attitude_derivative([0.0] * 6, rad, [0.0] * 3, p)
    tz = 3.0 * C.GME / rmag**3 * math.cos(theta) * math.sin(theta) * (C.IYY - C.IXX)
    np.testing.assert_allclose(d[3:], [0.0, 0.0, tz / C.IZZ], rtol=1e-14, atol=1e-30)
    # the same body-frame geometry with a rotated body: R_inertial = A^T r_body
    phi = [0.3, -0.2, 1.1]
    a = np.array(dcm321(phi))
    d2 = attitude_derivative([*phi, 0.0, 0.0, 0.0], (a.T @ rad).tolist(), [0.0] * 3,
                             AttitudeParams.from_mapping(ZERO_GAINS))
    np.testing.assert_allclose(d2[3:], [0.0, 0.0, tz / C.IZZ], rtol=1e-12, atol=1e-18)  # round-off 1e-22
    # R = 0 (RF-C stage 0): the guard turns gravity gradient off
    assert attitude_derivative([0.0] * 6, [0.0] * 3, [0.0] * 3, p)[3:] == [0.0, 0.0, 0.0]


def test_control_and_external_torque() -> None:
    gains = {"a0": 1000.0, "a1": 100.0, "b0": 1000.0, "b1": 100.0, "c0": 0.0, "c1": 0.0}  # case 2
    p = AttitudeParams.from_mapping(gains)
    phi, omega, t_aero = [0.01, -0.02, 0.03], [1e-3, 2e-3, -3e-3], [0.1, 0.2, 0.3]
    d = attitude_derivative([*phi, *omega], [0.0] * 3, t_aero, p)
    t_c = np.array([-(1000 * 0.01 + 100 * 1e-3), -(1000 * -0.02 + 100 * 2e-3), 0.0])
    i = np.diag([C.IXX, C.IYY, C.IZZ])
    expected = np.linalg.solve(i, t_c + t_aero - np.cross(omega, i @ omega))
    np.testing.assert_allclose(d[3:], expected, rtol=1e-13)


def test_closed_loop_single_axis_closed_form() -> None:
    """Constant torque about x, x gains only: a damped oscillator with a closed-form solution (eq. 16 sign)."""
    a0, a1, torque = 1000.0, 100.0, 0.05
    sim = Attitude()
    x0 = sim.initial_state({**ZERO_GAINS, "a0": a0, "a1": a1, "mu": 0.0})
    times = 0.1 * np.arange(1001)
    out, _ = sim.advance(x0, times, lambda t: {"R": np.zeros(3), "torque": np.array([torque, 0.0, 0.0])})
    wn = math.sqrt(a0 / C.IXX)
    zeta = a1 / (2.0 * math.sqrt(a0 * C.IXX))
    wd = wn * math.sqrt(1.0 - zeta**2)
    decay = np.exp(-zeta * wn * times)
    exact = torque / a0 * (1.0 - decay * (np.cos(wd * times) + zeta * wn / wd * np.sin(wd * times)))
    # RK4 truncation at wn h = 0.03 is ~2e-7 of the amplitude; a wrong sign or gain is an O(1) error
    np.testing.assert_allclose(out["phi"][:, 0], exact, rtol=0, atol=1e-6 * torque / a0)
    assert np.all(out["phi"][:, 1:] == 0.0) and np.all(out["omega"][:, 1:] == 0.0)


def test_torque_read_at_rk_stage_times() -> None:
    """Torque linear in time about x: phi_x is a cubic, exact under RK4 only if u is read at the stage times."""
    sim = Attitude()
    x0 = sim.initial_state({**ZERO_GAINS, "mu": 0.0, "idiv": 2})
    a, b = 0.3, 0.7
    times = np.array([2.0, 2.1, 2.2, 2.3, 2.4])
    x_axis = [1.0, 0.0, 0.0]
    out, _ = sim.advance(x0, times, lambda t: {"R": np.zeros(3), "torque": np.multiply.outer(a + b * t, x_axis)})
    t0, tau = times[0], times - times[0]
    w = (a * tau + b * (times**2 - t0**2) / 2.0) / C.IXX
    phi = (a * tau**2 / 2.0 + b * ((times**3 - t0**3) / 6.0 - t0**2 * tau / 2.0)) / C.IXX
    np.testing.assert_allclose(out["omega"][:, 0], w, rtol=1e-13, atol=0)
    np.testing.assert_allclose(out["phi"][:, 0], phi, rtol=1e-12, atol=0)
    np.testing.assert_allclose(out["omega_dot"][:, 0], (a + b * times) / C.IXX, rtol=1e-14)


def test_adapter_contract_and_purity() -> None:
    sim = Attitude()
    x0 = sim.initial_state({"phi0": [0.01, -0.02, 0.03], "omega0": [1e-3, 0.0, -2e-3]})
    state = x0.copy()
    state.setflags(write=False)
    r_i = np.array([5774354.283543313, 0.0, 3333825.0])

    def u(t: float | np.ndarray) -> dict[str, np.ndarray]:  # t (k,) -> (k, 3)
        return {"R": r_i + np.multiply.outer(t, [0.0, 7730.0, 0.0]),
                "torque": np.array([1e-3, -2e-3, 0.0]) + np.multiply.outer(t, [0.0, 0.0, 5e-4])}

    times = np.linspace(0.0, 0.4, 5)
    out1, end1 = sim.advance(state, times, u)
    out2, end2 = sim.advance(state, times, u)
    np.testing.assert_array_equal(state, x0)
    assert set(out1) == set(Attitude.outputs) == {"phi", "omega", "omega_dot"}
    for name in out1:
        assert out1[name].shape == (5, 3)
        np.testing.assert_array_equal(out1[name], out2[name])
    np.testing.assert_array_equal(end1, end2)
    np.testing.assert_array_equal(out1["phi"][0], x0[:3])
    np.testing.assert_array_equal(out1["omega"][0], x0[3:])
    np.testing.assert_array_equal(end1, np.concatenate([out1["phi"][-1], out1["omega"][-1]]))
    d0 = attitude_derivative(x0.tolist(), u(0.0)["R"].tolist(), u(0.0)["torque"].tolist(), sim.p)
    np.testing.assert_array_equal(out1["omega_dot"][0], d0[3:])
    with pytest.raises(ValueError, match="inertia"):
        Attitude().initial_state({"inertia": [[1, 0, 0], [0, -1, 0], [0, 0, 1]]})
    with pytest.raises(ValueError, match="unknown attitude parameter"):
        Attitude().initial_state({"a2": 1.0})
