"""The coupler against the paper's §2.3 (eqs. 1-10): stage n is a truncated series, exactly."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.coupler.convergence import Tolerance
from cosim.coupler.couplings import Coupling
from cosim.coupler.relaxation import Settings
from cosim.driver import Coordinator
from cosim.handles import InProcessHandle
from subsims.double_integrator.subsim import DoubleIntegrator
from subsims.integrator.subsim import Integrator

METHODS = ["centralized", "distributed"]


def stages_of_first_interval(coordinator: Coordinator, t1: float) -> list[dict]:
    seen: list[dict] = []
    coordinator.on_stage = lambda stage, outputs: seen.append(outputs)
    coordinator.advance(0.0, t1)
    return seen


def exact_settings(method: str, ndp: int, H: float, max_stages: int = 60) -> Settings:
    # lagrange interpolation reproduces the degree ndp-1 polynomials each stage produces
    return Settings(method=method, interval=H, samples=ndp, first_guess="zero", interp="lagrange",
                    tol=Tolerance(1e-13, 1e-15), max_stages=max_stages)


@pytest.mark.parametrize("method", METHODS)
def test_y_prime_equals_ky_stage_n_is_taylor_polynomial(method: str) -> None:
    """Eq. 5: y(n)(t) = y0 sum_{i<=n} (kt)^i / i!."""
    k, y0, ndp, H = -1.7, 2.0, 7, 0.9
    h = InProcessHandle(Integrator(), "y")
    h.configure({"y0": [y0]})
    c = Coordinator({"y": h}, [Coupling.make("y.u", "y.y", "gain", {"k": k})], exact_settings(method, ndp, H))
    stages = stages_of_first_interval(c, H)
    t = c.sample_times(0.0, H)
    for n in range(ndp):
        taylor = y0 * sum((k * t) ** i / math.factorial(i) for i in range(n + 1))
        np.testing.assert_allclose(stages[n]["y"]["y"][:, 0], taylor, rtol=1e-12, atol=0)
    # and not the next Taylor term: a stage adds exactly one order
    assert np.max(np.abs(stages[2]["y"]["y"][:, 0] - y0 * (1 + k * t + (k * t) ** 2 / 2 + (k * t) ** 3 / 6))) > 1e-3


@pytest.mark.parametrize("method", METHODS)
def test_y_prime_equals_ky_converges_to_exponential(method: str) -> None:
    k, y0, H = -0.8, 1.0, 0.25
    h = InProcessHandle(Integrator(), "y")
    h.configure({"y0": [y0]})
    c = Coordinator({"y": h}, [Coupling.make("y.u", "y.y", "gain", {"k": k})], exact_settings(method, 6, H))
    samples: list[tuple[np.ndarray, np.ndarray]] = []
    c.run(0.0, 5.0, lambda iv: samples.append((iv.t, iv.outputs["y"]["y"][:, 0])))
    t = np.concatenate([s[0] for s in samples])
    y = np.concatenate([s[1] for s in samples])
    assert t[-1] == pytest.approx(5.0)
    # collocation on 6 equispaced points per interval: local error O(H^7), 20 intervals
    np.testing.assert_allclose(y, y0 * np.exp(k * t), rtol=1e-9)


def oscillator_double(method: str, ndp: int, H: float, w: float) -> Coordinator:
    h = InProcessHandle(DoubleIntegrator(), "osc")
    h.configure({"y0": [1.0], "v0": [0.0]})
    couplings = [Coupling.make("osc.u", "osc.y", "gain", {"k": -(w**2)})]  # eq. 6
    return Coordinator({"osc": h}, couplings, exact_settings(method, ndp, H))


def oscillator_pair(method: str, ndp: int, H: float, w: float) -> Coordinator:
    """Eq. 10: Y = (y, y'), Y' = K Y with K = [[0, 1], [-w^2, 0]], as two single integrators."""
    a, b = InProcessHandle(Integrator(), "a"), InProcessHandle(Integrator(), "b")
    a.configure({"y0": [1.0]})
    b.configure({"y0": [0.0]})
    couplings = [Coupling.make("a.u", "b.y"), Coupling.make("b.u", "a.y", "gain", {"k": -(w**2)})]
    return Coordinator({"a": a, "b": b}, couplings, exact_settings(method, ndp, H))


def test_double_integrator_stage_n_is_cosine_series_of_order_2n() -> None:
    """Eq. 6: y(n) = y0 sum_{i<=n} (-1)^i (wt)^(2i) / (2i)!."""
    w, ndp, H = 2.0, 9, 0.7
    c = oscillator_double("centralized", ndp, H, w)
    stages = stages_of_first_interval(c, H)
    t = c.sample_times(0.0, H)
    for n in range(ndp // 2 + 1):  # input degree 2n-2 must stay <= ndp-1
        series = sum((-1) ** i * (w * t) ** (2 * i) / math.factorial(2 * i) for i in range(n + 1))
        np.testing.assert_allclose(stages[n]["osc"]["y"][:, 0], series, rtol=1e-12, atol=1e-14)


def test_jacobi_pair_stage_n_is_matrix_exponential_series_and_needs_two_stages_per_order() -> None:
    """Eq. 10: Y(n) = [I + K t + ... + K^n t^n / n!] Y(0); y of the pair at stage 2n equals the
    double integrator's y at stage n."""
    w, ndp, H = 2.0, 9, 0.7
    pair = oscillator_pair("centralized", ndp, H, w)
    double = oscillator_double("centralized", ndp, H, w)
    t = pair.sample_times(0.0, H)
    pair_stages, double_stages = stages_of_first_interval(pair, H), stages_of_first_interval(double, H)
    K = np.array([[0.0, 1.0], [-(w**2), 0.0]])
    for n in range(ndp):
        series = np.array([sum(np.linalg.matrix_power(K * tj, i) / math.factorial(i) for i in range(n + 1))
                           @ [1.0, 0.0] for tj in t])
        got = np.column_stack([pair_stages[n]["a"]["y"][:, 0], pair_stages[n]["b"]["y"][:, 0]])
        np.testing.assert_allclose(got, series, rtol=1e-12, atol=1e-13)
    for n in range(ndp // 2):
        np.testing.assert_allclose(pair_stages[2 * n]["a"]["y"], double_stages[n]["osc"]["y"], rtol=1e-12, atol=1e-14)
        assert not np.allclose(pair_stages[2 * n + 1]["a"]["y"], double_stages[n + 1]["osc"]["y"], rtol=1e-9)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("build", [oscillator_double, oscillator_pair], ids=["double", "pair"])
def test_oscillator_converges_to_cosine_over_ten_periods(method: str, build) -> None:
    w = 2 * np.pi
    c = build(method, 6, 0.05, w)
    ts, ys = [], []
    first = "osc" if "osc" in c.handles else "a"
    c.run(0.0, 10.0, lambda iv: (ts.append(iv.t), ys.append(iv.outputs[first]["y"][:, 0])))
    t, y = np.concatenate(ts), np.concatenate(ys)
    assert t[-1] == pytest.approx(10.0)
    assert np.max(np.abs(y - np.cos(w * t))) < 1e-7  # measured 8.5e-9 (double), 1.7e-8 (pair)
