"""Subsim processes: death is reported quickly, and every exit path really exits."""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from cosim.contract import SubsimDied, SubsimError
from cosim.launch import Bus, subsim_command, terminate

TIMES = np.linspace(0.0, 0.4, 5)


pytestmark = pytest.mark.zenoh


def test_kill_9_mid_run_is_reported_within_one_second(cosim_bus: Bus) -> None:
    proc = cosim_bus.spawn("subsims.integrator", "victim")
    proc.handle.configure({"compute_delay": 30.0})
    pending = proc.handle.start_run_interval(TIMES, {"u": np.zeros((5, 1))})
    time.sleep(0.3)
    os.kill(proc.popen.pid, signal.SIGKILL)
    killed = time.monotonic()
    with pytest.raises(SubsimDied) as err:
        pending()
    assert time.monotonic() - killed < 1.0
    assert err.value.subsim == "victim" and err.value.command == "run_interval"
    assert str(err.value).endswith("the process died during the request: its process was killed by SIGKILL"), err.value
    with pytest.raises(SubsimDied):  # later calls fail at once too
        proc.handle.status()


@pytest.mark.parametrize("how", ["shutdown", "SIGTERM", "SIGINT"])
def test_subsim_exits_with_code_0(cosim_bus: Bus, how: str) -> None:
    proc = cosim_bus.spawn("subsims.integrator", f"quitter-{how}")
    if how == "shutdown":
        proc.handle.shutdown()
    else:
        proc.popen.send_signal(getattr(signal, how))
    assert proc.popen.wait(10) == 0


# A subsim whose router-watch thread is about to start (its liveliness token already out: ready to be seen and
# signalled) gets SIGINT at that very moment.
SIGNALLED_WHILE_STARTING = """
import os, signal, sys, threading
start = threading.Thread.start
def signalled_start(self):
    if self.name == "router-watch":
        os.kill(os.getpid(), signal.SIGINT)
    return start(self)
threading.Thread.start = signalled_start
from cosim.process import main
from subsims.integrator.subsim import Integrator
raise SystemExit(main(Integrator, sys.argv[1:]))
"""


def test_a_signal_before_serving_starts_still_exits_with_code_0(cosim_bus: Bus, procs: list) -> None:
    """Startup has no window where a stop signal gives a traceback and exit code 1 (seen once in CI)."""
    popen = subprocess.Popen([sys.executable, "-c", SIGNALLED_WHILE_STARTING, "--connect", cosim_bus.endpoint,
                              "--run", cosim_bus.run, "--name", "early"],
                             env={**os.environ, **cosim_bus.subsim_env("early")}, stderr=subprocess.PIPE, text=True)
    procs.append(popen)
    _, err = popen.communicate(timeout=20)
    assert popen.returncode == 0, err
    assert "Traceback" not in err and "early: stopping on SIGINT" in err


def test_subsim_exits_when_the_coordinator_goes_away() -> None:
    bus = Bus.open()
    popen = subprocess.Popen(subsim_command("subsims.integrator", bus.endpoint, bus.run, "orphan"),
                             env={**os.environ, **bus.subsim_env("orphan")}, stderr=subprocess.PIPE, text=True)
    try:
        bus.attach("orphan")
        bus.session.close()  # its router gone without a shutdown (as when it is killed): code 3, for a supervisor
        assert popen.wait(10) == 3
        err = popen.stderr.read()  # it says why it stops: it was 'stopping on SIGTERM', a signal it sent itself
        assert "orphan: stopping as the coordinator" in err and "SIGTERM" not in err, err
    finally:
        if popen.poll() is None:
            popen.kill()
            popen.wait()


def _unused_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize(("host", "says"), [
    ("127.0.0.1", "(connection refused): is the coordinator running, and is this the address and port it printed?"),
    ("no-such-host.invalid", "cannot resolve 'no-such-host.invalid'"),
])
def test_unreachable_endpoint_exits_with_a_clear_message_at_once(host: str, says: str) -> None:
    """A closed port or a name that does not resolve is said at once, not after --connect-timeout as one line for
    every cause."""
    port = _unused_port()
    cmd = subsim_command("subsims.integrator", f"tcp/{host}:{port}", "run-x", "lonely")
    env = {**os.environ, "COSIM_SECRET": "00" * 32, "COSIM_ZENOH_AUTH": "site:pw"}
    started = time.monotonic()
    done = subprocess.run([*cmd, "--connect-timeout", "20"], capture_output=True, text=True, timeout=30, env=env)
    assert done.returncode == 2 and time.monotonic() - started < 10
    assert f"lonely: cannot reach the coordinator at tcp/{host}:{port}: " in done.stderr and says in done.stderr


def test_a_private_bus_that_is_gone_is_said_at_once(tmp_path: Path) -> None:
    """A subsim started as its coordinator was killed (the Unix socket of its private bus gone, or left with no one
    listening) tried for 10 s and then blamed its login or TLS (ops probe)."""
    stale = tmp_path / "router.sock"
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.bind(str(stale))  # a socket file no one listens on any more
    env = {**os.environ, "COSIM_SECRET": "00" * 32, "COSIM_ZENOH_AUTH": "site:pw"}
    for path in (tmp_path / "gone.sock", stale):
        endpoint = f"unixsock-stream/{path}"
        started = time.monotonic()
        done = subprocess.run([*subsim_command("subsims.integrator", endpoint, "run-x", "late"), "--connect-timeout",
                               "20"], capture_output=True, text=True, timeout=30, env=env)
        assert done.returncode == 2 and time.monotonic() - started < 10
        assert done.stderr.strip() == (f"late: cannot reach the coordinator at {endpoint}: nothing listens on {path} "
                                       "(its coordinator has ended?)"), done.stderr


def test_a_login_made_for_another_run_or_name_is_refused_at_start() -> None:
    """--run or --name mistyped: the login still connects, then the router refuses its keys in silence and the
    process waited forever; it now says so and exits."""
    bus = Bus.open(names=["a", "b"])
    try:
        cmd = subsim_command("subsims.integrator", bus.endpoint, bus.run, "b")  # given a's login
        env = {**os.environ, **bus.subsim_env("a")}
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=30, env=env)
        assert done.returncode == 2
        assert f"is the login 'cosim-{bus.run}.a', made for another run or subsim than --run {bus.run} --name b" \
            in done.stderr, done.stderr
    finally:
        bus.close()


@pytest.mark.slow
def test_a_subsim_with_another_runs_key_is_given_up_on_early_and_says_so_itself() -> None:
    """Started with the right login but another run's COSIM_SECRET: it connects and drops every request. The
    coordinator gave up only at the end of the attach wait (300 s by default); now after 15 s of silence, and
    the subsim says on its own terminal why nothing reaches it."""
    from cosim.protocol.transport.client import SILENT_LIMIT

    with Bus.open(names=["keyless"]) as bus:
        env = {**os.environ, **bus.subsim_env("keyless"), "COSIM_SECRET": "ab" * 32}
        proc = subprocess.Popen(subsim_command("subsims.integrator", bus.endpoint, bus.run, "keyless"), env=env,
                                stderr=subprocess.PIPE, text=True)
        try:
            started = time.monotonic()
            with pytest.raises(SubsimError, match=r"has not answered in 1\d s: is it running with this run's "
                                                  "COSIM_SECRET"):
                bus.attach("keyless", wait=120)
            assert time.monotonic() - started < SILENT_LIMIT + 10
        finally:
            terminate(proc)
        err = proc.stderr.read()
        assert "requests arrive, but none is sealed with our key: is COSIM_SECRET the one the coordinator printed" \
            in err, err


def test_bad_command_line_is_rejected() -> None:
    cmd = [sys.executable, "-m", "subsims.integrator", "--connect", "tcp/127.0.0.1:1", "--run", "a/b*"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=30)
    assert done.returncode == 2 and "--run" in done.stderr


RAISING = """
import numpy as np
from cosim import Subsim


class Raising(Subsim):
    inputs = {"u": 1}
    outputs = {"y": 1}

    def initial_state(self, params):
        return np.zeros(1)

    def advance(self, state, times, u):
        return 1 / 0
"""


def test_a_subsim_started_by_hand_shows_its_models_errors_on_its_own_terminal(tmp_path) -> None:
    """An external subsim's owner watches its terminal: the model's error showed only in the coordinator's."""
    (tmp_path / "raising.py").write_text(RAISING)
    bus = Bus.open()
    popen = subprocess.Popen(subsim_command("", bus.endpoint, bus.run, "boom", model="raising:Raising"),
                             env={**os.environ, **bus.subsim_env("boom"), "PYTHONPATH": str(tmp_path)},
                             stderr=subprocess.PIPE, text=True)
    try:
        handle = bus.attach("boom")
        handle.configure({})
        with pytest.raises(SubsimError) as err:
            handle.run_interval(TIMES, {"u": np.zeros((5, 1))})
        assert err.value.code == "model_exception"
        with pytest.raises(SubsimError):  # the caller's mistake is the caller's to see: not printed there
            handle.run_interval(TIMES, {"u": np.zeros((4, 1))})
        bus.close()
        assert popen.wait(10) == 0
        err_text = popen.stderr.read()
    finally:
        if popen.poll() is None:
            popen.kill()
            popen.wait()
        bus.close()
    assert "boom: run_interval failed: [model_exception] advance() raised ZeroDivisionError: division by zero" \
        in err_text, err_text
    assert 'raising.py", line 14, in advance' in err_text and "bad_value" not in err_text, err_text


def test_a_second_process_for_a_name_the_bus_serves_is_refused(cosim_bus: Bus) -> None:
    first = cosim_bus.spawn("subsims.integrator", "twice")
    with pytest.raises(ValueError, match=rf"'twice' is served by process {first.popen.pid} of this bus already"):
        cosim_bus.spawn("subsims.integrator", "twice")
    assert first.handle.status()["configured"] is False and len(cosim_bus.processes) == 1


def test_spawn_subsim_names_a_target_it_cannot_import(spawn_subsim) -> None:
    with pytest.raises(ValueError, match=r"spawn_subsim\('no_such_module:Thing'\): model 'no_such_module:Thing' "
                                         r"not found \(No module named 'no_such_module'\)"):
        spawn_subsim("no_such_module:Thing")
    with pytest.raises(ValueError, match=r"spawn_subsim\('subsims.no_such'\): no module named 'subsims.no_such'"):
        spawn_subsim("subsims.no_such")


def test_a_second_copy_started_by_hand_is_named_not_taken_for_the_first(cosim_bus: Bus, tmp_path: Path) -> None:
    """An external subsim started twice with the same command: both hold its key, both answer. The run stopped at
    once with 'not_configured' from the copy (the operator's restart after a blip); the coordinator now believes
    only the process that first answered and names the other."""
    first = cosim_bus.spawn("subsims.integrator", "twin")
    first.handle.configure({})
    stderr = tmp_path / "copy.err"
    with stderr.open("w") as sink:
        copy = subprocess.Popen(subsim_command("subsims.integrator", cosim_bus.endpoint, cosim_bus.run, "twin"),
                                env={**os.environ, **cosim_bus.subsim_env("twin")}, stderr=sink)
    try:
        t = np.array([0.0, 0.5])
        deadline = time.monotonic() + 60  # the copy starts meanwhile (seconds on a loaded machine)
        with pytest.raises(SubsimError) as err:
            while time.monotonic() < deadline:  # until the copy's reply comes first
                first.handle.run_interval(t, {"u": np.ones((2, 1))})
        assert err.value.code == "duplicate" and "a second process answers as 'twin'" in str(err.value)
        # the ids it names are those the two processes said as they started (a multi-host probe: which to stop?)
        copy_said = stderr.read_text()
        assert f"twin: serving run {cosim_bus.run} via " in copy_said, copy_said
        named = re.findall(r"Zenoh id ([0-9a-f]+)", str(err.value))
        assert len(named) == 2 and f"as Zenoh id {named[0]} (pid {copy.pid})" in copy_said, (named, copy_said)
    finally:
        terminate(copy)


def test_a_replaced_process_that_comes_back_stays_deaf(cosim_bus: Bus) -> None:
    """A subsim started through a launcher that cannot kill it (ssh: killing ssh leaves the remote process) hangs,
    is replaced, then runs again. Each replacement gets a key of its own, so the old process can neither read the
    new one's requests nor answer them: the run goes on with the replacement (the old one answering with its key
    would have been a second server: 'duplicate', or worse, its stale state believed)."""
    from cosim.launch import Elsewhere

    forking = Elsewhere(("sh", "-c", 'sh -c "$1"; :', "launcher"), python=sys.executable,  # the subsim in a child
                        connect=cosim_bus.endpoint)
    proc = cosim_bus.spawn("subsims.integrator", "phoenix", elsewhere=forking)
    old = proc.handle.status()["pid"]
    assert old != proc.popen.pid  # not the launcher's own process: killing that leaves it
    try:
        os.kill(old, signal.SIGSTOP)
        new = cosim_bus.respawn("phoenix")
        assert os.path.exists(f"/proc/{old}")  # the launcher was killed, the old subsim was not
        os.kill(old, signal.SIGCONT)
        new.handle.configure({})
        t = np.array([0.0, 0.5])
        for _ in range(200):  # the old process is connected again and sees every query on the key
            assert new.handle.run_interval(t, {"u": np.ones((2, 1))}).end_time == 0.5
        assert new.handle.status()["pid"] not in (old, new.popen.pid)
    finally:
        try:
            os.kill(old, signal.SIGKILL)
        except ProcessLookupError:  # it left by itself: stopped past its lease on a loaded machine, it found its
            pass  # router gone when it ran again


def test_a_tls_file_that_is_not_there_is_named_at_start(tmp_path: Path) -> None:
    """--tls-ca pointing at nothing (a relative path from another directory): Zenoh only said after 10 s that it
    could not connect, 'or its login/TLS refused ours'."""
    cmd = subsim_command("subsims.integrator", "tls/127.0.0.1:7447", "run-x", "lonely",
                         tls_ca=Path("certs/ca.pem"))
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=30, cwd=tmp_path,
                          env={**os.environ, "COSIM_SECRET": "00" * 32, "COSIM_ZENOH_AUTH": "site:pw"})
    assert done.returncode == 2 and f"--tls-ca certs/ca.pem: no such file (in {tmp_path})" in done.stderr
    # that line alone, not after argparse's usage text (a multi-host probe: 15 lines above the one that matters)
    assert done.stderr.count("\n") == 1 and done.stderr.startswith("python -m subsims.integrator: error: "), done.stderr


def test_a_subsim_without_its_login_is_refused_at_once_naming_the_variable(tmp_path: Path) -> None:
    """Started with COSIM_SECRET but without COSIM_ZENOH_AUTH (the second of the two printed variables): every run's
    router asks for a login, and the link was refused after --connect-timeout as 'login/TLS refused' (a multi-host
    probe)."""
    cmd = subsim_command("subsims.integrator", "tcp/127.0.0.1:9", "run-x", "lonely")
    env = {k: v for k, v in os.environ.items() if k != "COSIM_ZENOH_AUTH"}
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=30, env={**env, "COSIM_SECRET": "00" * 32})
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert "COSIM_ZENOH_AUTH is not set: start the subsim with the two variables cosim printed for it" in done.stderr


def test_a_death_is_put_down_to_a_pause_of_the_coordinator_only_when_that_explains_it(
        cosim_bus: Bus, monkeypatch: pytest.MonkeyPatch) -> None:
    """A subsim that exits by itself after this coordinator was stopped longer than its lease left because of it
    (replaced with the others that left, for one restart). Not one started after the pause began, not one killed by
    a signal, not after the pause is long past: for two minutes after a pause every death was 'left' and free, and
    --restarts no longer bounded anything (red team)."""
    from collections import deque

    from cosim.contract import SubsimLeft
    from cosim.protocol.transport import client

    handle = cosim_bus.spawn("subsims.integrator", "paused").handle
    now = time.monotonic()

    def kind(born: float, status: str, pause: tuple[float, float] = (now - 14.0, now - 1.0)) -> type:
        monkeypatch.setattr(client._WATCHDOG, "_pauses", deque([pause]))
        handle._born, handle.exit_status = born, lambda: status
        return type(handle._died_error("the process died during the request", "run_interval"))

    exited = "its process exited with code 0"
    assert kind(now - 20.0, exited) is SubsimLeft
    assert kind(now - 20.0, "its process was killed by SIGKILL") is SubsimDied
    assert kind(now - 5.0, exited) is SubsimDied  # its process was started after the pause began
    assert kind(now - 100.0, exited, (now - 60.0, now - 45.0)) is SubsimDied  # a pause that ended 45 s ago
    assert kind(now - 100.0, exited, (now - 6.0, now - 1.0)) is SubsimDied  # shorter than its lease


def test_a_model_that_fails_to_start_is_named_with_the_last_line_its_process_wrote(
        spawn_subsim, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A model whose __init__ raises: the error said only 'its process exited with code 1', the reason was left in
    the test's captured stderr (test-author probe)."""
    (tmp_path / "bad_init.py").write_text(
        "from cosim import Port, Subsim\n\n\nclass Bad(Subsim):\n    outputs = {'y': Port(1)}\n\n"
        "    def __init__(self):\n        raise RuntimeError('calibration file /data/cal.csv not found')\n")
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SubsimError) as err:
        spawn_subsim("bad_init:Bad", name="bad")
    assert str(err.value) == ("bad.spawn: [no_responder] its process exited with code 1; the last line it wrote: "
                              "bad: cannot start: Bad() raised RuntimeError: calibration file /data/cal.csv not found "
                              "(bad_init.py:8 in __init__)")  # (its one line, not a traceback's last: newcomer probe)


def test_a_subsim_that_timed_out_is_killed_at_once_when_stopped(cosim_bus: Bus) -> None:
    """Zenoh's own timeout (no deadline set) is a hang as a missed deadline is: stopping the process must not ask
    it to shut down and wait out two graces (6 s per hung subsim at a test's teardown)."""
    proc = cosim_bus.spawn("subsims.integrator", "stuck", timeout=1.0)
    proc.handle.configure({"compute_delay": 30.0})
    with pytest.raises(SubsimError) as err:
        proc.handle.run_interval(TIMES, {"u": np.zeros((5, 1))})
    assert err.value.code == "timeout" and str(err.value).endswith("no reply within 1 s (hung or stopped?)")
    assert proc.handle.hung
    assert proc.stop() == -signal.SIGKILL


def test_a_stopped_subsim_is_killed_at_once_and_the_bus_stops_its_processes_side_by_side(
        cosim_bus: Bus, monkeypatch: pytest.MonkeyPatch) -> None:
    """A subsim stopped with SIGSTOP (not known to be hung: no request missed a deadline) was asked to shut down, then
    sent SIGTERM, each with its grace: Ctrl-C took 8-9 s, 15 s with two (a red team). It is killed at once, and a
    bus stops its processes side by side."""
    import os
    import threading

    from cosim.launch import SubsimProcess, _stopped

    proc = cosim_bus.spawn("subsims.integrator", "frozen", timeout=5.0)
    asked: list[str] = []
    monkeypatch.setattr(proc.handle, "shutdown", lambda: asked.append("shutdown"))
    os.kill(proc.popen.pid, signal.SIGSTOP)
    deadline = time.monotonic() + 5.0
    while not _stopped(proc.popen.pid) and time.monotonic() < deadline:
        time.sleep(0.01)
    assert _stopped(proc.popen.pid)
    assert proc.stop() == -signal.SIGKILL and asked == []  # not asked: it could not answer
    assert not _stopped(os.getpid())
    # two processes slow to stop: the second is asked before the first is done
    events: list[tuple[str, str]] = []
    lock = threading.Lock()

    def slow(self: SubsimProcess, grace: float = 3.0) -> int:
        with lock:
            events.append(("start", self.name))
        time.sleep(0.5)
        with lock:
            events.append(("end", self.name))
        return 0

    for name in ("a", "b"):
        cosim_bus.spawn("subsims.integrator", name, timeout=5.0)
    spawned = list(cosim_bus.processes)
    monkeypatch.setattr(SubsimProcess, "stop", slow)
    cosim_bus.close()
    assert [e[0] for e in events][:2] == ["start", "start"], events
    for p in spawned:  # (the stand-in stopped none of them)
        p.popen.kill()
        p.popen.wait()
        p.handle.close()


def test_the_installed_eclipse_zenoh_is_read_as_pip_records_it() -> None:
    import importlib.metadata

    from cosim.protocol.transport.session import installed_zenoh

    assert installed_zenoh() == importlib.metadata.version("eclipse-zenoh")


@pytest.mark.parametrize(("installed", "refused"), [("1.0.4", True), ("1.9.9", True), ("2.0.0", True),
                                                    ("1.10.0", False), ("1.10.2", False), ("1.12.0rc1", False)])
def test_an_eclipse_zenoh_this_transport_is_not_written_for_is_named_in_one_line(
        monkeypatch: pytest.MonkeyPatch, installed: str, refused: bool) -> None:
    """A subsim on a machine with eclipse-zenoh 1.0.4 said 'serving run', then printed 1,372 TypeError tracebacks in
    15 s, and the coordinator asked whether it had this run's COSIM_SECRET (version-skew probe)."""
    from cosim.protocol.transport import session

    monkeypatch.setattr(session, "installed_zenoh", lambda: installed)
    said = session.zenoh_mismatch()
    assert (said is not None) == refused
    if refused:
        assert said == (f"cosim needs eclipse-zenoh >= 1.10, < 2 and this Python has {installed}: "
                        "pip install 'eclipse-zenoh>=1.10,<2'")


def test_a_subsim_process_on_an_old_eclipse_zenoh_exits_with_that_line_before_serving() -> None:
    older = ("import sys, cosim.protocol.transport.session as s; s.installed_zenoh = lambda: '1.0.4'\n"
             "from cosim.serve import main; sys.exit(main(sys.argv[1:]))\n")
    done = subprocess.run([sys.executable, "-c", older, "subsims.oscillator.subsim:Mass", "--connect",
                           "tcp/127.0.0.1:9", "--run", "r1", "--name", "m"], capture_output=True, text=True, timeout=60,
                          env={**os.environ, "COSIM_SECRET": "00" * 32, "COSIM_ZENOH_AUTH": "site:pw"})
    assert done.returncode == 2
    assert done.stderr == "m: cosim needs eclipse-zenoh >= 1.10, < 2 and this Python has 1.0.4: pip install " \
                          "'eclipse-zenoh>=1.10,<2'\n", done.stderr


def _children_named(name: str) -> list[int]:
    """This process's child processes (running or not yet reaped) whose command line names ``name``."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            cmdline = (entry / "cmdline").read_bytes().split(b"\0")
        except (OSError, ValueError, IndexError):
            continue
        if ppid == os.getpid() and name.encode() in cmdline:
            found.append(int(entry.name))
    return found


def test_a_ctrl_c_while_a_subsim_starts_leaves_no_process_behind(monkeypatch: pytest.MonkeyPatch) -> None:
    """A Ctrl-C between starting a subsim's process and the bus keeping it (an API probe: the process went on
    running, then stayed a zombie); spawning on a closed bus started a process too, then failed."""
    with Bus.open() as bus:
        def interrupted(self: Bus, name: str, timeout: float) -> None:
            raise KeyboardInterrupt

        monkeypatch.setattr(Bus, "_remote_handle", interrupted)
        with pytest.raises(KeyboardInterrupt):
            bus.spawn("subsims.integrator", "window-probe", quiet=True)
        assert _children_named("window-probe") == []
        monkeypatch.undo()
    with pytest.raises(RuntimeError, match="cannot start subsim 'closed-probe': this bus is closed"):
        bus.spawn("subsims.integrator", "closed-probe", quiet=True)
    assert _children_named("closed-probe") == []


def test_a_handle_used_after_its_bus_closed_says_so_and_a_coordinator_checks_its_arguments() -> None:
    """A library user's mistakes (an API probe): the closed bus was reported as 'the subsim process is gone: its
    process exited with code 0', and settings given as a dict failed inside with "'dict' object has no attribute
    'method'"."""
    from cosim.coupler.relaxation import Settings
    from cosim.driver import Coordinator

    with Bus.open() as bus:
        handle = bus.spawn("subsims.integrator", "after-close", quiet=True).handle
    with pytest.raises(SubsimError) as err:
        handle.status()
    assert str(err.value) == ("after-close.status: [no_responder] its bus is closed (the coordinator's session, and "
                              "the processes it started): open another and spawn or attach the subsim again")
    with pytest.raises(TypeError, match=r"settings must be a cosim.coupler.relaxation.Settings \(Settings\(\*\*table\) "
                                        r"of a dict\), got dict"):
        Coordinator({"a": handle}, [], {"interval": 0.05})  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="couplings must be a Plan or a list of Coupling .*, got str"):
        Coordinator({"a": handle}, ["a.u <- a.y"], Settings())  # type: ignore[list-item]
