"""Scenario loading: every mistake is reported with the file and the offending key."""

from __future__ import annotations

from pathlib import Path

import pytest

from cosim.runner import open_session
from cosim.scenario import ScenarioError, load

GOOD = """
stop = 1.0
[coupling]
method = "distributed"
interval = 0.1
samples = 5
[coupling.centralized]
tol = 1e-12
[subsims.a]
model = "subsims.integrator.subsim:Integrator"
params = { size = 2 }
[subsims.b]
model = "subsims.integrator.subsim:Integrator"
[[couplings]]
to = "a.u"
from = "a.y"
transform = "gain"
params = { k = -1.0 }
[[couplings]]
to = "b.u"
from = ["a.y"]
transform = "linear"
params = { gains = [[[1.0, 0.0]]] }
"""


def write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "s.toml"
    p.write_text(text)
    return p


def test_good_scenario_loads_with_per_method_settings(tmp_path: Path) -> None:
    sc = load(write(tmp_path, GOOD))
    assert sc.default_method == "distributed"
    assert sc.settings_for("centralized").tol.rel == 1e-12
    assert sc.settings_for("distributed").tol.rel == 1e-10
    assert sc.settings_for().interval == 0.1 and sc.settings_for().samples == 5
    assert [str(c) for c in sc.couplings] == ["a.y -> a.u", "a.y -> b.u"]


@pytest.mark.parametrize(
    ("old", "new", "key", "words"),
    [
        ('to = "b.u"', 'to = "c.u"', "couplings[1]", "unknown subsim 'c'"),
        ('from = ["a.y"]', 'from = "a"', "couplings[1]", "subsim.port"),
        ("tol = 1e-12", "tol = -1.0", "coupling.centralized", "tol (Tolerance.rel) must be a finite number >= 0"),
        ("samples = 5", "samples = 1", "coupling", "samples"),
        ('method = "distributed"', 'method = "jacobi"', "coupling.method", "jacobi"),
        ("interval = 0.1", "interval = 0.1\nspeed = 3", "coupling", "unknown key(s) ['speed']"),
        ('model = "subsims.integrator.subsim:Integrator"\nparams', 'model = "subsims.nothere:X"\nparams',
         "subsims.a.model", "not found"),
        ('transform = "gain"', 'transform = "warp"', "couplings[0]", "unknown transform 'warp'"),
        ("stop = 1.0", "stop = -1.0", "stop", "after start"),
        ("stop = 1.0", "stop = inf", "stop", "must be a finite number, got inf"),  # (it ran until killed: red team)
        ("stop = 1.0", "", "stop", "is required: stop = <a number>"),
        # no interval fits every model (the old default, 1 s, ran a 0.4 s-period oscillator 6 times off, exit 0)
        ("interval = 0.1", "", "coupling.interval", 'is required: the convergence interval in s, short against'),
        ("interval = 0.1", "[coupling.distributed]\ninterval = 0.1", "coupling.interval", "or interval = \"auto\""),
        ("samples = 5", "sampels = 5", "coupling", "unknown key(s) ['sampels'] (did you mean 'samples'?); allowed:"),
        ("samples = 5", "sampels = 5\nmetod = 'x'", "coupling",
         "['metod', 'sampels'] (did you mean 'method' for 'metod', 'samples' for 'sampels'?)"),
        ("stop = 1.0", 'stop = 1.0\n[unified]\nfuncton = "m:f"', "unified", "unknown key(s) ['funct"),
        ('[subsims.b]\nmodel = "subsims.integrator.subsim:Integrator"', "[subsims.b]", "subsims.b", "needs model"),
        ("[subsims.b]", '[subsims."b.1"]', "subsims.b.1", "has a '.', which separates a subsim from its port"),
        ("[subsims.b]", f'[subsims.{"b" * 65}]', f"subsims.{'b' * 65}",  # (it said '.' was allowed: a docs probe)
         "must be 1-64 characters of letters, digits, '_' or '-'"),
        # a subsim started on another machine (launcher)
        ("[subsims.b]", "[subsims.b]\nlauncher = 'ssh lab-2'", "subsims.b.launcher", "non-empty list of strings"),
        ("[subsims.b]", "[subsims.b]\nlauncher = []", "subsims.b.launcher", "non-empty list of strings"),
        ("[subsims.b]", "[subsims.b]\nworkdir = '/x'", "subsims.b.workdir", "add launcher = [...]"),
        ("[subsims.b]", "[subsims.b]\nlauncher = ['ssh', 'h']\nexternal = true", "subsims.b",
         "launcher (cosim starts it elsewhere) or external = true (you start it), not both"),
        ("[subsims.b]", "[subsims.b]\nlauncher = ['ssh', 'h']\npython = 3", "subsims.b.python",
         "must be a non-empty string"),
        ("[subsims.b]", "[subsims.b]\nlauncher = ['ssh', 'h']\nconnect = 'garbage'", "subsims.b.connect",
         "must be an endpoint such as 'tcp/192.168.1.10:7447', got 'garbage'"),
        # values of the wrong type: refused by key, never a bare TypeError or AttributeError
        ('to = "b.u"', "to = 3", "couplings[1].to", "must be a string, got 3"),
        ('from = ["a.y"]', 'from = ["a.y", 4]', "couplings[1].from", "must be a 'subsim.port' string or a list"),
        ('to = "b.u"', 'to = "b.u"\ndoc = 3', "couplings[1].doc", "must be a string"),
        ("params = { size = 2 }", "params = { size = 2 }\ndoc = 3", "subsims.a.doc", "must be a string"),
        ("stop = 1.0", "stop = 1.0\nname = 3", "name", "must be a string, got 3"),
        ("stop = 1.0", "stop = 1.0\ndescription = true", "description", "must be a string, got True"),
        ("stop = 1.0", "stop = 1.0\n[output]\npath = 3", "output.path", "must be a string, got 3"),
        ("interval = 0.1", "interval = true", "coupling", "interval must be a positive number, got True"),
        ("samples = 5", "samples = true", "coupling", "samples must be an integer >= 2, got True"),
        ("interval = 0.1", "interval = 0.1\nmax_halvings = true", "coupling", "max_halvings must be an integer"),
    ],
)
def test_load_errors_name_the_key(tmp_path: Path, old: str, new: str, key: str, words: str) -> None:
    assert old in GOOD
    with pytest.raises(ScenarioError) as err:
        load(write(tmp_path, GOOD.replace(old, new, 1)))
    assert f"[{key}]" in str(err.value) and words in str(err.value) and "s.toml" in str(err.value)
    assert str(err.value).count("s.toml") == 1, str(err.value)  # one prefix: not wrapped twice


def test_an_interval_key_without_auto_is_named_once(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError) as err:
        load(write(tmp_path, GOOD.replace("interval = 0.1", "interval = 0.1\ninterval_tol = 1e-6", 1)))
    assert str(err.value) == f"{tmp_path / 's.toml'}: [coupling] ['interval_tol'] need interval = \"auto\""


@pytest.mark.parametrize(
    ("old", "new", "key", "words"),
    [
        ('from = ["a.y"]', 'from = ["a.z"]', "couplings[1]", "has no output 'z'"),
        ('to = "b.u"', 'to = "b.w"', "couplings[1]", "has no input 'w'"),
        ('from = ["a.y"]\ntransform = "linear"\nparams = { gains = [[[1.0, 0.0]]] }', 'from = "a.y"',
         "couplings[1]", "size mismatch"),
        ("params = { size = 2 }", "params = { size = 2, y0 = [1.0] }", "subsims.a.params", "y0"),
        ("[[couplings]]", '[tolerances."a.yy"]\nabs = 1.0\n[[couplings]]', "tolerances.'a.yy'", "no subsim"),
    ],
)
def test_signal_errors_found_when_ports_are_known_name_the_key(
    tmp_path: Path, old: str, new: str, key: str, words: str
) -> None:
    assert old in GOOD
    sc = load(write(tmp_path, GOOD.replace(old, new, 1)))
    with pytest.raises(ScenarioError) as err:
        open_session(sc, inprocess=True).close()
    assert f"[{key}]" in str(err.value) and words in str(err.value)


def test_missing_file_and_bad_toml(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match="not found"):
        load(tmp_path / "nope.toml")
    with pytest.raises(ScenarioError, match="not valid TOML"):
        load(write(tmp_path, "stop = = 1"))


def test_a_subsim_started_elsewhere_is_not_imported_here(tmp_path: Path) -> None:
    """Its model lives on its machine: a module this one lacks is no error at load."""
    text = GOOD.replace('[subsims.b]\nmodel = "subsims.integrator.subsim:Integrator"',
                        '[subsims.b]\nmodel = "lab_only.model:Thing"\nlauncher = ["ssh", "lab-2"]\n'
                        'workdir = "/srv/lab"\npython = "/opt/venv/bin/python"')
    b = load(write(tmp_path, text)).subsims["b"]
    assert (b.launcher, b.workdir, b.python, b.connect) == (("ssh", "lab-2"), "/srv/lab", "/opt/venv/bin/python", None)
    with pytest.raises(ScenarioError, match=r"\[subsims.b\] is started on another machine .launcher.: it cannot run "
                       "in this process"):
        open_session(load(write(tmp_path, text)), inprocess=True)


@pytest.mark.parametrize("name", ["../../x", " ", "..", "mass/spring"])
def test_a_name_that_would_make_the_default_results_file_a_path_is_refused_when_it_is_used(tmp_path: Path,
                                                                                           name: str) -> None:
    """The name names results/<name>-<method>.csv: name = '../../x' wrote results/../../x-distributed.csv, outside
    results/. Refused then, naming the key; a scenario that writes elsewhere ([output] path) may be called so (a red
    team: 'mass/spring A/B' with [output] path was refused by a first fix)."""
    from cosim.runner import default_output

    sc = load(write(tmp_path, GOOD.replace("stop = 1.0", f"stop = 1.0\nname = {name!r}", 1)))
    with pytest.raises(ScenarioError) as err:
        default_output(sc, "distributed")
    assert f"[name] {name!r} names the default results file" in str(err.value) and "s.toml" in str(err.value)
    elsewhere = load(write(tmp_path, GOOD.replace("stop = 1.0", f"stop = 1.0\nname = {name!r}\n[output]\n"
                                                  "path = 'out.csv'", 1)))
    assert default_output(elsewhere, "distributed") == Path.cwd() / "out.csv"
    assert default_output(load(write(tmp_path, GOOD)), "centralized") == Path.cwd() / "results" / "s-centralized.csv"
