"""A scenario finds the user's modules beside it and in the working directory, without PYTHONPATH,
both when it is loaded and in the subsim processes ``cosim run`` launches."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from cosim.results import read_results

ROOT = Path(__file__).parents[1]

MODEL = '''
import numpy as np
from cosim import Port, Subsim


class Ramp(Subsim):
    """y' = 1."""
    outputs = {"y": Port(1)}

    def initial_state(self, params):
        return np.zeros(1)

    def advance(self, state, times, u):
        y = state[0] + (times - times[0])
        return {"y": y[:, None]}, y[-1:]
'''

TRANSFORM = '''
def double(x):
    return 2.0 * x
'''

SCENARIO = '''
stop = 0.5
[coupling]
interval = 0.25
samples = 3
[subsims.ramp]
model = "beside_scenario:Ramp"
[subsims.sink]
model = "subsims.integrator.subsim:Integrator"
[[couplings]]
to = "sink.u"
from = "ramp.y"
transform = "in_cwd:double"
'''


@pytest.mark.parametrize("inprocess", [True, False], ids=["inprocess", "launched"])
def test_modules_beside_the_scenario_and_in_the_working_directory(tmp_path: Path, inprocess: bool) -> None:
    scenario_dir, work, bin_dir = tmp_path / "scenario", tmp_path / "work", tmp_path / "bin"
    for d in (scenario_dir, work, bin_dir):
        d.mkdir()
    (scenario_dir / "beside_scenario.py").write_text(MODEL)
    (scenario_dir / "s.toml").write_text(SCENARIO)
    (work / "in_cwd.py").write_text(TRANSFORM)
    # like the installed `cosim` script: sys.path[0] is the script's directory, not the working directory
    script = bin_dir / "cosim_script.py"
    script.write_text("from cosim.cli import main\nraise SystemExit(main())\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}  # the code under test only, none of the user's directories
    out = work / "r.csv"
    cmd = [sys.executable, str(script), "run", str(scenario_dir / "s.toml"), "--output", str(out), "--quiet",
           *(["--inprocess"] if inprocess else [])]
    done = subprocess.run(cmd, cwd=work, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    cols, data = read_results(out)
    assert cols == ["time", "ramp.y[0]", "sink.y[0]"]
    t = data[:, 0]
    assert data[-1, 0] == 0.5
    assert list(data[:, 1]) == list(t)  # y = t
    assert abs(data[-1, 2] - 0.25) < 1e-14  # the integral of 2 t from 0 to 0.5


VARIANT = MODEL.replace('"""y\' = 1."""', '"""y\' = RATE."""').replace("state[0] + (times", "state[0] + RATE * (times")
assert VARIANT.count("RATE") == 2


@pytest.mark.parametrize("inprocess", [True, False], ids=["inprocess", "launched"])
@pytest.mark.parametrize("work_in", ["elsewhere", "variant1"])
def test_two_scenarios_with_a_module_of_the_same_name_each_run_their_own(tmp_path: Path, inprocess: bool,
                                                                        work_in: str,
                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """A study over model variants, each in its own directory under the same module name, in one interpreter: each
    scenario runs its own module, not the one the first scenario imported (nor the first on sys.path), also when
    the working directory is one of the variants' (its module comes after the scenario's own directory's, as
    scenarios.md says, in the launched processes too, where `python -m` put the working directory first)."""
    import cosim

    work = tmp_path / ("work" if work_in == "elsewhere" else work_in)
    for rate in (1, 3):
        d = tmp_path / f"variant{rate}"
        d.mkdir()
        (d / "variant_model.py").write_text(f"RATE = {rate}.0\n" + VARIANT)
        (d / "s.toml").write_text(SCENARIO.replace("beside_scenario:Ramp", "variant_model:Ramp")
                                  .replace('transform = "in_cwd:double"\n', ""))
    work.mkdir(exist_ok=True)
    monkeypatch.chdir(work)
    ends = [float(cosim.run(tmp_path / f"variant{rate}" / "s.toml", inprocess=inprocess)["ramp.y"][-1, 0])
            for rate in (1, 3, 1)]
    assert ends == [0.5, 1.5, 0.5]


def test_a_model_file_named_as_a_standard_module_is_told_to_be_renamed(tmp_path: Path) -> None:
    """``code.py`` beside the scenario: Python's own ``code`` is imported first (installed modules go first, by
    design), and the error said only "module 'code' has no attribute 'Node'" (a newcomer probe)."""
    from cosim.scenario import ScenarioError, load

    (tmp_path / "code.py").write_text("from subsims.integrator.subsim import Integrator as Node\n")
    (tmp_path / "s.toml").write_text('stop = 1.0\n[coupling]\ninterval = 0.5\nsamples = 3\n'
                                     '[subsims.a]\nmodel = "code:Node"\ninputs = { u = 0.0 }\n')
    with pytest.raises(ScenarioError) as err:
        load(tmp_path / "s.toml")
    said = str(err.value)
    assert "module 'code' has no attribute 'Node'" in said and f"which comes before {tmp_path / 'code.py'}" in said
    assert said.endswith("rename code.py"), said


def test_a_model_class_of_the_running_script_is_refused_for_a_subsim_process(tmp_path: Path,
                                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """``model = "__main__:MyLag"`` (a class defined in the user's script) loads and runs in this process; over
    Zenoh its process exited with code 2 saying only "module '__main__' has no attribute 'MyLag'" (a probe)."""
    from cosim.runner import run_scenario
    from cosim.scenario import ScenarioError, load
    from subsims.integrator.subsim import Integrator

    monkeypatch.setattr(sys.modules["__main__"], "MyLag", Integrator, raising=False)
    (tmp_path / "s.toml").write_text('stop = 1.0\n[coupling]\ninterval = 0.5\nsamples = 3\n'
                                     '[subsims.a]\nmodel = "__main__:MyLag"\ninputs = { u = 0.0 }\n')
    scenario = load(tmp_path / "s.toml")
    with pytest.raises(ScenarioError, match=r"\[subsims.a.model\] '__main__:MyLag' is a class of the running script"):
        run_scenario(scenario, output=tmp_path / "z.csv", progress=False, log=lambda m: None)
    done = run_scenario(scenario, output=tmp_path / "p.csv", inprocess=True, progress=False, log=lambda m: None)
    assert done.summary.t_end == 1.0


def test_code_digests_name_the_package_files_loaded_and_differing_code_compares_what_is_here(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """What a subsim's describe says of its code (``code``) and how a coordinator compares it (the end-to-end case:
    tests/test_external.py)."""
    import hashlib
    import importlib
    import re

    from cosim.contract import ProtocolError
    from cosim.importing import code_digests, differing_code
    from cosim.protocol.messages import decode_reply, encode_result

    pkg = tmp_path / "digestpkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "model.py").write_text("X = 1\n")
    (pkg / "unused.py").write_text("Y = 2\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    importlib.import_module("digestpkg.model")
    code = code_digests("digestpkg.model")
    assert code == {name: hashlib.sha256((pkg / f"{file}.py").read_bytes()).hexdigest()[:16]
                    for name, file in (("digestpkg", "__init__"), ("digestpkg.model", "model"))}  # loaded ones only
    assert code_digests("__main__") == {}  # a script's name: another process's __main__ is another file
    model = "digestpkg.model:M"
    assert differing_code(code, model) == []
    assert differing_code({**code, "digestpkg.model": "0" * 16, "digestpkg.nowhere": "1" * 16}, model) == \
        ["digestpkg.model"]
    (pkg / "model.py").write_text("X = 2\n")  # edited since
    assert differing_code(code, model) == ["digestpkg.model"]
    (pkg / "model.py").write_bytes(b"X = 1\r\n")  # the same code from a Windows checkout (a red team)
    assert differing_code(code, model) == []
    # names of other packages, which the other process chose, are neither compared nor imported (a red team: the
    # coordinator imported 'this' and printed the Zen of Python); nor is a subpackage's __init__ run to find a file
    (pkg / "sub").mkdir()
    (pkg / "sub" / "__init__.py").write_text("raise SystemExit('imported')\n")
    (pkg / "sub" / "leaf.py").write_text("Z = 3\n")
    assert differing_code({"this": "0" * 16, "digestpkg.sub.leaf": "0" * 16}, model) == ["digestpkg.sub.leaf"]
    imported = "this" in sys.modules
    assert differing_code({"this": "0" * 16}, "this:X") == ["this"]  # a lone module: found by its file, not imported
    assert ("this" in sys.modules) is imported
    # a helper module beside the package, in the model's project, is its code too (the tutorial's rk4.py, copied
    # and edited on a second machine, was not compared: a newcomer probe); cosim's own modules are not the model's
    (pkg / "model.py").write_text("X = 1\n")
    (tmp_path / "digesthelper.py").write_text("H = 1\n")
    importlib.import_module("digesthelper")
    code = code_digests("digestpkg.model")
    assert code["digesthelper"] == hashlib.sha256(b"H = 1\n").hexdigest()[:16]
    assert not any(name.startswith("cosim") for name in code)
    assert code_digests("digesthelper")["digestpkg.model"] == code["digestpkg.model"]  # a lone module's project too
    assert differing_code(code, model) == []
    (tmp_path / "digesthelper.py").write_text("H = 2\n")
    assert differing_code(code, model) == ["digesthelper"]
    assert differing_code({"cosim.runtime": "0" * 16}, model) == []  # (not the model's: never compared)
    described = {"name": "a", "model": "m.M", "inputs": {}, "outputs": {}, "algebraic": False, "configured": False,
                 "history_limit": 1, "protocol": 1}
    assert decode_reply("describe", encode_result({**described, "code": code}))["code"] == code
    with pytest.raises(ProtocolError, match=re.escape("result.code.m: expected a string, got 3")):
        decode_reply("describe", encode_result({**described, "code": {"m": 3}}))
    with pytest.raises(ProtocolError, match=re.escape("result.code key: expected a string")):  # (it crashed the run)
        decode_reply("describe", encode_result({**described, "code": {b"zz": "a", "x": "b"}}))
