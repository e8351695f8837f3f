"""cosim.run: the same run as ``cosim run``, bit for bit, as numpy arrays."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

import cosim
from cosim.outputs import OutputError
from cosim.results import DIAG_COLUMNS, read_results
from cosim.scenario import ScenarioError

pytestmark = [pytest.mark.slow]  # the inner loop: pytest -m "not slow"

ROOT = Path(__file__).parents[1]
OSCILLATOR = ROOT / "scenarios" / "oscillator.toml"
CASE1 = ROOT / "scenarios" / "satellite" / "case1.toml"


def cli(tmp_path: Path, scenario: Path, *args: str) -> tuple[list[str], np.ndarray, np.ndarray]:
    out = tmp_path / "cli.csv"
    done = subprocess.run([sys.executable, "-m", "cosim.cli", "run", str(scenario), "--output", str(out), "--quiet",
                           *args], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    columns, data = read_results(out)
    diag_columns, diag = read_results(tmp_path / "cli.csv.diag.csv")
    assert diag_columns == DIAG_COLUMNS
    return columns, data, diag


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.mark.parametrize("method", ["distributed", "centralized"])
def test_run_returns_the_cli_results_bit_for_bit(tmp_path: Path, method: str) -> None:
    columns, data, diag = cli(tmp_path, OSCILLATOR, "--method", method, "--stop", "0.3")
    r = cosim.run(OSCILLATOR, method=method, stop=0.3)  # over Zenoh, processes launched, as the CLI does
    assert r.method == method and r.output is None
    for i, name in enumerate(columns):
        assert same_bits(r.column(name), data[:, i]), name
    assert r["mass1.u"].shape == (data.shape[0], 1)
    assert same_bits(r.diagnostics["stages"].astype(float), diag[:, 3])
    assert same_bits(r.diagnostics["t1"], diag[:, 2]) and r.summary.intervals == diag.shape[0] == 6
    assert list(r.diagnostics) == DIAG_COLUMNS  # every column of the .diag.csv, as documented
    for name in ("halvings", "restarts", "length_s"):  # written exactly; largest_residual and error are rounded
        assert same_bits(r.diagnostics[name].astype(float), diag[:, DIAG_COLUMNS.index(name)]), name
    assert r.order == ["mass1", "mass2"] and r.feedback == ["mass2.u -> mass1.F"]


def test_unified_method_and_the_written_file(tmp_path: Path) -> None:
    columns, data, _ = cli(tmp_path, CASE1, "--method", "unified", "--stop", "2")
    out = tmp_path / "api.csv"
    r = cosim.run(CASE1, method="unified", stop=2, output=out)
    assert r.output == out and out.read_bytes() == (tmp_path / "cli.csv").read_bytes()
    for i, name in enumerate(columns):
        assert same_bits(r.column(name), data[:, i]), name
    coupled = cosim.run(OSCILLATOR, stop=0.1, inprocess=True)  # (read back from the file, counts were floats)
    assert {k: v.dtype for k, v in r.diagnostics.items()} == {k: v.dtype for k, v in coupled.diagnostics.items()}
    assert r.diagnostics["stages"].dtype == np.int64


def test_params_override_the_scenario_for_one_run(tmp_path: Path) -> None:
    moved = cosim.run(OSCILLATOR, stop=0.1, inprocess=True, params={"mass2": {"u0": 0.5}})
    assert moved["mass2.u"][0, 0] == 0.5 and moved["mass1.u"][0, 0] == 1.0
    with pytest.raises(ScenarioError, match="unknown subsim 'mass3'"):
        cosim.run(OSCILLATOR, stop=0.1, inprocess=True, params={"mass3": {"u0": 0.5}})
    with pytest.raises(ScenarioError, match="did you mean 'u0'") as err:
        cosim.run(OSCILLATOR, stop=0.1, inprocess=True, params={"mass2": {"u_0": 0.5}})
    assert str(err.value).endswith("(the params= of this call are merged over the file's)"), err.value  # (a probe)


def test_resume_goes_on_with_an_interrupted_run_and_returns_the_whole_run(tmp_path: Path) -> None:
    from cosim.runner import run_scenario
    from cosim.scenario import load, parse

    sc = load(OSCILLATOR)
    sc = parse({**sc.raw, "run": {**sc.raw.get("run", {}), "checkpoint_every": 10}}, sc.path)
    whole = cosim.run(sc, method="distributed", stop=3.0, inprocess=True)

    class Stop(Exception):
        pass

    seen = [0]

    def stop_at_47(_interval: object) -> None:
        seen[0] += 1
        if seen[0] == 47:
            raise Stop

    out = tmp_path / "part.csv"
    with pytest.raises(Stop):
        run_scenario(sc, method="distributed", stop=3.0, output=out, inprocess=True, progress=False,
                     on_interval=stop_at_47)
    with pytest.raises(ScenarioError, match="output="):
        cosim.run(sc, method="distributed", stop=3.0, inprocess=True, resume=True)
    r = cosim.run(sc, method="distributed", stop=3.0, output=out, inprocess=True, resume=True)
    assert r.summary.intervals == 20  # from the resume point at interval 40 of 60, not from t = 0
    assert r.method == "distributed" and r.output == out
    assert same_bits(r.t, whole.t) and set(r.signals) == set(whole.signals)
    for name, values in whole.signals.items():
        assert same_bits(r[name], values), name
    assert same_bits(r.diagnostics["t1"], whole.diagnostics["t1"])


TWO_CTRL_C = '''
import os, signal, sys, threading, time
from pathlib import Path
import cosim

def children():
    return [int(c) for t in Path(f"/proc/{os.getpid()}/task").iterdir() for c in (t / "children").read_text().split()]

def ctrl_c_twice():
    while len(children()) < 2:  # both subsims started
        time.sleep(0.01)
    time.sleep(0.5)  # mid-run
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(0.01)
    os.kill(os.getpid(), signal.SIGINT)

threading.Thread(target=ctrl_c_twice, daemon=True).start()
try:
    cosim.run(sys.argv[1], stop=1000.0)
except KeyboardInterrupt:
    print("KeyboardInterrupt", children(), sorted(os.listdir(os.environ["TMPDIR"])))
'''


def test_a_second_ctrl_c_does_not_cut_the_cleanup_short(tmp_path: Path) -> None:
    """Two SIGINTs 10 ms apart while cosim.run runs over the bus: one KeyboardInterrupt, raised once both subsim
    processes are stopped and reaped, and the run's private bus directory removed (a second Ctrl-C used to land
    in the middle of that)."""
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    done = subprocess.run([sys.executable, "-c", TWO_CTRL_C, str(OSCILLATOR)], capture_output=True, text=True,
                          timeout=120, env={**os.environ, "TMPDIR": str(scratch)})
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == "KeyboardInterrupt [] []", done.stdout + done.stderr[-2000:]


def test_arguments_the_command_would_refuse_are_refused_in_one_line(tmp_path: Path) -> None:
    for kwargs, words in (({"stop": -1.0}, "stop must be a finite time after the scenario's start (0 s), got -1.0"),
                          ({"stop": float("nan")}, "stop must be a finite time"),
                          ({"stop": "1.0"}, "got '1.0'"),
                          ({"restarts": -1}, "restarts must be a whole number >= 0"),
                          ({"timeout": 0}, "timeout must be a finite number of seconds > 0"),
                          ({"params": {"mass1": 3}}, "params['mass1'] must be {parameter: value}, got int"),
                          ({"run_id": "pa/bad"}, "run id 'pa/bad' must be 1-64 characters"),
                          ({"run_id": "a/b*", "inprocess": True}, "run id 'a/b*' must be 1-64 characters"),
                          ({"output": "x.txt"}, "output 'x.txt': a result file ends in .csv or .npz")):
        with pytest.raises(ScenarioError, match=re.escape(words)):
            cosim.run(OSCILLATOR, **kwargs)


def test_a_run_without_output_writes_nothing_and_an_interval_callback_sees_each_interval(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    monkeypatch.chdir(tmp_path)
    seen: list[float] = []
    r = cosim.run(OSCILLATOR, stop=0.3, inprocess=True, on_interval=lambda i: seen.append(float(i.t[-1])),
                  log=lambda line: None)
    assert list(tmp_path.iterdir()) == []  # no scratch directory, no results/ directory
    assert seen == list(r.diagnostics["t1"]) and len(seen) == 6
    assert cosim.run(OSCILLATOR, stop=np.float64(0.3), restarts=np.int64(1), inprocess=True).t.size == r.t.size
    with pytest.raises(KeyError, match=r"name one as 'subsim.port\[i\]'"):
        r.column("mass1.u")


def test_progress_is_drawn_in_a_notebook_and_not_in_a_log_file() -> None:
    """A Jupyter kernel's stderr says it is no terminal but shows "\\r" redraws: cosim.run(progress=True) drew
    nothing there. A plain file still gets nothing (logs stay clean)."""
    import io

    from cosim.progress import Progress

    class OutStream(io.StringIO):  # stands for ipykernel.iostream.OutStream
        pass

    OutStream.__module__ = "ipykernel.iostream"
    notebook, log = OutStream(), io.StringIO()
    for stream in (notebook, log):
        bar = Progress(0.0, 1.0, stream=stream, clock=lambda: 0.0)
        interval = type("I", (), {"t": np.array([0.0, 0.5]), "stages": 3})()
        bar.update(interval)
        bar.done()
    assert notebook.getvalue().startswith("\r 50.0%  t = 0.5 / 1 s") and "\x1b" not in notebook.getvalue()
    assert log.getvalue() == ""


def test_api_mistakes_are_named(tmp_path: Path) -> None:
    """A probe using cosim as a library: cosim.run(dict) met pathlib's TypeError, r.column('a.y[3]') a bare numpy
    IndexError, and method='jacobi' listed the coupled methods without unified."""
    with pytest.raises(ScenarioError, match="scenario must be a file path or a loaded Scenario, got dict"):
        cosim.run({"stop": 1.0})
    with pytest.raises(ScenarioError, match="method 'jacobi' unknown; use one of centralized, distributed, or unified"):
        cosim.run(OSCILLATOR, method="jacobi", stop=0.1, inprocess=True)
    r = cosim.run(OSCILLATOR, stop=0.1, inprocess=True)
    with pytest.raises(KeyError, match=r"column 'mass1.u\[3\]': mass1.u has 1 columns, \[0\] to \[0\]"):
        r.column("mass1.u[3]")
    assert r.column("mass1.u[0]").tobytes() == r["mass1.u"][:, 0].tobytes()


def test_a_bus_opened_in_a_fork_of_a_process_that_used_zenoh_is_refused_not_hung() -> None:
    """A parameter sweep: cosim.run once in the script, then in multiprocessing workers (forked, Linux's default):
    every worker hung for good (an API probe; Zenoh's threads do not survive a fork). It is refused, naming 'spawn'."""
    import select
    import signal

    from cosim.protocol.transport.session import open_router

    session, _ = open_router()  # this process uses Zenoh
    session.close()
    read, write = os.pipe()
    child = os.fork()
    if child == 0:  # pragma: no cover (the child)
        try:
            open_router()[0].close()
            said = "opened"
        except RuntimeError as exc:
            said = str(exc)
        os.write(write, said.encode())
        os._exit(0)
    os.close(write)
    try:
        ready, _, _ = select.select([read], [], [], 20.0)
        said = os.read(read, 4096).decode() if ready else "hung"
    finally:
        os.close(read)
        if not ready:
            os.kill(child, signal.SIGKILL)
        os.waitpid(child, 0)
    assert said.startswith("this process was forked (multiprocessing's default start method on Linux) from one that "
                           "had used Zenoh"), said
    assert "multiprocessing.get_context('spawn')" in said


def test_a_result_is_iterable_over_its_signals_short_in_repr_and_picklable() -> None:
    """What a notebook or a multiprocessing sweep does with a Result (an API probe): `in` and a for loop raised
    "no signal 0", pickle could not copy its scenario's read-only tables (a Pool could not return one), and its repr
    printed every array (10,014 characters)."""
    import pickle
    import types

    r = cosim.run(OSCILLATOR, stop=0.2, inprocess=True)
    assert "mass1.u" in r and "mass1.x" not in r and 0 not in r
    assert list(r) == ["mass1.u", "mass1.v", "mass2.u", "mass2.v"] and len(r) == 4
    assert repr(r) == ("<Result of 'oscillator', distributed: t = 0 to 0.2 s, 17 samples, 4 intervals; signals mass1.u "
                       "(1,), mass1.v (1,), mass2.u (1,), mass2.v (1,)>")
    back = pickle.loads(pickle.dumps(r))
    assert same_bits(back["mass2.u"], r["mass2.u"]) and back.scenario == r.scenario
    with pytest.raises(TypeError):  # what pickles the process's other read-only views is left as it was (a review)
        pickle.dumps(types.MappingProxyType({"a": 1}))
    with pytest.raises(TypeError):  # its tables are still read-only views
        back.scenario.subsims["mass1"] = None  # type: ignore[index]
    with pytest.raises(KeyError, match=r"name one as 'subsim.port\[i\]'"):  # (a ValueError from int('²'))
        r.column("mass1.u[²]")


def test_what_subsims_print_reaches_a_replaced_sys_stderr_and_a_broken_one_is_not_replaced(monkeypatch) -> None:
    """In a notebook sys.stderr is the notebook's stream: what the subsims wrote went to the kernel's terminal
    instead (copied to descriptor 2), and one OSError writing a line replaced the caller's sys.stderr with
    /dev/null for the rest of the process (an API probe)."""
    import contextlib
    import io

    from cosim.console import say

    shown = io.StringIO()
    with contextlib.redirect_stderr(shown):
        cosim.run(OSCILLATOR, stop=0.1, progress=True)
    assert re.search(r"^mass1: serving run run-\w+ via \S+ as Zenoh id \w+ \(pid \d+\)$", shown.getvalue(), re.M), \
        shown.getvalue()

    class Broken(io.StringIO):
        def write(self, text: str) -> int:
            raise BrokenPipeError(32, "Broken pipe")

    broken = Broken()
    monkeypatch.setattr(sys, "stderr", broken)
    say("one line")  # the reader is gone: nothing, no error
    assert sys.stderr is broken
    monkeypatch.setattr(sys, "stderr", shown)
    say("after it")
    assert shown.getvalue().endswith("after it\n")


def test_errors_name_the_functions_arguments_not_the_commands_options(tmp_path: Path) -> None:
    """A script was told to pass --overwrite and --resume (an API probe)."""
    out = tmp_path / "r.csv"
    cosim.run(OSCILLATOR, stop=0.1, inprocess=True, output=out)  # finished: no resume point left
    with pytest.raises(OutputError) as err:
        cosim.run(OSCILLATOR, stop=0.2, inprocess=True, output=out, resume=True)
    said = str(err.value)
    assert said.endswith("run it again from the start (resume=False)") and "--" not in said, said


def test_a_results_signals_are_in_the_scenarios_order_whatever_the_method() -> None:
    """list(r) followed the run's order, which the method decides: stacking two methods' signals misaligned them (a
    five-subsim probe). Case 1's distributed order is orbit, attitude, aero; its scenario's too, so aero goes first."""
    text = CASE1.read_text()
    first, rest = text.split("[subsims.orbit]", 1)
    aero_at = rest.index("[subsims.aero]")
    next_table = rest.index("[[couplings]]", aero_at)
    reordered = first + rest[aero_at:next_table] + "[subsims.orbit]" + rest[:aero_at] + rest[next_table:]
    scenario = Path(tempfile.mkdtemp()) / "case1-aero-first.toml"
    scenario.write_text(reordered)
    runs = {m: cosim.run(scenario, method=m, stop=0.8, inprocess=True) for m in ("distributed", "centralized")}
    assert list(runs["distributed"]) == list(runs["centralized"])
    assert list(runs["distributed"])[0].startswith("aero.") and runs["distributed"].order[0] == "orbit"
