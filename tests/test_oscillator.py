"""Two-mass, three-spring oscillator cut at the middle spring (scenarios/oscillator.toml)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from cosim.results import read_results
from cosim.runner import run_scenario
from cosim.scenario import Scenario, load

SCENARIO = Path(__file__).parents[1] / "scenarios" / "oscillator.toml"


def variant(method: str, **settings) -> Scenario:
    sc = load(SCENARIO)
    return dataclasses.replace(
        sc, settings={**sc.settings, method: dataclasses.replace(sc.settings[method], **settings)}
    )


def exact(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return 0.5 * np.cos(2 * np.pi * t) + 0.5 * np.cos(6 * np.pi * t), 0.5 * np.cos(2 * np.pi * t) - 0.5 * np.cos(
        6 * np.pi * t
    )


def run(sc: Scenario, method: str, out: Path, stop: float = 1.0, inprocess: bool = True) -> np.ndarray:
    run_scenario(sc, method=method, stop=stop, output=out, inprocess=inprocess, progress=False)
    cols, data = read_results(out)
    assert cols == ["time", "mass1.u[0]", "mass1.v[0]", "mass2.u[0]", "mass2.v[0]"]
    return data


def max_error(data: np.ndarray) -> float:
    u1, u2 = exact(data[:, 0])
    return float(max(np.abs(data[:, 1] - u1).max(), np.abs(data[:, 3] - u2).max()))


@pytest.mark.parametrize("method", ["centralized", "distributed"])
@pytest.mark.parametrize(("interp", "expected_order"), [("linear", 2.0), ("cubic", 4.0)])
def test_converges_to_exact_solution_at_expected_order(
    tmp_path: Path, method: str, interp: str, expected_order: float
) -> None:
    """Linear input interpolation limits the scheme to order 2; cubic with RK4 gives order 4."""
    errors = []
    for H in (0.04, 0.02, 0.01):
        data = run(variant(method, interval=H, interp=interp), method, tmp_path / f"{H}.csv")
        assert data[-1, 0] == pytest.approx(1.0)
        errors.append(max_error(data))
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(np.abs(orders - expected_order) < 0.5), (errors, orders)
    assert errors[-1] < (1e-3 if interp == "linear" else 5e-7)  # measured 4.1e-4, 1.2e-7 (H = 0.01)


@pytest.mark.parametrize("method", ["centralized", "distributed"])
def test_energy_stays_at_ten_pi_squared(tmp_path: Path, method: str) -> None:
    data = run(variant(method, interval=0.01), method, tmp_path / "e.csv")
    u1, v1, u2, v2 = data[:, 1], data[:, 2], data[:, 3], data[:, 4]
    k, k12 = 4 * np.pi**2, 16 * np.pi**2
    energy = 0.5 * (v1**2 + v2**2) + 0.5 * (k * u1**2 + k * u2**2 + k12 * (u1 - u2) ** 2)
    np.testing.assert_allclose(energy, 10 * np.pi**2, rtol=2e-7)  # measured 2.3e-8


def test_distributed_needs_fewer_stages_than_centralized(tmp_path: Path) -> None:
    stages = {}
    for method in ("centralized", "distributed"):
        rep = run_scenario(
            load(SCENARIO), method=method, stop=0.5, output=tmp_path / f"{method}.csv", inprocess=True, progress=False
        )
        s = rep.summary
        stages[method] = sum(k * v for k, v in s.stages.items()) / s.intervals
    assert stages["distributed"] < stages["centralized"]


@pytest.mark.zenoh
@pytest.mark.parametrize("method", ["centralized", "distributed"])
def test_bit_identical_in_process_and_over_zenoh(tmp_path: Path, method: str) -> None:
    sc = load(SCENARIO)
    local = run(sc, method, tmp_path / "local.csv", stop=0.5, inprocess=True)
    remote = run(sc, method, tmp_path / "remote.csv", stop=0.5, inprocess=False)
    assert local.shape == remote.shape and local.shape[0] > 10
    assert local.tobytes() == remote.tobytes()
    assert (tmp_path / "local.csv").read_bytes() == (tmp_path / "remote.csv").read_bytes()
