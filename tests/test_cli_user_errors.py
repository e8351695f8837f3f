"""A user's mistakes, through the CLI as a process: one line naming what is wrong, exit 2, no traceback."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

OSCILLATOR = Path(__file__).parents[1] / "scenarios" / "oscillator.toml"
COSIM = [sys.executable, "-m", "cosim.cli"]


@pytest.mark.parametrize(("old", "new", "words"), [
    # a misspelled model parameter: refused with the known ones and the close one
    ("params = { m = 1.0, k = 197.39208802178717, u0 = 1.0,",
     "params = { mass = 1.0, k = 197.39208802178717, u0 = 1.0,",
     ["[subsims.mass1.params]", "unknown parameter(s) 'mass'", "this model takes: m,"]),
    ("v0 = 0.0, idiv = 1 }\n\n[subsims.mass2]", "v0 = 0.0, idvi = 1 }\n\n[subsims.mass2]",
     ["[subsims.mass1.params]", "'idvi' (did you mean 'idiv'?)"]),
    # a number in quotes: refused by name, before it fails deep inside the model
    ("params = { m = 1.0, k = 197.39208802178717, u0 = 1.0,",
     'params = { m = "1.0", k = 197.39208802178717, u0 = 1.0,',
     ["[subsims.mass1.params]", "parameter 'm' must be a number (its default is 1.0), got the string '1.0'",
      "without quotes"]),
    # a misspelled table name that breaks the TOML itself
    ('[[couplings]]\nto = "mass2.F"', '[[coupling]]\nto = "mass2.F"', ["not valid TOML", "line 37"]),
])
def test_a_mistake_in_the_scenario_is_one_line_naming_it(tmp_path: Path, old: str, new: str, words: list[str]) -> None:
    text = OSCILLATOR.read_text()
    assert old in text
    sc = tmp_path / "s.toml"
    sc.write_text(text.replace(old, new, 1))
    done = subprocess.run([*COSIM, "run", str(sc), "--inprocess", "--quiet", "--output", str(tmp_path / "x.csv")],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("cosim: "), done.stderr
    assert all(w in lines[0] for w in words), lines[0]
    assert "Traceback" not in done.stderr


def test_an_input_fed_by_no_coupling_is_refused_unless_held(tmp_path: Path) -> None:
    text = OSCILLATOR.read_text()
    cut = text.index('[[couplings]]\nto = "mass2.F"')
    sc = tmp_path / "s.toml"
    sc.write_text(text[:cut])  # the coupling into mass2.F is gone
    run = [*COSIM, "run", str(sc), "--inprocess", "--quiet", "--stop", "0.1"]
    done = subprocess.run([*run, "--output", str(tmp_path / "x.csv")], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1
    assert "[subsims.mass2.inputs] input mass2.F" in done.stderr and "fed by no" in done.stderr
    sc.write_text(text[:cut].replace("[subsims.mass2]\n", "[subsims.mass2]\ninputs = { F = 0.0 }\n"))
    held = subprocess.run([*run, "--output", str(tmp_path / "y.csv")], capture_output=True, text=True, timeout=120)
    assert held.returncode == 0, held.stderr


@pytest.mark.parametrize(("source", "words"), [
    ("from cosim import Subsim\n\nclass Broken(Subsim)\n    pass\n", ["SyntaxError", "broken.py", "line 3"]),
    ("from cosim import Subsim\n\nSTEP = undefined_name\n", ["NameError", "undefined_name", "broken.py, line 3"]),
])
def test_a_broken_model_module_is_one_line_naming_its_file_and_line(tmp_path: Path, source: str,
                                                                   words: list[str]) -> None:
    """A syntax error or a failing top-level statement in the user's module: not cosim's traceback through importlib."""
    (tmp_path / "broken.py").write_text(source)
    sc = tmp_path / "s.toml"
    mass = 'model = "subsims.oscillator.subsim:Mass"'
    sc.write_text(OSCILLATOR.read_text().replace(mass, 'model = "broken:Broken"', 1))
    for command in (["run", str(sc), "--inprocess", "--quiet", "--output", str(tmp_path / "x.csv")],
                    ["describe", str(sc)]):
        done = subprocess.run([*COSIM, *command], capture_output=True, text=True, timeout=120, cwd=tmp_path)
        assert done.returncode == 2, done.stderr
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("cosim: ") and "Traceback" not in done.stderr, done.stderr
        assert "model 'broken:Broken': importing 'broken' raised" in lines[0], lines[0]
        assert all(w in lines[0] for w in words), lines[0]
