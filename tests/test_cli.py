"""The ``cosim`` command as a user runs it: real processes, exit codes, files, cleanup."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import numpy as np
import pytest
from terminal import as_from_a_terminal

from cosim.results import read_results

ROOT = Path(__file__).parents[1]
OSCILLATOR = ROOT / "scenarios" / "oscillator.toml"
COSIM = [sys.executable, "-m", "cosim.cli"]


TAG = "COSIM_TEST_TAG"


def tagged() -> tuple[bytes, dict[str, str]]:
    """A fresh tag and an environment carrying it: every process the test starts, and their children
    (the launcher passes its environment on), carry it, and no other test's processes do."""
    tag = uuid.uuid4().hex
    return f"{TAG}={tag}".encode(), {**os.environ, TAG: tag}


def serving(tag: bytes) -> list[int]:
    """Pids of live processes (not zombies: their environ reads empty) whose environment holds ``tag``.

    Looks only at this test's processes, orphaned ones included, so suites running side by side do not
    see each other's subsims (a scan of all command lines for "subsims.oscillator" did)."""
    if not Path("/proc/self/environ").exists():
        pytest.skip("needs /proc to find the test's processes")
    pids = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                environ = (entry / "environ").read_bytes()
            except OSError:  # gone meanwhile, or another user's
                continue
            if tag in environ.split(b"\0"):
                pids.append(int(entry.name))
    return pids


def test_serving_sees_only_the_tagged_processes(procs: list) -> None:
    """The finder can fail: it sees a tagged child and its grandchild, and not an untagged sibling."""
    tag, env = tagged()
    code = "import subprocess, sys, time; subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)']); " \
           "time.sleep(60)"
    parent = subprocess.Popen([sys.executable, "-c", code], env=env)
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    procs += [parent, other]
    deadline = time.monotonic() + 30
    while len(serving(tag)) < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    found = serving(tag)
    assert parent.pid in found and other.pid not in found and len(found) == 2
    for pid in found:
        os.kill(pid, signal.SIGKILL)
    parent.wait()
    deadline = time.monotonic() + 30
    while serving(tag) and time.monotonic() < deadline:  # the grandchild is reaped by init
        time.sleep(0.05)
    assert serving(tag) == []


@pytest.mark.zenoh
def test_run_writes_results_and_diagnostics_and_leaves_no_process(tmp_path: Path) -> None:
    out = tmp_path / "osc.csv"
    tag, env = tagged()
    done = subprocess.run([*COSIM, "run", str(OSCILLATOR), "--stop", "0.2", "--output", str(out)],
                          capture_output=True, text=True, timeout=120, env=env)
    assert done.returncode == 0, done.stderr
    cols, data = read_results(out)
    assert cols == ["time", "mass1.u[0]", "mass1.v[0]", "mass2.u[0]", "mass2.v[0]"]
    assert data[0, 0] == 0.0 and data[-1, 0] == pytest.approx(0.2) and data[0, 1] == 1.0
    diag = (tmp_path / "osc.csv.diag.csv").read_text().splitlines()
    assert diag[0] == "interval,t0,t1,stages,largest_residual,wall_time_s,halvings,restarts,length_s,error"
    assert len(diag) == 1 + 4
    assert "order: mass1 -> mass2" in done.stdout and str(out) in done.stdout
    assert "%" not in done.stderr  # no progress display when stderr is not a terminal
    assert serving(tag) == []  # neither the coordinator nor any subsim it started is left


def test_run_says_what_it_cost_in_requests(tmp_path: Path) -> None:
    # the paper's satellite, RF-C: 5 stages an interval; orbit's input at stage 1 (aero's force on the zero first
    # guess) is zero again, so it is not run: 3 + 2 + 3 + 3 + 3 = 14 requests in 5 round trips, 5 per 0.4 s
    satellite = ROOT / "scenarios" / "satellite" / "case1.toml"
    done = subprocess.run([*COSIM, "run", str(satellite), "--stop", "4", "--output", str(tmp_path / "c.csv"),
                           "--inprocess", "--method", "centralized", "--quiet"], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert "10 intervals to t = 4 " in done.stdout and "(10 took 5 stages)" in done.stdout
    cost = "requests: 14.00 an interval, sent in 5.00 round trips (12.5 round trips per simulated second)"
    assert cost + "\n" in done.stdout  # in process: no round trip time (no transport to time)
    # RF-C checks all 18 outputs: aero's force is the last of them to settle
    assert "slowest to converge (failed the check before the last): aero.force in 10 intervals\n" in done.stdout
    remote = subprocess.run([*COSIM, "run", str(ROOT / "scenarios" / "oscillator.toml"), "--stop", "0.5", "--output",
                             str(tmp_path / "o.csv"), "--quiet"], capture_output=True, text=True, timeout=120)
    assert remote.returncode == 0, remote.stderr
    # over the bus, what a round trip took (a lossy link made a run 13x slower with no word of it: multi-host probe)
    took = re.search(r"round trips per simulated second\); a round trip took ([0-9.e+-]+) ms \(median\), "
                     r"([0-9.e+-]+) (ms|s) at most\n", remote.stdout)
    assert took is not None and 0.01 < float(took.group(1)) < 10_000, remote.stdout
    slowest = float(took.group(2)) * (1e3 if took.group(3) == "s" else 1.0)  # (a stalled subsim shows here)
    assert slowest >= float(took.group(1)), remote.stdout
    unified = subprocess.run([*COSIM, "run", str(satellite), "--stop", "4", "--output", str(tmp_path / "u.csv"),
                              "--method", "unified", "--quiet"], capture_output=True, text=True, timeout=120)
    assert unified.returncode == 0 and "requests:" not in unified.stdout  # one program: no requests


def test_npz_output_by_suffix_in_process(tmp_path: Path) -> None:
    out = tmp_path / "osc.npz"
    done = subprocess.run([*COSIM, "run", str(OSCILLATOR), "--stop", "0.1", "--output", str(out), "--inprocess",
                           "--method", "centralized", "--quiet"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    cols, data = read_results(out)
    assert cols[0] == "time" and data.shape == (9, 5) and done.stderr == ""  # 2 intervals x 4 samples + the end


@pytest.mark.zenoh
def test_ctrl_c_keeps_committed_results_and_cleans_up(tmp_path: Path, procs: list) -> None:
    out = tmp_path / "long.csv"
    tag, env = tagged()
    proc = subprocess.Popen([*COSIM, "run", str(OSCILLATOR), "--stop", "1000", "--output", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                            preexec_fn=as_from_a_terminal)
    procs.append(proc)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and (not out.exists() or len(out.read_text().splitlines()) < 50):
        time.sleep(0.1)
    children = [pid for pid in serving(tag) if pid != proc.pid]
    assert len(children) == 2  # mass1 and mass2 (the router runs inside the coordinator)
    rows_seen = len(out.read_text().splitlines()) - 1  # data rows written before the signal (less the header)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130 and "stopped by SIGINT at t = " in err
    _, data = read_results(out)
    assert rows_seen >= 49 and data.shape[0] >= rows_seen and data[-1, 0] < 1000
    deadline = time.monotonic() + 30
    while serving(tag) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert serving(tag) == [] and [p for p in children if _alive(p)] == []


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def test_non_convergence_stops_with_a_named_interval_and_signals(tmp_path: Path) -> None:
    sc = tmp_path / "tight.toml"
    sc.write_text(OSCILLATOR.read_text().replace("max_stages = 50", "max_stages = 2"))
    done = subprocess.run([*COSIM, "run", str(sc), "--inprocess", "--output", str(tmp_path / "x.csv")],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 1
    assert "interval [0.0, 0.05] did not converge in 2 stages" in done.stderr
    assert "mass1.F" in done.stderr and "residual by stage" in done.stderr
    assert "to try: more [coupling] max_stages, or a shorter [coupling] interval" in done.stderr  # (2 stages: no trend)


def test_halving_recovers_an_interval_that_does_not_converge(tmp_path: Path) -> None:
    sc = tmp_path / "halving.toml"
    text = OSCILLATOR.read_text().replace("interval = 0.05 ", "interval = 0.4 ")
    text = text.replace("max_stages = 50", "max_stages = 8")
    sc.write_text(text.replace("[coupling]\n", "[coupling]\nmax_halvings = 4\n"))
    done = subprocess.run([*COSIM, "run", str(sc), "--inprocess", "--quiet", "--stop", "0.8",
                           "--output", str(tmp_path / "h.csv")], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    header, *diag = (tmp_path / "h.csv.diag.csv").read_text().splitlines()
    column = header.split(",").index("halvings")
    assert any(int(row.split(",")[column]) > 0 for row in diag)


def test_bad_scenario_exits_2_naming_the_key(tmp_path: Path) -> None:
    sc = tmp_path / "bad.toml"
    sc.write_text(OSCILLATOR.read_text().replace('to = "mass2.F"', 'to = "mass3.F"'))
    done = subprocess.run([*COSIM, "run", str(sc)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "[couplings[1]]" in done.stderr and "mass3" in done.stderr


def test_describe_prints_order_and_feedback_edges() -> None:
    done = subprocess.run([*COSIM, "describe", str(OSCILLATOR)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert "order (derived): mass1 -> mass2" in done.stdout
    assert "feedback edges (1 scalar signals): mass2.u -> mass1.F" in done.stdout
    assert "mass1.u -> mass2.F via gain (k = 157.91367041742973)" in done.stdout  # the file's gain, as written
    assert "concurrent groups" not in done.stdout  # mass2 reads mass1 in the same stage


def test_describe_tells_an_automatic_interval_from_a_fixed_one() -> None:
    """case1-auto's intervals are sized by the coupler: describe says so, with the controller's bounds, where it
    printed the first interval's 0.4 s as if it were fixed; and the stage limit and speculation of case 1."""
    satellite = Path(__file__).resolve().parents[1] / "scenarios" / "satellite"
    auto = subprocess.run([*COSIM, "describe", str(satellite / "case1-auto.toml")], capture_output=True, text=True,
                          timeout=60)
    assert auto.returncode == 0, auto.stderr
    assert ("distributed: H = auto from 0.4 in [0.4, 25.6], interval_tol 7e-14, grows below 3 stages, 129 samples, "
            "tol 1e-14/1e-10, first guess extrapolate, interp cubic, at most 100 stages\n") in auto.stdout
    fixed = subprocess.run([*COSIM, "describe", str(satellite / "case1.toml")], capture_output=True, text=True,
                           timeout=60)
    assert ("distributed: H = 0.4, 5 samples, tol 1e-14/1e-14, first guess zero, interp linear, at most 100 stages, "
            "speculate\n") in fixed.stdout
    assert "centralized: H = 0.4, 5 samples, tol 1e-12/1e-12, first guess zero, interp linear, at most 100 stages\n" \
        in fixed.stdout  # speculation is the distributed method's only


def test_describe_prints_the_groups_of_subsims_that_run_side_by_side(tmp_path: Path) -> None:
    lines = ['name = "line4"', "stop = 1.0", "[coupling]", 'method = "distributed"', "interval = 0.1"]
    for i in range(4):
        lines += [f"[subsims.m{i}]", 'model = "subsims.oscillator.subsim:Mass"', "params = { m = 1.0, k = 4.0 }"]
    for i in range(4):
        near = ", ".join(f'"m{j}.u"' for j in (i - 1, i + 1) if 0 <= j < 4)
        lines += ["[[couplings]]", f'to = "m{i}.F"', f"from = [{near}]", 'transform = "linear"',
                  f"params = {{ gains = [{', '.join(['1.0'] * (2 if 0 < i < 3 else 1))}] }}"]
    sc = tmp_path / "line4.toml"
    sc.write_text("\n".join(lines) + "\n")
    done = subprocess.run([*COSIM, "describe", str(sc)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert "order (derived): m0 -> m2 -> m1 -> m3" in done.stdout
    assert "run as 2 concurrent groups per stage: {m0, m2} -> {m1, m3}" in done.stdout


@pytest.mark.zenoh
def test_external_subsim_started_by_hand(tmp_path: Path, procs: list) -> None:
    """The coordinator prints the command; a 'user' starts it as a separate process."""
    sc = tmp_path / "ext.toml"
    text = OSCILLATOR.read_text()
    sc.write_text(text.replace('[subsims.mass2]\nmodel = "subsims.oscillator.subsim:Mass"',
                               '[subsims.mass2]\nexternal = true\nmodel = "subsims.oscillator.subsim:Mass"'))
    out = tmp_path / "ext.csv"
    coord = subprocess.Popen([*COSIM, "run", str(sc), "--stop", "0.2", "--output", str(out), "--quiet"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    procs.append(coord)
    command, env = None, {}
    for line in coord.stderr:
        words = line.split()
        if "python" in words and words[0].startswith("COSIM_SECRET="):  # VAR=value ... python -m cosim.serve ...
            at = words.index("python")
            env, command = dict(w.split("=", 1) for w in words[:at]), words[at:]
            break
    assert command is not None and "--connect" in command and "mass2" in command
    assert set(env) == {"COSIM_SECRET", "COSIM_ZENOH_AUTH"}  # the secrets travel in the environment
    user = subprocess.Popen([sys.executable, *command[1:]], stderr=subprocess.DEVNULL, env={**os.environ, **env})
    procs.append(user)
    stdout, _ = coord.communicate(timeout=120)
    assert coord.returncode == 0
    _, data = read_results(out)
    assert data[-1, 0] == pytest.approx(0.2)
    assert user.wait(timeout=15) == 0  # it leaves when the coordinator does


TALKY = '''
import sys
import warnings
import numpy as np
from cosim import Port, Subsim


class Talky(Subsim):
    inputs = {"u": Port(1)}
    outputs = {"x": Port(1)}

    def initial_state(self, params):
        return np.zeros(1)

    def advance(self, state, times, u):
        print(f"advancing to {times[-1]:.2f}")
        print("in", end="")
        print(" parts")
        sys.stdout.buffer.write(b"bytes from " + str(sys.stdout.fileno()).encode() + b"\\n")  # as sys.stdout has them
        for _ in range(20000):  # 20,000 writes without a newline: quadratic once (80 s for this test)
            print(".", end="")
        print()
        print("to its stderr", file=sys.stderr)
        warnings.warn("a model warning")
        return {"x": np.zeros((times.size, 1))}, state
'''


@pytest.mark.zenoh
def test_what_a_model_prints_is_on_stderr_under_its_subsims_name(tmp_path: Path) -> None:
    """A model's print() went, unprefixed, into cosim run's standard output (its summary, which scripts read)."""
    (tmp_path / "talky.py").write_text(TALKY)
    (tmp_path / "s.toml").write_text('stop = 0.2\n[coupling]\ninterval = 0.1\nmethod = "distributed"\n'  # one at a time
                                     '[subsims.a]\nmodel = "talky:Talky"\n'
                                     '[subsims.b]\nmodel = "talky:Talky"\n[[couplings]]\nto = "a.u"\nfrom = "b.x"\n'
                                     '[[couplings]]\nto = "b.u"\nfrom = "a.x"\n')
    done = subprocess.run([*COSIM, "run", "s.toml", "--quiet"], capture_output=True, text=True, timeout=120,
                          cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "advancing" not in done.stdout and "parts" not in done.stdout, done.stdout
    lines = done.stderr.splitlines()
    for name in ("a", "b"):
        assert lines.count(f"{name}: advancing to 0.10") >= 1 and f"{name}: in parts" in lines, done.stderr
        assert f"{name}: bytes from 2" in lines and f"{name}: {'.' * 20000}" in lines, done.stderr
        # its stderr too (a NumPy or a model's warning named no subsim: a five-subsim probe), its own lines once
        assert f"{name}: to its stderr" in lines, done.stderr
        assert any(x.startswith(f"{name}: ") and "UserWarning: a model warning" in x for x in lines), done.stderr
        assert not any(x.startswith(f"{name}: {name}: ") for x in lines), done.stderr


def _run_in_process(tmp_path: Path, scenario: str, stop: str) -> tuple[subprocess.CompletedProcess, list, np.ndarray]:
    """``cosim run`` of the ``scenario`` text in one process to ``stop``: the finished command and its diagnostics."""
    (tmp_path / "s.toml").write_text(scenario)
    out = tmp_path / "s.csv"
    done = subprocess.run([*COSIM, "run", str(tmp_path / "s.toml"), "--inprocess", "--quiet", "--stop", stop,
                           "--output", str(out)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    cols, diag = read_results(Path(str(out) + ".diag.csv"))
    return done, cols, diag


def test_the_summary_counts_the_rejected_tries_and_the_intervals_over_interval_tol(tmp_path: Path) -> None:
    """An automatic run on a coupling too stiff for its first intervals: its tries rolled back and those accepted
    above interval_tol at interval_min were in the diagnostics only; the summary says how many (the same counts)."""
    text = OSCILLATOR.read_text()
    text = text.replace("interval = 0.05          # H, seconds", 'interval = "auto"').replace("max_stages = 50", "")
    text = text.replace("k = 197.39208802178717", "k = 39517.89602196179")  # k1 + k12, k12 = 4000 pi^2
    text = text.replace("k = 157.91367041742973", "k = 39478.41760435743")
    done, cols, diag = _run_in_process(tmp_path, text, "0.2")
    rejected = int(diag[:, cols.index("halvings")].sum())
    over = int((diag[:, cols.index("error")] > 1.0).sum())
    found = re.search(r"^rejected: (\d+) tries, retried shorter \((\d+) not converged, (\d+) over interval_tol\), "
                      r"(\d+) stages run in them$", done.stdout, re.M)
    assert found, done.stdout
    tries, unconverged, over_tol, stages = map(int, found.groups())
    assert tries == rejected > 0 and unconverged + over_tol == tries and unconverged >= 1  # 0.1 s diverges
    assert stages >= 2 * tries  # every try ran a check: two stages at least
    assert f"over interval_tol: {over} intervals, accepted at interval_min" in done.stdout and over > 0


def test_both_ends_print_the_package_and_protocol_versions_and_the_package_version_is_pyprojects() -> None:
    """Every tree printed 'cosim 0.1.0', so an operator comparing two machines learned nothing of the protocol."""
    import tomllib

    from cosim.contract import PROTOCOL_VERSION

    version = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    for cmd in ([*COSIM, "--version"], [sys.executable, "-m", "cosim.serve", "--version"],
                [sys.executable, "-m", "subsims.oscillator", "--version"]):
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
        assert (done.returncode, done.stdout.strip()) == (0, f"cosim {version} (protocol {PROTOCOL_VERSION})"), cmd


def test_a_stopped_runs_note_names_where_its_intervals_are(tmp_path: Path) -> None:
    """'every interval to t = 93.2 s is in small/x.npz' named a file a full disk had kept from being built (the samples
    were in x.npz.partial), and after the results file was removed during a run the note sent the user to --resume,
    which then failed (durability probe)."""
    from cosim.cli import _kept
    from cosim.outputs import stream_path

    csv, npz = tmp_path / "a.csv", tmp_path / "b.npz"
    assert _kept(csv) is None and _kept(npz) is None  # nothing there: nothing to go on from
    csv.write_text("time,x\n")
    stream_path(npz).write_bytes(b"samples")
    assert _kept(csv) == str(csv)
    assert _kept(npz) == f"{stream_path(npz)} (`cosim recover {npz}` builds the NPZ from it)"
    npz.write_bytes(b"built")
    assert _kept(npz) == str(npz)


def test_the_rejected_tries_of_fixed_intervals_are_said_as_halvings(tmp_path: Path) -> None:
    """With max_halvings (fixed intervals) the line read '(5 not converged, 0 over interval_tol)': no interval_tol
    there (red team)."""
    text = OSCILLATOR.read_text().replace("interval = 0.05          # H, seconds", "interval = 0.8\nmax_halvings = 6")
    done, cols, diag = _run_in_process(tmp_path, text, "0.8")
    halvings = int(diag[:, cols.index("halvings")].sum())
    assert halvings > 0
    assert re.search(rf"^rejected: {halvings} tries, retried shorter \(not converged: max_halvings\), \d+ stages run "
                     "in them$", done.stdout, re.M), done.stdout
    assert "interval_tol" not in done.stdout


def test_round_trip_times_read_as_an_operator_writes_them() -> None:
    """Two significant digits, never in exponent form: '2.3e+02 ms' (a newcomer probe), '1e+02 ms' (a red team)."""
    from cosim.cli import _duration

    got = [_duration(x) for x in (0.00052, 0.0012, 0.0996, 0.23, 9.1, 99.7, None)]
    assert got == ["0.52 ms", "1.2 ms", "100 ms", "230 ms", "9.1 s", "100 s", "?"]
