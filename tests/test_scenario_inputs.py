"""Inputs no coupling feeds: refused when the run starts unless [subsims.<name>.inputs] holds them constant."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cosim.results import read_results
from cosim.runner import open_session, run_scenario
from cosim.scenario import ScenarioError, load

ROOT = Path(__file__).parents[1]

# y' = u: with u held at c, y(t) = c t (Gauss quadrature, exact up to rounding)
SCENARIO = """
stop = 1.0
[coupling]
interval = 0.5
samples = 3
[subsims.a]
model = "subsims.integrator.subsim:Integrator"
params = { size = 2 }
[subsims.a.inputs]
u = [3.0, -0.5]
[subsims.b]
model = "subsims.integrator.subsim:Integrator"
[[couplings]]
to = "b.u"
from = "a.y"
transform = "linear"
params = { gains = [[[1.0, 0.0]]] }
"""


def write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "held.toml"
    p.write_text(text)
    return p


@pytest.mark.parametrize("method", ["centralized", "distributed"])
def test_held_input_feeds_its_constant(tmp_path: Path, method: str) -> None:
    out = tmp_path / f"{method}.csv"
    run_scenario(load(write(tmp_path, SCENARIO)), method=method, output=out, inprocess=True, progress=False)
    cols, data = read_results(out)
    t = data[:, 0]
    assert cols[1:3] == ["a.y[0]", "a.y[1]"]
    np.testing.assert_allclose(data[:, 1], 3.0 * t, rtol=1e-15)
    np.testing.assert_allclose(data[:, 2], -0.5 * t, rtol=1e-15)
    np.testing.assert_allclose(data[:, 3], 1.5 * t**2, rtol=1e-14)  # b.y = integral of 3 t


@pytest.mark.parametrize(
    ("old", "new", "words"),
    [
        ("[subsims.a.inputs]\nu = [3.0, -0.5]\n", "", "[subsims.a.inputs] input a.u (2 x unitless) is fed by no"),
        ("u = [3.0, -0.5]", "u = [3.0]", "[subsims.a.inputs.u] a.u takes 2 values, got 1"),
        ("u = [3.0, -0.5]", "u = [3.0, -0.5]\nv = 1.0", "[subsims.a.inputs.v] a.v is no input (inputs: u)"),
        ("[subsims.b]\n", "[subsims.b]\ninputs = { u = 1.0 }\n", "[subsims.b.inputs.u] b.u is fed by a coupling"),
    ],
)
def test_unfed_or_wrongly_held_inputs_are_refused_naming_the_key(tmp_path: Path, old: str, new: str,
                                                                 words: str) -> None:
    assert old in SCENARIO
    scenario = load(write(tmp_path, SCENARIO.replace(old, new, 1)))
    with pytest.raises(ScenarioError) as err:
        open_session(scenario, inprocess=True).close()
    assert words in str(err.value) and "held.toml" in str(err.value)


@pytest.mark.parametrize("value", ['"x"', "[]", "[1.0, true]", "{ a = 1 }"])
def test_held_values_must_be_numbers(tmp_path: Path, value: str) -> None:
    with pytest.raises(ScenarioError) as err:
        load(write(tmp_path, SCENARIO.replace("u = [3.0, -0.5]", f"u = {value}")))
    assert "[subsims.a.inputs.u] must be a number or a list of numbers" in str(err.value)


def test_a_tolerance_the_runs_method_never_checks_is_said(tmp_path: Path) -> None:
    """One [tolerances] table serves both methods: a tolerance on an input (a distributed run's) was dropped without
    a word by a centralized run, and one on an output by a distributed run (a docs probe)."""
    text = (ROOT / "scenarios" / "oscillator.toml").read_text()
    scenario = tmp_path / "tol.toml"
    scenario.write_text(text + '\n[tolerances."mass1.F"]\nabs = 1e-3\n\n[tolerances."mass2.u"]\nabs = 1e-3\n')
    said: dict[str, list[str]] = {}
    for method in ("centralized", "distributed"):
        said[method] = []
        run_scenario(load(scenario), method=method, stop=0.1, output=tmp_path / f"{method}.csv", inprocess=True,
                     progress=False, log=said[method].append)
    assert said["centralized"] == ["cosim: [tolerances.'mass1.F'] does not apply to this centralized run, which checks "
                                   "outputs"]
    assert said["distributed"] == ["cosim: [tolerances.'mass2.u'] does not apply to this distributed run, which checks "
                                   "the fed-back inputs: mass1.F"]


def test_settings_that_do_nothing_in_the_run_are_said(tmp_path: Path) -> None:
    """speculate in a centralized run and max_halvings with interval = "auto" did nothing without a word (a probe)."""
    text = (ROOT / "scenarios" / "oscillator.toml").read_text().replace("max_stages = 50", "max_stages = 50\n"
                                                                       "speculate = true\nmax_halvings = 2")
    scenario = tmp_path / "s.toml"
    scenario.write_text(text)
    said: list[str] = []
    run_scenario(load(scenario), method="centralized", stop=0.1, output=tmp_path / "c.csv", inprocess=True,
                 progress=False, log=said.append)
    assert said == ["cosim: speculate does nothing in a centralized run (its subsims run side by side already)"]
    scenario.write_text(text.replace("interval = 0.05 ", 'interval = "auto" '))
    said.clear()
    run_scenario(load(scenario), method="distributed", stop=0.1, output=tmp_path / "d.csv", inprocess=True,
                 progress=False, log=said.append)
    assert said == ['cosim: max_halvings does nothing with interval = "auto", which shortens a try that fails itself']


POINTING = '''
import numpy as np
from cosim import Port, Subsim


class Body(Subsim):
    """A unit quaternion turning about z at a rate the torque sets (q = [cos(a/2), 0, 0, sin(a/2)])."""
    inputs = {"torque": Port(1)}
    outputs = {"q": Port(4)}

    def initial_state(self, params):
        return np.array([0.3])

    def advance(self, state, times, u):
        a = state[0] + (times - times[0]) * (0.1 + u(times)["torque"][:, 0])
        q = np.column_stack([np.cos(a / 2), 0 * a, 0 * a, np.sin(a / 2)])
        return {"q": q}, np.array([a[-1]])


class Pointer(Subsim):
    """Takes the quaternion's angle: a zero quaternion has none."""
    inputs = {"q": Port(4)}
    outputs = {"torque": Port(1)}

    def initial_state(self, params):
        return np.zeros(0)

    def advance(self, state, times, u):
        q = u(times)["q"]
        norm = np.linalg.norm(q, axis=1)
        if not np.all(norm > 0.5):
            raise ValueError(f"not a unit quaternion: {q[0].tolist()}")
        return {"torque": (-0.01 * 2 * np.arctan2(q[:, 3], q[:, 0]))[:, None]}, state
'''


def test_a_guess_stands_in_for_the_zeros_a_coupled_input_starts_from(tmp_path: Path) -> None:
    """A centralized run feeds zeros to every input at the first stage: a model taking a quaternion could not start,
    and nothing could be given instead (a five-subsim probe). [subsims.<name>.guess] gives it; widths and ports are
    checked."""
    (tmp_path / "pointing.py").write_text(POINTING)
    base = ('stop = 1.0\n[coupling]\ninterval = 0.25\nmethod = "centralized"\n[subsims.body]\nmodel = '
            '"pointing:Body"\n[subsims.pointer]\nmodel = "pointing:Pointer"\n[[couplings]]\nto = "pointer.q"\nfrom = '
            '"body.q"\n[[couplings]]\nto = "body.torque"\nfrom = "pointer.torque"\n')
    scenario = tmp_path / "p.toml"
    scenario.write_text(base)
    with pytest.raises(Exception, match=r"not a unit quaternion: \[0.0, 0.0, 0.0, 0.0\]"):
        run_scenario(load(scenario), stop=0.5, output=tmp_path / "z.csv", inprocess=True, progress=False)
    scenario.write_text(base + "[subsims.pointer.guess]\nq = [1.0, 0.0, 0.0, 0.0]\n")
    report = run_scenario(load(scenario), stop=0.5, output=tmp_path / "g.csv", inprocess=True, progress=False)
    assert report.summary.t_end == 0.5
    for guess, why in (("q = [1.0, 0.0]", "pointer.q takes 4 values, got 2"), ("w = 1.0", "pointer.w is no input")):
        scenario.write_text(base + f"[subsims.pointer.guess]\n{guess}\n")
        with pytest.raises(ScenarioError, match=rf"\[subsims.pointer.guess.\w\] {why}"):
            run_scenario(load(scenario), stop=0.5, output=tmp_path / "e.csv", inprocess=True, progress=False)
