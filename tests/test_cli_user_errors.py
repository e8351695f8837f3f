"""A user's mistakes, through the CLI as a process: one line naming what is wrong, exit 2, no traceback."""

from __future__ import annotations

import os
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
    # a name that differs only in case is too short for a similarity: it is found all the same
    ("params = { m = 1.0, k = 197.39208802178717, u0 = 1.0,", "params = { M = 1.0, k = 197.39208802178717, u0 = 1.0,",
     ["[subsims.mass1.params]", "'M' (did you mean 'm'?)"]),
    # a number in quotes: refused by name, before it fails deep inside the model
    ("params = { m = 1.0, k = 197.39208802178717, u0 = 1.0,",
     'params = { m = "1.0", k = 197.39208802178717, u0 = 1.0,',
     ["[subsims.mass1.params]", "parameter 'm' must be a number (its default is 1.0), got the string '1.0'",
      "without quotes"]),
    # a transform's parameter misspelled, and gains that do not fit the signals: found before the run
    ('params = { k = 157.91367041742973 }\n\n[[couplings]]', 'params = { kk = 157.91367041742973 }\n\n[[couplings]]',
     ["[couplings[0]]", "transform 'gain'", "unexpected keyword argument 'kk' (did you mean 'k'?); it takes: k"]),
    ('params = { k = 157.91367041742973 }\n\n[[couplings]]', 'params = { K = 157.91367041742973 }\n\n[[couplings]]',
     ["[couplings[0]]", "unexpected keyword argument 'K' (did you mean 'k'?); it takes: k"]),  # (a newcomer probe)
    ('params = { k = 157.91367041742973 }\n\n[[couplings]]', 'params = { k = [[1.0], [2.0]] }\n\n[[couplings]]',
     ["[couplings[0]]", "mass2.u -> mass1.F: transform 'gain' turns 2 samples of mass2.u (1 wide) into shape (2, 2)",
      "input mass1.F takes 1 per sample"]),
    ('transform = "gain"\nparams = { k = 157.91367041742973 }\n\n[[couplings]]',
     'transform = "linear"\nparams = { gains = [1.0, 2.0] }\n\n[[couplings]]',
     ["[couplings[0]]", "transform 'linear': linear: 1 sources need 1 gains, got 2"]),
    # a package where a class is needed (as spawn_subsim and python -m take it): the class it holds is named
    ('model = "subsims.oscillator.subsim:Mass"', 'model = "subsims.oscillator"',
     ["[subsims.mass1.model]", "must be 'package.module:Class' (did you mean 'subsims.oscillator.subsim:Mass'?)"]),
    # the hint reads the module's source: a __main__ named there is not run (it printed its usage and exited 2)
    ('model = "subsims.oscillator.subsim:Mass"', 'model = "subsims.oscillator.__main__"',
     ["[subsims.mass1.model]", "model 'subsims.oscillator.__main__' must be 'package.module:Class'"]),
    ('model = "subsims.oscillator.subsim:Mass"', 'model = "subsims.no_such_package"',
     ["[subsims.mass1.model]", "model 'subsims.no_such_package' must be 'package.module:Class'"]),
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


def picky_scenario(tmp_path: Path, extra: str = "") -> Path:
    """The oscillator with a transform of the user's that fails once |x| passes 0.6 (not on the trial call before
    the run), plus ``extra`` TOML."""
    (tmp_path / "picky.py").write_text(
        "import numpy as np\n\n\ndef picky(x, k, limit):\n"
        "    if np.abs(x).max() > limit:\n        raise ValueError(f'|x| = {np.abs(x).max():.2f} is past {limit}')\n"
        "    return k * x\n")
    text = OSCILLATOR.read_text()
    old = 'transform = "gain"\nparams = { k = 157.91367041742973 }\n\n[[couplings]]'
    assert old in text
    sc = tmp_path / "s.toml"
    sc.write_text(text.replace(old, 'transform = "picky:picky"\nparams = { k = 157.91367041742973, limit = 0.6 }'
                                    '\n\n[[couplings]]', 1) + extra)
    return sc


def test_a_transform_failing_in_a_run_stops_it_in_one_line_keeping_what_was_committed(tmp_path: Path) -> None:
    """A user's transform that fails only on some values (not on the trial call before the run): the run
    stops with one line naming the coupling and the error (it was a raw traceback), exit 1, and the
    committed intervals stay in the results."""
    sc = picky_scenario(tmp_path)
    out = tmp_path / "x.csv"
    for where in (["--inprocess"], []):
        done = subprocess.run([*COSIM, "run", str(sc), *where, "--quiet", "--output", str(out), "--overwrite"],
                              capture_output=True, text=True, timeout=120, cwd=tmp_path)
        lines = done.stderr.strip().splitlines()  # --quiet: the subsims started do not announce themselves either
        assert done.returncode == 1 and len(lines) == 2 and "Traceback" not in done.stderr, done.stderr
        assert lines[0].startswith("cosim: run stopped: coupling mass2.u -> mass1.F: transform 'picky:picky' "
                                   "failed: |x| = "), lines[0]
        assert lines[0].endswith("is past 0.6 (ValueError at picky.py:6)"), lines[0]  # (where: a newcomer probe)
        # where the intervals are, and (no resume point yet) how to run again: it said nothing (a newcomer probe)
        end = float(out.read_text().splitlines()[-1].split(",")[0])
        assert lines[1] == f"cosim: every interval to t = {end:.6g} s is in {out}; once that is fixed, the same " \
                           "command runs it again from the start", lines[1]
        rows = out.read_text().splitlines()[1:]
        assert len(rows) > 5 and all(abs(float(r.split(",")[3])) <= 0.6 for r in rows)  # mass2.u
    # failing in the first interval: no file is left (headers only), so a second try needs no --overwrite
    sc.write_text(sc.read_text().replace("limit = 0.6", "limit = -1.0"))
    for f in tmp_path.glob("x.*"):
        f.unlink()
    for _ in range(2):
        done = subprocess.run([*COSIM, "run", str(sc), "--quiet", "--output", str(out)], capture_output=True,
                              text=True, timeout=120, cwd=tmp_path)
        assert done.returncode == 1 and "is past -1.0" in done.stderr and "exists" not in done.stderr, done.stderr
        assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("x.")) == []


def test_a_run_stopped_by_an_error_after_a_resume_point_says_how_to_go_on(tmp_path: Path) -> None:
    """A run that stops on an error late (a transform here; a subsim out of restarts, a full disk alike) said only
    the error: nothing said the results were kept or that --resume goes on once it is fixed (ops probe)."""
    sc = picky_scenario(tmp_path, "\n[run]\ncheckpoint_every = 2\n")
    out = tmp_path / "x.csv"
    done = subprocess.run([*COSIM, "run", str(sc), "--inprocess", "--quiet", "--output", str(out)],
                          capture_output=True, text=True, timeout=120)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 1 and len(lines) == 2 and lines[0].startswith("cosim: run stopped: coupling "), lines
    end = out.read_text().splitlines()[-1].split(",")[0]
    assert lines[1].startswith(f"cosim: every interval to t = {float(end):.6g} s is in {out}; once that is fixed, "
                               "the same command with --resume goes on from t = "), lines[1]
    again = subprocess.run([*COSIM, "run", str(sc), "--inprocess", "--quiet", "--output", str(out), "--overwrite"],
                           capture_output=True, text=True, timeout=120)  # (--resume and --overwrite exclude each other)
    assert "the same command with --resume instead of --overwrite goes on" in again.stderr, again.stderr


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_an_overwrite_that_fails_before_its_first_interval_keeps_the_results_it_was_to_replace(
        tmp_path: Path, suffix: str) -> None:
    """--overwrite of good results by a run that stops in its first interval (it cannot converge): the good files
    stay as they were, byte for byte (they were gone), and no staged file is left. The interrupted run's resume
    point stays too; once a run's first interval is in, the files are the new run's."""
    out = tmp_path / f"x{suffix}"

    def run(scenario: Path, *extra: str) -> subprocess.CompletedProcess:
        return subprocess.run([*COSIM, "run", str(scenario), "--inprocess", "--quiet", "--output", str(out), *extra],
                              capture_output=True, text=True, timeout=120)

    done = run(OSCILLATOR, "--stop", "0.2")
    assert done.returncode == 0, done.stderr
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    assert len(before) == (2 if suffix == ".npz" else 3), sorted(before)  # results, diagnostics (, units)
    (tmp_path / f"x{suffix}.resume.npz").write_bytes(b"an interrupted run's")  # (it would be replaced too)
    before[f"x{suffix}.resume.npz"] = b"an interrupted run's"
    bad = tmp_path / "bad.toml"
    bad.write_text(OSCILLATOR.read_text().replace("max_stages = 50", "max_stages = 2", 1))
    done = run(bad, "--stop", "0.2", "--overwrite")
    assert done.returncode == 1 and "did not converge in 2 stages" in done.stderr, done.stderr
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir() if p != bad} == before
    done = run(OSCILLATOR, "--stop", "0.1", "--overwrite")
    assert done.returncode == 0, done.stderr
    after = {p.name for p in tmp_path.iterdir() if p != bad}
    assert after == set(before) - {f"x{suffix}.resume.npz"}, after  # a finished run leaves no resume point
    assert out.read_bytes() != before[out.name]  # the new, shorter run's


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
    # an import in the module failing: it was "model 'broken:Broken' not found (No module named 'scipy.signall')",
    # of a file that is there (a newcomer probe)
    ("import math\nimport scipy.signall\n", ["ModuleNotFoundError", "scipy.signall", "broken.py, line 2"]),
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


def test_a_model_whose_constructor_raises_is_one_line_in_one_process_and_over_zenoh(tmp_path: Path) -> None:
    """``__init__`` raising (a licence server, a missing file) printed 28 lines of cosim's traceback in one process
    and from ``cosim describe``, and 20 from the subsim process before the line that said it (a probe)."""
    (tmp_path / "licensed.py").write_text(
        "from subsims.oscillator.subsim import Mass\n\nclass Licensed(Mass):\n    def __init__(self):\n"
        "        raise ValueError('license server not found')\n")
    sc = tmp_path / "s.toml"
    sc.write_text(OSCILLATOR.read_text().replace('model = "subsims.oscillator.subsim:Mass"',
                                                 'model = "licensed:Licensed"', 1))
    said = "Licensed() raised ValueError: license server not found (licensed.py:5 in __init__)"
    for command in (["run", str(sc), "--inprocess", "--quiet", "--output", str(tmp_path / "x.csv")],
                    ["describe", str(sc)], ["run", str(sc), "--quiet", "--output", str(tmp_path / "y.csv")]):
        done = subprocess.run([*COSIM, *command], capture_output=True, text=True, timeout=120, cwd=tmp_path)
        assert done.returncode != 0 and "Traceback" not in done.stderr, done.stderr
        assert done.stderr.strip().splitlines()[-1].endswith(said), done.stderr
        if "--inprocess" in command or "describe" in command:
            assert done.stderr.strip().splitlines() == [f"cosim: {sc}: [subsims.mass1] {said}"], done.stderr


@pytest.mark.parametrize(("args", "words"), [
    (["--timeout", "0"], "--timeout must be a finite number of seconds > 0, got 0"),
    (["--timeout", "nan"], "--timeout must be a finite number of seconds > 0, got nan"),
    (["--restarts", "-1"], "--restarts must be a whole number >= 0, got -1"),
    (["--attach-wait", "-5"], "--attach-wait must be a finite number of seconds > 0, got -5"),
    (["--output", "out.txt"], "--output out.txt: a result file ends in .csv or .npz (lower case)"),
    (["--output", "out.NPZ"], "--output out.NPZ: a result file ends in .csv or .npz (lower case)"),
    (["--resume", "--overwrite"], "--resume goes on with the results; --overwrite starts them again: give one of them"),
    # a model hanging in one process waited forever with --timeout 5 given (a newcomer probe)
    (["--inprocess", "--timeout", "5"], "--timeout is for subsim processes: with --inprocess every model runs in this "
                                        "one, which nothing times out (Ctrl-C stops a model in Python code; one stuck "
                                        "in native code, an FMU, only kill -9 does)"),
    (["--resume", "--method", "unified"],
     "--resume continues coupled runs (centralized, distributed), not unified ones"),
])
def test_a_bad_option_value_is_refused_naming_the_option(tmp_path: Path, args: list[str], words: str) -> None:
    """Values the scenario file's [run] table refuses are refused on the command line too (a zero timeout made every
    subsim 'hung'; a .txt output was written as CSV)."""
    done = subprocess.run([*COSIM, "run", str(OSCILLATOR), "--quiet", *args], capture_output=True, text=True,
                          timeout=60, cwd=tmp_path)
    assert done.returncode == 2 and done.stderr.splitlines() == [f"cosim: {words}"], done.stderr
    assert not (tmp_path / "results").exists()  # refused before anything ran


def test_a_scenario_timeout_that_cannot_apply_in_one_process_is_said(tmp_path: Path) -> None:
    """[run] timeout in the file was ignored without a word with --inprocess (the flag is refused; the file serves both
    ways, so it is said, not refused)."""
    scenario = tmp_path / "s.toml"
    scenario.write_text(OSCILLATOR.read_text() + "\n[run]\ntimeout = 30\n")
    done = subprocess.run([*COSIM, "run", str(scenario), "--quiet", "--inprocess", "--stop", "0.05"],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stderr.splitlines()[0] == ("cosim: [run] timeout = 30 s is for subsim processes: with --inprocess "
                                           "nothing times out a model (Ctrl-C stops one in Python code)"), done.stderr


@pytest.mark.parametrize("command", ["run", "describe", "plot"])
def test_a_misspelled_option_shows_the_usage_of_its_own_command(tmp_path: Path, command: str) -> None:
    """Not the top-level ``cosim`` usage, which lists none of the command's options."""
    done = subprocess.run([*COSIM, command, str(OSCILLATOR), "--stopp", "3"], capture_output=True, text=True,
                          timeout=60, cwd=tmp_path)
    assert done.returncode == 2
    assert done.stderr.startswith(f"usage: cosim {command} ")
    assert done.stderr.rstrip().endswith(f"cosim {command}: error: unrecognized arguments: --stopp 3"), done.stderr


@pytest.mark.parametrize(("command", "words"), [
    (["run", "."], "is a directory: give a scenario file (.toml) in it"),
    (["describe", "."], "is a directory: give a scenario file (.toml) in it"),
    (["run", "binary.toml"], "binary.toml: not a text file, so not a scenario (TOML)"),
    (["run", str(OSCILLATOR), "--listen", "garbage"], "cannot listen on garbage: Endpoints must be of the form"),
    (["describe", str(OSCILLATOR), "--listen", "tcp/127.0.0.1:0"], "--listen is where the router of --launch"),
])
def test_a_scenario_or_endpoint_that_cannot_be_used_is_one_line(tmp_path: Path, command: list[str],
                                                                words: str) -> None:
    (tmp_path / "binary.toml").write_bytes(bytes(range(256)))
    done = subprocess.run([*COSIM, *command, "--quiet"] if command[0] == "run" else [*COSIM, *command],
                          capture_output=True, text=True, timeout=60, cwd=tmp_path)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1 and words in lines[0], done.stderr
    assert ".rs:" not in lines[0] and "Traceback" not in done.stderr  # no Rust source paths, no Python frames


@pytest.mark.parametrize(("command", "words"), [
    (["-m", "subsims.oscillator", "--connect", "tcp/127.0.0.1:9", "--run", "r1", "--connect-timeout", "-1"],
     "argument --connect-timeout: must be a number of seconds > 0 and at most a day, got -1"),
    (["-m", "subsims.oscillator", "--connect", "tcp/127.0.0.1:9", "--run", "r1", "--lease", "nan"],
     "argument --lease: must be a number of seconds > 0 and at most a day, got nan"),
    (["-m", "subsims.oscillator", "--connect", "tcp/127.0.0.1:9", "--run", "r1", "--history", "-1"],
     "argument --history: must be a whole number >= 0, got -1"),
    (["-m", "cosim.conformance", "tcp/127.0.0.1:0", "r1", "mass", "--samples", "1"],
     "--samples must be at least 2"),
    (["-m", "cosim.conformance", "tcp/127.0.0.1:0", "r1", "mass", "--interval", "0"],
     "--interval must be a finite number of seconds > 0"),
    (["-m", "cosim.conformance", "garbage", "r1", "mass"], "cannot listen on garbage"),
])
def test_a_subsim_or_checker_argument_that_cannot_work_is_refused_at_once(command: list[str], words: str) -> None:
    """An endless --connect-timeout could not be interrupted (zenoh holds the signals while it connects); a bad
    --history or --lease was a traceback; a bad --interval was reported as the subsim's violation."""
    done = subprocess.run([sys.executable, *command], capture_output=True, text=True, timeout=60,
                          env={**os.environ, "COSIM_SECRET": "00" * 32, "COSIM_ZENOH_AUTH": "site:pw"})
    assert done.returncode == 2 and words in done.stderr.strip().splitlines()[-1], done.stderr
    assert "Traceback" not in done.stderr


def test_describe_of_a_scenario_with_an_external_subsim_describes_its_model_or_says_how(tmp_path: Path) -> None:
    """The tutorial's last scenario (one subsim external, its model named) was refused by cosim describe, which
    pointed at cosim run (a newcomer probe): its model is described from this machine's copy. Without a model
    named there is nothing to describe here: it says how."""
    sc = tmp_path / "s.toml"
    sc.write_text(OSCILLATOR.read_text().replace("[subsims.mass2]\n", "[subsims.mass2]\nexternal = true\n", 1))
    done = subprocess.run([*COSIM, "describe", str(sc)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert "  mass2 [subsims.oscillator.subsim:Mass, external]\n    in:  F(1 N)\n" in done.stdout, done.stdout
    sc.write_text(sc.read_text().replace('external = true\nmodel = "subsims.oscillator.subsim:Mass"\n',
                                         "external = true\n", 1))
    done = subprocess.run([*COSIM, "describe", str(sc)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "cosim describe --launch" in done.stderr and "Traceback" not in done.stderr


def test_a_binary_auth_file_is_named(tmp_path: Path) -> None:
    (tmp_path / "users").write_bytes(bytes(range(128, 256)))
    done = subprocess.run([*COSIM, "run", str(OSCILLATOR), "--auth-file", str(tmp_path / "users"), "--quiet",
                           "--output", str(tmp_path / "x.csv")], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and done.stderr.splitlines() == [
        f"cosim: credential file {tmp_path / 'users'} is not text: expected 'user:password' lines"], done.stderr


def test_serve_help_is_not_an_error() -> None:
    done = subprocess.run([sys.executable, "-m", "cosim.serve", "--help"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stdout.startswith("usage: python -m cosim.serve package.module:Class")


def test_a_run_whose_stderr_reader_went_away_still_runs_to_the_end(tmp_path: Path) -> None:
    """`cosim run ... 2>&1 | head -1`, a dead tee: every line on stderr then fails with EPIPE. The subsims died
    of it at their first line (and replacements at theirs), and the run stopped without a word. The
    pipe is closed before anything is written, so every line of the run meets EPIPE."""
    out = tmp_path / "x.csv"
    proc = subprocess.Popen([*COSIM, "run", str(OSCILLATOR), "--stop", "1", "--output", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    proc.stderr.close()
    try:
        stdout, _ = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, stdout
    assert "20 intervals to t = 1 " in stdout
    assert out.read_text().splitlines()[-1].startswith("1.0,")


@pytest.mark.parametrize(("interval", "words"), [
    ("5", "transform 'gain' produced NaN or inf (as a coupling iteration that diverges makes them: a shorter "
          "[coupling] interval then; its sources reached "),
    ("20", "on inputs the coupling iteration made: if that iteration diverged (values growing stage by stage), a "
           "shorter [coupling] interval is the cure"),
])
def test_an_interval_so_long_that_the_iteration_diverges_says_so(tmp_path: Path, interval: str, words: str) -> None:
    """The oscillator at 5 s and 20 s intervals (its period is 0.4 s): the iteration overflows. It read as a bug in a
    transform or a model ('output 'u' is not finite'), with nothing pointing at the interval (newcomer probe)."""
    text = OSCILLATOR.read_text()
    assert "\ninterval = " in text
    sc = tmp_path / "long.toml"
    sc.write_text("\n".join(f"interval = {interval}" if x.startswith("interval = ") else x
                            for x in text.splitlines()))
    done = subprocess.run([*COSIM, "run", str(sc), "--inprocess", "--quiet", "--stop", "120", "--output",
                           str(tmp_path / "x.csv")], capture_output=True, text=True, timeout=120)
    assert done.returncode == 1 and words in done.stderr, done.stderr
    assert "Traceback" not in done.stderr


def test_an_interval_longer_than_the_run_is_said(tmp_path: Path) -> None:
    """interval = 500 with stop = 100 ran one interval to t = 500 and said nothing of it (a newcomer probe)."""
    from cosim.runner import run_scenario
    from cosim.scenario import load

    said: list[str] = []
    run_scenario(load(OSCILLATOR), stop=0.03, output=tmp_path / "x.csv", inprocess=True, progress=False,
                 log=said.append)
    assert said == ["cosim: [coupling] interval = 0.05 s is longer than the run (0 to 0.03 s): it runs one whole "
                    "interval, to t = 0.05"]
    said.clear()
    run_scenario(load(OSCILLATOR), stop=0.05, output=tmp_path / "y.csv", inprocess=True, progress=False,
                 log=said.append)
    assert said == []
