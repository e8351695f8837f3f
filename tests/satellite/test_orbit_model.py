"""Orbit dynamics: closed forms (circular Kepler orbit, force-driven free particle), adapter contract."""

from __future__ import annotations

import math

import numpy as np
import pytest

from subsims.orbit.model import OrbitParams, circular_orbit, integrate, orbit_derivative
from subsims.orbit.subsim import Orbit
from subsims.satellite import constants as C


def zero_force(t: float) -> dict[str, np.ndarray]:
    return {"f_aero": np.zeros(3)}


def test_paper_initial_conditions() -> None:
    # spec §7.1, §7.8 (values with the double-precision G)
    assert C.GME == pytest.approx(3.985140974547934e14, rel=1e-15)
    r, v = circular_orbit()
    assert r == pytest.approx((5774354.283543313, 0.0, 3333824.9999999995), rel=1e-15)
    assert v[1] == pytest.approx(math.sqrt(C.GME / 6667650.0), rel=1e-15)
    x0 = Orbit().initial_state({})
    np.testing.assert_array_equal(x0, np.array(r + v))


def test_circular_orbit_over_one_period() -> None:
    """Density zero: the orbit is a circle; radius, energy and angular momentum constant; motion = closed form."""
    sim = Orbit()
    x0 = sim.initial_state({})
    mu = C.GME
    r0 = np.linalg.norm(x0[:3])
    n_rate = math.sqrt(mu / r0**3)
    period = 2.0 * math.pi / n_rate
    times = 0.1 * np.arange(int(period / 0.1) + 2)  # the paper's 0.1 s step, a little over one period
    out, end = sim.advance(x0, times, zero_force)
    R, V = out["R"], out["V"]
    assert R.shape == V.shape == (times.size, 3)
    rad = np.linalg.norm(R, axis=1)
    assert np.max(np.abs(rad / r0 - 1.0)) < 5e-13  # measured 5.1e-14
    energy = 0.5 * np.sum(V * V, axis=1) - mu / rad
    assert np.max(np.abs(energy / energy[0] - 1.0)) < 5e-13  # measured 6.4e-14
    h = np.cross(R, V)
    assert np.max(np.linalg.norm(h - h[0], axis=1)) / np.linalg.norm(h[0]) < 3e-13  # measured 3.2e-14
    # closed form R(t) = R0 cos(nt) + V0/n sin(nt)
    c, s = np.cos(n_rate * times)[:, None], np.sin(n_rate * times)[:, None]
    exact = x0[:3] * c + x0[3:] / n_rate * s
    assert np.max(np.linalg.norm(R - exact, axis=1)) < 1e-5  # m (measured 1.3e-6 m: RK4 phase error)
    np.testing.assert_array_equal(end, np.concatenate([R[-1], V[-1]]))


def test_force_read_at_rk_stage_times_idiv() -> None:
    """mu = 0, force linear in time: R is a cubic, which RK4 integrates exactly only if u is read at stage times."""
    sim = Orbit()
    m = 250.0
    x0 = sim.initial_state({"mu": 0.0, "mass": m, "r0": [7e6, 0, 0], "v0": [1.0, 2.0, 3.0], "idiv": 3})
    a, b = np.array([0.5, -1.0, 2.0]), np.array([0.03, 0.01, -0.02])
    calls: list[float] = []

    def u(t: float | np.ndarray) -> dict[str, np.ndarray]:  # t (k,) -> (k, 3)
        calls.extend(np.atleast_1d(t).tolist())
        return {"f_aero": a + np.multiply.outer(t, b)}

    times = np.array([10.0, 10.1, 10.2, 10.3, 10.4])
    out, end = sim.advance(x0, times, u)
    tau = (times - times[0])[:, None]
    t_abs = times[:, None]
    # integrate f/m from times[0]: V = V0 + (a tau + b (t^2 - t0^2)/2)/m; R = R0 + V0 tau + ...
    t0 = times[0]
    v_exact = x0[3:] + (a * tau + b * (t_abs**2 - t0**2) / 2.0) / m
    r_exact = x0[:3] + x0[3:] * tau + (a * tau**2 / 2.0 + b * ((t_abs**3 - t0**3) / 6.0 - t0**2 * tau / 2.0)) / m
    np.testing.assert_allclose(out["V"], v_exact, rtol=0, atol=1e-12)
    np.testing.assert_allclose(out["R"], r_exact, rtol=0, atol=1e-8)
    # RK stages at sub-step starts, mid-points and ends: 3 sub-steps x (start, mid, end) per sample interval
    h = 0.1 / 3
    expected = {round(times[0] + k * h / 2, 12) for k in range(2 * 3 * 4 + 1)}
    assert {round(t, 12) for t in calls} == expected


def test_orbit_derivative_closed_form() -> None:
    x = [3e6, 4e6, 0.0, 10.0, 20.0, 30.0]
    f = [1.0, 2.0, 3.0]
    mu, m = 4e14, 1000.0
    d = orbit_derivative(x, f, mu, m)
    r = np.array(x[:3])
    expected_acc = -mu * r / np.linalg.norm(r) ** 3 + np.array(f) / m
    np.testing.assert_allclose(d[:3], x[3:], rtol=0, atol=0)
    np.testing.assert_allclose(d[3:], expected_acc, rtol=1e-14)


def test_adapter_contract_and_purity() -> None:
    sim = Orbit()
    x0 = sim.initial_state({})
    assert x0.shape == (6,) and x0.dtype == np.float64
    state = x0.copy()
    state.setflags(write=False)  # advance must not write into it
    times = np.linspace(0.0, 0.4, 5)

    def u(t: float | np.ndarray) -> dict[str, np.ndarray]:  # t (k,) -> (k, 3)
        return {"f_aero": np.array([-0.05, 0.0, 0.002]) + np.multiply.outer(t, [0.0, 0.01, 0.0])}

    out1, end1 = sim.advance(state, times, u)
    out2, end2 = sim.advance(state, times, u)
    np.testing.assert_array_equal(state, x0)
    assert set(out1) == set(Orbit.outputs) == {"R", "V"}
    for name in ("R", "V"):
        assert out1[name].shape == (5, 3)
        np.testing.assert_array_equal(out1[name], out2[name])
    np.testing.assert_array_equal(out1["R"][0], x0[:3])
    np.testing.assert_array_equal(out1["V"][0], x0[3:])
    np.testing.assert_array_equal(end1, end2)
    np.testing.assert_array_equal(end1, np.concatenate([out1["R"][-1], out1["V"][-1]]))
    # continuing from the end state over the next interval equals one run over both intervals
    out_b, _ = sim.advance(end1, times + 0.4, lambda t: u(t))
    out_ab, _ = sim.advance(x0, np.linspace(0.0, 0.8, 9), u)
    np.testing.assert_allclose(out_b["R"], out_ab["R"][4:], rtol=1e-15)


def test_single_sample_and_bad_params() -> None:
    sim = Orbit()
    x0 = sim.initial_state({})
    out, end = sim.advance(x0, np.array([5.0]), zero_force)
    np.testing.assert_array_equal(out["R"], x0[None, :3])
    np.testing.assert_array_equal(end, x0)
    with pytest.raises(ValueError, match="idiv"):
        Orbit().initial_state({"idiv": 0})
    with pytest.raises(ValueError, match="unknown orbit parameter"):
        Orbit().initial_state({"mas": 1.0})
    with pytest.raises(ValueError, match="r0"):
        Orbit().initial_state({"r0": [1.0, 2.0]})


def test_integrate_idiv_converges() -> None:
    """Finer sub-steps change the circular orbit by far less than the step (RK4 is 4th order)."""
    p1 = OrbitParams.from_mapping({"idiv": 1})
    p4 = OrbitParams.from_mapping({"idiv": 4})
    times = np.arange(0.0, 600.0 + 1e-9, 60.0).tolist()  # a coarse 60 s grid to make the error visible
    s1, _ = integrate(p1, p1.initial_state().tolist(), times, lambda t: (0.0, 0.0, 0.0))
    s4, _ = integrate(p4, p4.initial_state().tolist(), times, lambda t: (0.0, 0.0, 0.0))
    r0 = np.linalg.norm(s1[0, :3])
    n = math.sqrt(C.GME / r0**3)
    t = np.array(times)[:, None]
    exact = s1[0, :3] * np.cos(n * t) + s1[0, 3:] / n * np.sin(n * t)
    e1 = np.max(np.linalg.norm(s1[:, :3] - exact, axis=1))
    e4 = np.max(np.linalg.norm(s4[:, :3] - exact, axis=1))
    assert e1 > 0.0 and e4 < e1 / 100.0  # 4th order: 4^4 = 256 in theory
