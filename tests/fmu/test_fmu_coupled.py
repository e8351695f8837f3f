"""Two FMU masses coupled over Zenoh (real processes), RF-C and RF-D, FMI 2.0 and 3.0; and the mixed
system (an FMU mass and the shipped Python mass) run with ``cosim run``.

The oscillator: m1 = m2 = 1, k1 = k2 = 4 pi^2, k12 = 16 pi^2, u(0) = (1, 0), v(0) = 0; exact
u1,2 = 1/2 cos 2 pi t +- 1/2 cos 6 pi t.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from cosim.cli import main as cosim_main
from cosim.results import read_results
from cosim.runner import run_scenario
from cosim.scenario import load

pytestmark = [pytest.mark.slow]  # the inner loop: pytest -m "not slow"

K12 = 16 * np.pi**2  # the middle spring
K = 20 * np.pi**2  # each mass's own spring plus the middle one
SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios" / "fmu"
STOP = 0.5
H_COMM = 0.02 / 20  # the scenario's interval / (samples - 1): the communication step


def exact(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return 0.5 * np.cos(2 * np.pi * t) + 0.5 * np.cos(6 * np.pi * t), 0.5 * np.cos(2 * np.pi * t) - 0.5 * np.cos(
        6 * np.pi * t
    )


def scenario_copy(tmp_path: Path, name: str, fmus: dict[str, Path], **fmu_files: str) -> Path:
    """The shipped scenario beside its own copies of the FMUs, so ``fmu = "..."`` resolves against the
    scenario's directory (the test runs from elsewhere)."""
    for target, source in fmu_files.items():
        shutil.copy(fmus[source], tmp_path / target)
    path = tmp_path / name
    shutil.copy(SCENARIOS / name, path)
    return path


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("method", ["centralized", "distributed"])
def test_two_fmus_match_the_one_process_reference_and_the_closed_form(
    tmp_path: Path, fmus: dict[str, Path], two_mass_reference, version: int, method: str
) -> None:
    """Converged recursive feedback of co-simulation FMUs is the fixed point of the sampled coupling, which
    is exactly what a one-process master computes when it steps both FMUs over the same communication
    points with each force set from the other mass at that point (conftest.two_masses, FMPy only). The
    runs stop at relative stage differences of 1e-12, so they must agree with it to 1e-9.

    Against the closed form, the only error is the hold of the coupling force over each communication step
    h (the FMU steps exactly for a held force). A force held from t_i acts like the force delayed by h/2:
    k12 u_j(t - h/2) = k12 u_j(t) - k12 (h/2) v_j(t) + O(h^2). In the in-phase mode s = u1 + u2 this is a
    damping k12 h/2, in the anti-phase mode d = u1 - u2 a negative damping of the same size, so the two
    mode amplitudes (1 each) become exp(-r t) and exp(+r t), r = k12 h / 4. To first order
    u2 - u2_exact = -(r t / 2)(cos 2 pi t + cos 6 pi t), whose largest value on [0, T] is r T when both
    cosines are +-1 together, as at T = 0.5. So max |u - u_exact| = k12 h T / 4 = 0.0197 for h = 1e-3,
    up to O(h^2) and O((r T)^2) terms (relative 1e-3 here); the test allows 1 %.
    """
    fmu = f"mass{version}.fmu"
    text = (SCENARIOS / "oscillator_fmu.toml").read_text().replace('"mass2.fmu"', f'"{fmu}"')
    (tmp_path / "scenario.toml").write_text(text)
    shutil.copy(fmus[f"mass{version}"], tmp_path / fmu)
    scenario = load(tmp_path / "scenario.toml")
    assert scenario.subsims["mass1"].params["fmu"] == str((tmp_path / fmu).resolve())
    out = tmp_path / "run.csv"
    report = run_scenario(scenario, method=method, stop=STOP, output=out, inprocess=False, progress=False)
    cols, data = read_results(out)
    assert cols == ["time", "mass1.u[0]", "mass1.v[0]", "mass2.u[0]", "mass2.v[0]"]
    assert data[-1, 0] == pytest.approx(STOP) and data.shape[0] == round(STOP / H_COMM) + 1
    assert report.summary.intervals == 25

    ref = two_mass_reference(fmus[f"mass{version}"], data[:, 0], K, K12, (1.0, 0.0))
    deviation = np.abs(data[:, 1:] - ref).max()
    assert deviation < 1e-9, deviation

    u1, u2 = exact(data[:, 0])
    error = max(np.abs(data[:, 1] - u1).max(), np.abs(data[:, 3] - u2).max())
    predicted = K12 * H_COMM * STOP / 4
    assert abs(error / predicted - 1) < 0.01, (error, predicted)


@pytest.mark.parametrize("method", ["centralized", "distributed"])
def test_mixed_fmu_and_python_mass_with_cosim_run(
    tmp_path: Path, fmus: dict[str, Path], method: str, capsys: pytest.CaptureFixture
) -> None:
    """scenarios/fmu/oscillator_mixed.toml: mass 1 the FMI 3.0 FMU through model exchange (scipy DOP853,
    rtol 1e-10), mass 2 subsims.oscillator (RK4, 4 steps per sample), cubic interpolation, sample spacing
    h = 2.5e-3. The error is that of the cubic interpolation of the coupling force and of mass 2's RK4, both
    O(h^4). A priori: the interpolation error of F = k12 u is about h^4 / 24 max|d4F/dt4| <= 1.3e-5 N, which
    moves a mass by at most 1.3e-5 T / (m w) ~ 1e-6 over T = 0.5 (w = 2 pi, the slower mode); RK4 at step
    h/4 adds less. So the mixed run must be within 1e-6 of the closed form, and of the same scenario with
    mass 1 replaced by the Python mass. (Measured: 2.4e-8 from the closed form, 1.3e-8 apart.)"""
    path = scenario_copy(tmp_path, "oscillator_mixed.toml", fmus, **{"mass3.fmu": "mass3"})
    out = tmp_path / "mixed.csv"
    code = cosim_main(["run", str(path), "--method", method, "--stop", "0.5", "--output", str(out), "--quiet"])
    printed = capsys.readouterr()
    assert code == 0, printed.err
    assert "oscillator-mixed (" in printed.out
    cols, data = read_results(out)
    assert cols == ["time", "mass1.u[0]", "mass1.v[0]", "mass2.u[0]", "mass2.v[0]"]
    assert data[-1, 0] == pytest.approx(0.5) and data.shape[0] == 201
    u1, u2 = exact(data[:, 0])
    error = max(np.abs(data[:, 1] - u1).max(), np.abs(data[:, 3] - u2).max())
    assert error < 1e-6, error

    python_only = path.read_text().replace('fmu = "mass3.fmu"', 'model = "subsims.oscillator.subsim:Mass"')
    python_only = python_only.replace('interface = "me", ', "").replace("u0 = 1.0 }", "u0 = 1.0, idiv = 4 }")
    (tmp_path / "python.toml").write_text(python_only)
    ref = tmp_path / "python.csv"
    run_scenario(load(tmp_path / "python.toml"), method=method, stop=0.5, output=ref, inprocess=True, progress=False)
    _, data_py = read_results(ref)
    assert np.abs(data[:, 1:] - data_py[:, 1:]).max() < 1e-6
