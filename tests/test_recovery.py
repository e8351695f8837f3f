"""A subsim that dies or hangs is replaced, restored and replayed: the run's results are bit-identical.

Real processes on loopback. Three integrators in a ring (a <- c, b <- a, c <- b), coupled by RF-C and
RF-D; SIGKILL (or SIGSTOP) of one process at chosen moments: between stages, right after an interval
converged (its commit rides on the next request), while a request is in flight, and during the
final commit. Every committed interval and every final state must equal the undisturbed run's, bit
for bit.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from cosim.contract import SubsimDied, SubsimError, SubsimHung
from cosim.coupler.convergence import Tolerance
from cosim.coupler.couplings import Coupling
from cosim.coupler.relaxation import Interval, Settings
from cosim.driver import Coordinator, Deadline, Recovery
from cosim.launch import Bus
from cosim.results import read_results
from cosim.runner import run_scenario
from cosim.scenario import load

OSCILLATOR = Path(__file__).parents[1] / "scenarios" / "oscillator.toml"
RING = [Coupling.make("a.u", "c.y", "gain", {"k": -0.8}), Coupling.make("b.u", "a.y"), Coupling.make("c.u", "b.y")]
PARAMS = {"a": {"y0": [1.0]}, "b": {"y0": [0.5]}, "c": {"y0": [-0.25]}}
H, INTERVALS = 0.1, 8


def settings(method: str) -> Settings:
    return Settings(method=method, interval=H, samples=4, first_guess="extrapolate", interp="cubic",
                    tol=Tolerance(1e-12, 1e-14), order=("a", "b", "c"))


class Ring:
    """The three processes on one bus, and a coordinator that can replace them."""

    def __init__(
        self, bus: Bus, method: str, delay: float = 0.0, restarts: int = 2, params: dict | None = None
    ) -> None:
        self.bus, self.delay, self.params = bus, delay, {**PARAMS, **(params or {})}
        self.handles = {name: self.start(name) for name in PARAMS}
        self.log: list[str] = []
        recovery = Recovery(self.revive, restarts=restarts, checkpoint_every=3, log=self.log.append)
        self.coordinator = Coordinator(self.handles, RING, settings(method), recovery=recovery,
                                       deadline=Deadline(floor=1.5, initial=5.0))
        self.intervals: list[Interval] = []

    def configure(self, handle, name: str):
        handle.configure({"compute_delay": self.delay, **self.params[name]})
        return handle

    def start(self, name: str):
        return self.configure(self.bus.spawn("subsims.integrator", name, quiet=True).handle, name)

    def revive(self, name: str, why: str):
        return self.configure(self.bus.respawn(name, quiet=True).handle, name)

    def pid(self, name: str) -> int:
        return next(p.popen.pid for p in self.bus.processes if p.name == name)

    def run(self) -> list[bytes]:
        self.coordinator.run(0.0, H * INTERVALS, self.intervals.append)
        return self.fingerprint()

    def fingerprint(self) -> list[bytes]:
        rows = [iv.t.tobytes() + b"".join(iv.outputs[n]["y"].tobytes() for n in sorted(iv.outputs))
                for iv in self.intervals]
        states = [self.coordinator.handles[n].get_state() for n in sorted(PARAMS)]
        return rows + [np.float64(s.time).tobytes() + s.state.tobytes() for s in states]


@pytest.fixture(scope="module")
def undisturbed() -> dict[str, list[bytes]]:
    out = {}
    for method in ("centralized", "distributed"):
        with Bus.open() as bus:
            out[method] = Ring(bus, method).run()
    return out


def kill(pid: int, sig: int = signal.SIGKILL) -> None:
    os.kill(pid, sig)


# (method, victim, moment, which occurrence): 26 kill points
POINTS = [
    (method, victim, moment, k)
    for method in ("centralized", "distributed")
    for victim, moment, k in [
        ("a", "stage", 1), ("b", "stage", 4), ("c", "stage", 9),
        ("a", "commit", 0), ("b", "commit", 3), ("c", "commit", 6),
        ("b", "in-flight", 2), ("c", "in-flight", 5), ("a", "in-flight", 7),
        ("a", "stage", 0), ("c", "commit", 2), ("b", "final", 0),
    ]
] + [  # killed in the last stage of the third interval (a checkpoint's), its death known before the commit is sent
    ("centralized", "c", "noticed", 23), ("distributed", "c", "noticed", 9),  # stages 10, 7, 7 and 4, 3, 3
]


@pytest.mark.slow
@pytest.mark.parametrize(("method", "victim", "moment", "k"), POINTS)
def test_a_killed_subsim_is_replaced_and_the_results_are_bit_identical(
    undisturbed: dict, method: str, victim: str, moment: str, k: int
) -> None:
    with Bus.open() as bus:
        ring = Ring(bus, method, delay=0.02 if moment == "in-flight" else 0.0)
        seen = {"stage": 0, "commit": 0, "in-flight": 0}

        def on_stage(stage: int, outputs: dict) -> None:
            n = seen["stage"]
            seen["stage"] += 1
            if moment in ("stage", "noticed") and n == k:
                kill(ring.pid(victim))
            if moment == "noticed" and n == k:  # the coordinator learns of it before it sends anything more
                deadline = time.monotonic() + 10
                while ring.coordinator.handles[victim].alive and time.monotonic() < deadline:
                    time.sleep(0.005)
            if moment == "in-flight" and n == k:  # the next request is being computed 10 ms from now
                threading.Timer(0.01, kill, (ring.pid(victim),)).start()

        ring.coordinator.on_stage = on_stage
        intervals = ring.intervals

        def on_interval(iv: Interval) -> None:
            intervals.append(iv)
            if moment == "commit" and len(intervals) - 1 == k:
                kill(ring.pid(victim))
            if moment == "final" and len(intervals) == INTERVALS:
                kill(ring.pid(victim))

        ring.coordinator.run(0.0, H * INTERVALS, on_interval)
        died = [r for r in ring.coordinator.restarts if r.reason.startswith("died")]
        assert [r.subsim for r in died] == [victim], ring.log
        assert ring.fingerprint() == undisturbed[method]


@pytest.mark.slow
def test_a_stopped_subsim_is_found_by_its_deadline_and_replaced(undisturbed: dict) -> None:
    with Bus.open() as bus:
        ring = Ring(bus, "centralized", restarts=3)
        stopped: list[int] = []
        found: list[float] = []

        def on_stage(stage: int, outputs: dict) -> None:
            if not stopped and len(ring.intervals) == 4:
                stopped.append(ring.pid("b"))
                found.append(time.monotonic())
                kill(stopped[0], signal.SIGSTOP)

        ring.coordinator.on_stage = on_stage
        try:
            assert ring.run() == undisturbed["centralized"]
        finally:
            for pid in stopped:  # respawn killed it; make sure
                try:
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
        # b was replaced as hung (on a loaded machine another subsim may also have missed the 1.5 s deadline once:
        # that costs a replacement, never a different result)
        hung_b = [r for r in ring.coordinator.restarts if r.subsim == "b" and r.reason.startswith("hung")]
        assert len(hung_b) == 1, ring.log


def kill_on_call(ring: Ring, victim: str, method: str, occurrence: int) -> None:
    """Kill ``victim`` when its handle's ``method`` is called the ``occurrence``-th time (from 0), and wait until the
    coordinator knows it is gone, then let the call go on: the call meets a dead process."""
    handle = ring.handles[victim]
    original, calls = getattr(handle, method), [0]

    def call(*args, **kwargs):
        calls[0] += 1
        if calls[0] - 1 == occurrence:
            kill(ring.pid(victim))
            deadline = time.monotonic() + 10
            while handle.alive and time.monotonic() < deadline:
                time.sleep(0.005)
        return original(*args, **kwargs)

    setattr(handle, method, call)


@pytest.mark.slow
@pytest.mark.parametrize("occurrence", [0, 1])  # the checkpoint before the first interval, the first periodic one
def test_a_subsim_killed_at_a_checkpoint_is_replaced_and_the_results_are_bit_identical(
    undisturbed: dict, occurrence: int
) -> None:
    with Bus.open() as bus:
        ring = Ring(bus, "distributed")
        kill_on_call(ring, "b", "get_state", occurrence)
        assert ring.run() == undisturbed["distributed"]
        assert [r.subsim for r in ring.coordinator.restarts] == ["b"], ring.log


@pytest.mark.slow
def test_a_subsim_killed_at_a_rollback_is_replaced_and_the_results_are_bit_identical(
    monkeypatch: pytest.MonkeyPatch
) -> None:
    """Three stages are too few for the first 0.1 s interval: it is rolled back and halved three times (nine
    rollbacks of the three subsims), and a subsim killed at its first rollback is replaced there."""
    short = settings("distributed")
    monkeypatch.setattr(sys.modules[__name__], "settings", lambda method: replace(short, max_stages=3, max_halvings=3))
    with Bus.open() as bus:
        calm = Ring(bus, "distributed")
        calm_rollbacks = [0]
        calm.handles["a"].rollback = lambda *a, _r=calm.handles["a"].rollback, **k: (
            calm_rollbacks.__setitem__(0, calm_rollbacks[0] + 1), _r(*a, **k))[1]
        expected = calm.run()
    assert calm_rollbacks[0] == 3  # the interval was rolled back (else this test would test nothing)
    with Bus.open() as bus:
        ring = Ring(bus, "distributed")
        kill_on_call(ring, "c", "rollback", 0)
        assert ring.run() == expected
        assert [r.subsim for r in ring.coordinator.restarts] == ["c"], ring.log


@pytest.mark.slow
def test_a_hung_subsim_is_killed_at_once_when_the_run_stops() -> None:
    """A process found hung (stopped) is not asked to shut down nor given SIGTERM's grace: it is killed."""
    with Bus.open() as bus:
        ring = Ring(bus, "distributed", restarts=0)
        ring.coordinator.deadline = Deadline(fixed=1.0)
        ring.coordinator.on_stage = lambda stage, out: kill(ring.pid("b"), signal.SIGSTOP) if stage == 1 else None
        with pytest.raises(SubsimHung):
            ring.run()
        (proc,) = [p for p in bus.processes if p.name == "b"]
        started = time.monotonic()
        assert proc.stop() == -signal.SIGKILL
        assert time.monotonic() - started < 2.0  # not a 3 s shutdown grace and a 3 s SIGTERM grace


@pytest.mark.slow
def test_with_no_restarts_left_the_failure_stops_the_run() -> None:
    with Bus.open() as bus:
        ring = Ring(bus, "distributed", restarts=0)
        ring.coordinator.on_stage = lambda stage, out: kill(ring.pid("c")) if stage == 1 else None
        with pytest.raises(SubsimDied) as err:
            ring.run()
        assert ring.coordinator.restarts == [] and "restarts" not in str(err.value)  # none were allowed
        assert "its process was killed by SIGKILL" in str(err.value)  # how it ended


class FailingRevivals(Ring):
    """A Ring whose first ``fail`` replacements of a subsim fail while being restored: killed as soon as they
    answer (``how = "killed"``; their set_state or replay meets a dead process), or never started
    (``how = "no start"``: the error a replacement that exits during start-up gives)."""

    def __init__(self, bus: Bus, method: str, how: str, fail: int, restarts: int) -> None:
        self.how, self.fail = how, fail
        super().__init__(bus, method, restarts=restarts)

    def revive(self, name: str, why: str):
        if self.fail == 0:
            return super().revive(name, why)
        self.fail -= 1
        if self.how == "no start":
            raise SubsimError("no_responder", "process exited with code -9", name, "spawn")
        handle = super().revive(name, why)
        kill(self.pid(name))
        deadline = time.monotonic() + 10
        while handle.alive and time.monotonic() < deadline:
            time.sleep(0.005)
        return handle


@pytest.mark.slow
@pytest.mark.parametrize("how", ["killed", "no start"])
def test_a_replacement_that_fails_while_being_restored_uses_a_restart_and_the_next_one_is_tried(
    undisturbed: dict, how: str
) -> None:
    """The replacement's own failure ended the run, whatever --restarts said."""
    with Bus.open() as bus:
        ring = FailingRevivals(bus, "distributed", how, fail=1, restarts=3)
        ring.coordinator.on_stage = lambda stage, out: kill(ring.pid("b")) if len(ring.intervals) == 5 and \
            not ring.coordinator.restarts else None
        assert ring.run() == undisturbed["distributed"]
        assert [(r.subsim, r.restored) for r in ring.coordinator.restarts] == [("b", False), ("b", True)], ring.log
        assert "failed while being restored" in ring.log[0] and "replaced (2 of 3)" in ring.log[1], ring.log


@pytest.mark.slow
def test_when_the_last_restart_fails_while_being_restored_the_error_says_so() -> None:
    with Bus.open() as bus:
        ring = FailingRevivals(bus, "distributed", "killed", fail=2, restarts=2)
        ring.coordinator.on_stage = lambda stage, out: kill(ring.pid("b")) if len(ring.intervals) == 5 and \
            not ring.coordinator.restarts else None
        with pytest.raises(SubsimError) as err:
            ring.run()
        assert err.value.subsim == "b" and "(its replacement 2 of 2, while being restored)" in err.value.message
        assert [r.restored for r in ring.coordinator.restarts] == [False, False], ring.log


def children(pid: int) -> list[int]:
    out = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        text = (task / "children").read_text().split()
        out += [int(x) for x in text]
    return out


@pytest.mark.slow
def test_cosim_run_replaces_a_killed_subsim_and_writes_the_same_csv(tmp_path: Path) -> None:
    """End to end: `cosim run` of the two-mass oscillator, one mass SIGKILLed mid-run; the CSV is byte-identical."""
    scenario = Path(__file__).resolve().parents[1] / "scenarios" / "oscillator.toml"
    cmd = [sys.executable, "-m", "cosim.cli", "run", str(scenario), "--stop", "40", "--quiet"]
    clean = subprocess.run([*cmd, "--output", str(tmp_path / "clean.csv")], capture_output=True, text=True,
                           timeout=300)
    assert clean.returncode == 0, clean.stderr
    run = subprocess.Popen([*cmd, "--output", str(tmp_path / "hurt.csv")], stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while len(children(run.pid)) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(1.0)  # mid-run
        victims = children(run.pid)
        assert len(victims) == 2
        os.kill(victims[0], signal.SIGKILL)
        _, err = run.communicate(timeout=300)
    finally:
        if run.poll() is None:
            run.kill()
            run.wait()
    assert run.returncode == 0, err
    assert "replaced (1 of 2)" in err
    assert (tmp_path / "hurt.csv").read_bytes() == (tmp_path / "clean.csv").read_bytes()
    header, *rows = (tmp_path / "hurt.csv.diag.csv").read_text().splitlines()
    column = header.split(",").index("restarts")
    restarts = [row.split(",")[column] for row in rows]
    assert sorted(restarts, reverse=True)[:2] == ["1", "0"] and restarts.count("1") == 1  # recorded once
    assert read_results(tmp_path / "hurt.csv")[1].shape[0] > 100


@pytest.mark.slow
def test_a_model_stuck_in_advance_is_found_and_the_run_fails_when_every_replacement_sticks_too() -> None:
    """The replacement is configured the same way, so it hangs again: after the restarts the run stops with
    the hang named (it does not wait for zenoh's 60 s query timeout)."""
    with Bus.open() as bus:
        ring = Ring(bus, "centralized", restarts=1, params={"b": {**PARAMS["b"], "compute_delay": 30.0}})
        ring.coordinator.deadline = Deadline(fixed=1.0)
        started = time.monotonic()
        with pytest.raises(SubsimError) as err:
            ring.run()
        assert isinstance(err.value, SubsimHung) and err.value.subsim == "b"
        # not only in the log
        assert str(err.value).endswith("(no restarts left: 1 of 1 used; a model this slow at times needs a longer "
                                       "deadline: timeout (--timeout S, [run] timeout))"), str(err.value)
        assert [r.subsim for r in ring.coordinator.restarts] == ["b"]
        assert time.monotonic() - started < 20  # two 1 s deadlines and a restart, not a 30 s model


class ExternalRun:
    """`cosim run` of the oscillator with mass2 external (``run``: lines added to its [run] table) beside an undisturbed
    run's CSV; the 'user' starts mass2 with the command the coordinator prints. Every process is ended on exit."""

    def __init__(self, tmp_path: Path, stop: float, run: str = "") -> None:
        text = OSCILLATOR.read_text()
        external = tmp_path / "ext.toml"
        external.write_text(text.replace('[subsims.mass2]\nmodel = "subsims.oscillator.subsim:Mass"',
                                         '[subsims.mass2]\nexternal = true\nmodel = "subsims.oscillator.subsim:Mass"')
                            + (f"\n[run]\n{run}\n" if run else ""))
        cmd = [sys.executable, "-m", "cosim.cli", "run", "--stop", f"{stop:g}", "--quiet"]
        self.clean, self.result = tmp_path / "clean.csv", tmp_path / "ext.csv"
        clean = subprocess.run([*cmd, str(OSCILLATOR), "--output", str(self.clean)], capture_output=True, text=True,
                               timeout=300)
        assert clean.returncode == 0, clean.stderr
        self.coord = subprocess.Popen([*cmd, str(external), "--output", str(self.result)], stdout=subprocess.PIPE,
                                      stderr=subprocess.PIPE, text=True)
        self.users: list[subprocess.Popen] = []
        self.lines: list[str] = []
        self.env, self.command = dict(os.environ), None
        assert self.coord.stderr is not None
        for line in self.coord.stderr:
            self.lines.append(line)
            words = line.split()
            if "cosim.serve" in words:  # VAR=value ... python -m cosim.serve ... (the run's secrets go in the env)
                at = words.index("python")
                self.env.update(w.split("=", 1) for w in words[:at])
                self.command = [sys.executable, *words[at + 1:]]
                break
        assert self.command is not None
        self._reader = threading.Thread(target=lambda: self.lines.extend(self.coord.stderr), daemon=True)
        self._reader.start()

    def start_user(self, **popen: object) -> subprocess.Popen:
        assert self.command is not None
        self.users.append(subprocess.Popen(self.command, env=self.env, **popen))  # type: ignore[call-overload]
        return self.users[-1]

    def wait_for(self, text: str, timeout: float = 60.0) -> None:
        deadline = time.monotonic() + timeout
        while not any(text in line for line in self.lines):
            assert time.monotonic() < deadline and self.coord.poll() is None, "".join(self.lines)
            time.sleep(0.05)

    def finish(self) -> str:
        """The coordinator's standard error once it has ended (asserting it succeeded)."""
        self.coord.wait(timeout=300)
        self._reader.join(timeout=10)
        err = "".join(self.lines)
        assert self.coord.returncode == 0, err
        return err

    def __enter__(self) -> ExternalRun:
        return self

    def __exit__(self, *exc: object) -> None:
        for p in [self.coord, *self.users]:
            if p.poll() is None:
                p.kill()  # (a stopped process dies of it too)
            p.wait()


@pytest.mark.slow
def test_an_external_subsim_that_disappears_is_waited_for_and_restored(tmp_path: Path) -> None:
    """`cosim run` with mass2 external: the 'user' starts it, it is killed mid-run, the user starts it again with
    the same command; the run goes on and the CSV equals an undisturbed run's."""
    with ExternalRun(tmp_path, stop=30) as run:
        first = run.start_user(stderr=subprocess.DEVNULL)
        time.sleep(2.0)  # mid-run
        first.kill()
        first.wait()
        time.sleep(0.5)
        run.start_user(stderr=subprocess.DEVNULL)
        err = run.finish()
        assert "mass2 is gone" in err  # (not 'died': its process may have been stopped by its operator)
        waiting = "; it must attach again: waiting up to 300 s for it"
        assert err.index(waiting) < err.index("mass2 is gone")  # said while waiting, not only once it is back
        assert "cosim: external subsim 'mass2' is gone (mass2." in err  # and why it is waited for (a multi-host probe)
        assert "the process ended (Ctrl-C at its terminal, a kill, a crash), or its link was silent" in err, err
        assert run.result.read_bytes() == run.clean.read_bytes()


@pytest.mark.slow
@pytest.mark.parametrize("past_lease", [True, False], ids=["past-its-lease", "found-hung"])
def test_a_replaced_process_that_wakes_up_and_answers_again_is_ignored_not_taken_for_a_copy(
    tmp_path: Path, past_lease: bool
) -> None:
    """mass2 is stopped (SIGSTOP): past its 2 s lease (its token goes), or for less than its 10 s lease but past a 2 s
    deadline (found hung). The run asks for it again and its operator starts it again; then the old process wakes up
    and goes on serving beside its replacement. The run stopped with [duplicate]; its replies are ignored now, and the
    run ends as an undisturbed one."""
    with ExternalRun(tmp_path, stop=60, run="lease = 2" if past_lease else "timeout = 2") as run:
        old = run.start_user(stderr=subprocess.DEVNULL)
        time.sleep(2.0)
        old.send_signal(signal.SIGSTOP)
        stopped = time.monotonic()
        run.wait_for("it must attach again")
        run.start_user(stderr=subprocess.DEVNULL)
        run.wait_for("replaced (1 of")
        time.sleep(max(0.0, stopped + (4.0 if past_lease else 0.0) - time.monotonic()))  # past: twice its lease
        old.send_signal(signal.SIGCONT)
        time.sleep(2.0)
        assert run.coord.poll() is None, "the run ended before the old process was heard again: a longer --stop"
        err = run.finish()
        assert "[duplicate]" not in err and ("mass2 is gone" if past_lease else "mass2 hung") in err, err
        assert old.wait(timeout=30) == 0  # the run's shutdown reached it too
        assert run.result.read_bytes() == run.clean.read_bytes()


@pytest.mark.slow
def test_an_external_subsim_stopped_past_its_lease_and_woken_is_that_subsim_again(tmp_path: Path) -> None:
    """mass2 is stopped for three times its 2 s lease and woken, and nobody starts another: it attaches again by
    itself (its session reconnects) and is restored; the run ends as an undisturbed one (a red team: a subsim that
    left by itself on waking made this wait for its operator)."""
    with ExternalRun(tmp_path, stop=60, run="lease = 2") as run:
        old = run.start_user(stderr=subprocess.DEVNULL)
        time.sleep(2.0)
        old.send_signal(signal.SIGSTOP)
        run.wait_for("it must attach again")
        time.sleep(4.0)
        old.send_signal(signal.SIGCONT)
        err = run.finish()
        assert "mass2 is gone" in err and "replaced (1 of" in err, err
        assert old.wait(timeout=30) == 0
        assert run.result.read_bytes() == run.clean.read_bytes()


def test_the_deadline_follows_measured_request_times() -> None:
    d = Deadline(floor=1.5, typical=50.0, spike=3.0, initial=30.0, warmup=5)
    assert d.seconds() == 30.0  # nothing measured yet
    for _ in range(5):
        d.observe(0.001)
    assert d.seconds() == 1.5  # 50 x 1 ms is below the floor
    for _ in range(40):
        d.observe(0.1)  # a slower model: 50 x the median
    assert d.seconds() == pytest.approx(5.0)
    d.observe(3.0)  # one slow request: at once three times it
    assert d.seconds() == pytest.approx(9.0)
    assert Deadline(fixed=0.7).seconds() == 0.7


@pytest.mark.slow
def test_an_external_subsim_that_is_not_started_again_is_named_so(tmp_path: Path) -> None:
    """Its process killed mid-run and nobody starting it again: the wait ran out with 'no process appeared ... check
    its --run and --name' (a first start's advice, for the command that had worked); the line asking for it again
    now repeats its command (multi-host probe). It is waited for once, not once per restart left, each wait logged
    as a failed replacement though nothing had started (a second multi-host probe: 2 x --attach-wait)."""
    scenario = Path(__file__).resolve().parents[1] / "scenarios" / "oscillator.toml"
    external = tmp_path / "ext.toml"
    external.write_text(scenario.read_text().replace(
        '[subsims.mass2]\nmodel = "subsims.oscillator.subsim:Mass"',
        '[subsims.mass2]\nexternal = true\nmodel = "subsims.oscillator.subsim:Mass"') + "\n[run]\nlease = 30\n")
    coord = subprocess.Popen([sys.executable, "-m", "cosim.cli", "run", str(external), "--stop", "30", "--quiet",
                              "--attach-wait", "2", "--restarts", "2", "--output", str(tmp_path / "ext.csv")],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    user = None
    try:
        assert coord.stderr is not None
        env, command = dict(os.environ), None
        for line in coord.stderr:
            words = line.split()
            if "cosim.serve" in words:
                at = words.index("python")
                env.update(w.split("=", 1) for w in words[:at])
                command = [sys.executable, *words[at + 1:]]
                break
        assert command is not None
        user = subprocess.Popen(command, stderr=subprocess.DEVNULL, env=env)
        time.sleep(2.0)  # mid-run
        user.kill()
        user.wait()
        _, err = coord.communicate(timeout=120)
    finally:
        for p in [coord, *([user] if user else [])]:
            if p.poll() is None:
                p.kill()
            p.wait()
    assert coord.returncode == 1, err
    again = err.index("cosim: external subsim 'mass2' is gone (mass2.")
    assert err.count("must attach again") == 1 and "replacement" not in err, err
    assert "python -m cosim.serve subsims.oscillator.subsim:Mass" in err[again:]  # its command, once more
    assert "silent for longer than its 30 s lease" in err  # the lease its command was given, not 10 s
    assert ("run stopped: mass2.connect: [no_responder] it did not attach again within 2 s (its command is above; "
            "--attach-wait sets how long it is waited for)") in err, err


CRASHES_ONCE = """
import os, signal
from pathlib import Path
from subsims.oscillator.subsim import Mass

MARK = Path(__file__).with_name("crashed-{where}")


def crash_once():
    if not MARK.exists():
        MARK.touch()
        os.kill(os.getpid(), signal.SIGKILL)  # as the OOM killer or a segfault would


class Fragile(Mass):
    def __init__(self):
        if "{where}" == "start":
            crash_once()
        super().__init__()

    def initial_state(self, params):
        if "{where}" == "configure":
            crash_once()
        return super().initial_state(params)
"""


HANGS_ONCE = """
import os, signal, time
from pathlib import Path
from subsims.oscillator.subsim import Mass

MARK = Path(__file__).with_name("hung")


class Slow(Mass):
    def __init__(self):
        if not MARK.exists():  # the first process stands still before it can answer
            MARK.touch()
            {how}
        super().__init__()
"""


def test_a_subsim_stopped_as_it_starts_is_started_again(tmp_path: Path) -> None:
    """A launched subsim stopped as it started (a red team's SIGSTOP of over 20 s) stopped the run, "did not come
    up within 20 s", with restarts left: it is killed and started again, within the run's restarts, and the summary
    says so. One slow or stuck in its own code (not stopped) is not: it would be as slow again (a review)."""
    sc = tmp_path / "s.toml"
    sc.write_text(OSCILLATOR.read_text().replace('model = "subsims.oscillator.subsim:Mass"', 'model = "slow:Slow"', 1))
    (tmp_path / "slow.py").write_text(HANGS_ONCE.replace("{how}", "time.sleep(3600)"))
    with pytest.raises(SubsimError, match=r"did not come up within 20 s$"):
        run_scenario(load(sc), stop=0.2, output=tmp_path / "y.csv", progress=False, log=lambda m: None, restarts=1)
    (tmp_path / "hung").unlink()
    (tmp_path / "slow.py").write_text(HANGS_ONCE.replace("{how}", "os.kill(os.getpid(), signal.SIGSTOP)"))
    said: list[str] = []
    run_scenario(load(OSCILLATOR), stop=0.2, output=tmp_path / "calm.csv", progress=False, log=said.append)
    report = run_scenario(load(sc), stop=0.2, output=tmp_path / "x.csv", progress=False, log=said.append, restarts=1)
    assert (tmp_path / "hung").exists()
    assert [m for m in said if "lost while starting" in m] == [
        "cosim: mass1 was lost while starting (did not come up within 20 s (its process is stopped)); starting it "
        "again (0 more restarts in this run at most)"]
    assert (tmp_path / "x.csv").read_bytes() == (tmp_path / "calm.csv").read_bytes()
    restarts = report.extra["restarts"]  # in the report and the summary too (they were left out: a red team)
    assert [(r.subsim, r.reason) for r in restarts] == [
        ("mass1", "was lost while starting (did not come up within 20 s (its process is stopped))")]
    assert math.isnan(restarts[0].at)  # nothing was restored: the summary says "started again"


@pytest.mark.parametrize("where", ["start", "configure"])
def test_a_subsim_killed_while_it_starts_is_started_again(tmp_path: Path, where: str) -> None:
    """A launched subsim killed by a signal before it answered, or while it was configured, stopped the run at once
    ("orbit.spawn: [no_responder] its process was killed by SIGKILL"), with restarts left (a red-team probe). It is
    started again, within the run's restarts, and the run is the undisturbed one; an exit of its own is not retried
    (it would come again), nor a kill with no restarts."""
    (tmp_path / "fragile.py").write_text(CRASHES_ONCE.replace("{where}", where))
    text = OSCILLATOR.read_text()
    sc = tmp_path / "s.toml"
    sc.write_text(text.replace('model = "subsims.oscillator.subsim:Mass"', 'model = "fragile:Fragile"', 1))
    said: list[str] = []
    run_scenario(load(OSCILLATOR), stop=0.2, output=tmp_path / "calm.csv", progress=False, log=said.append)
    run_scenario(load(sc), stop=0.2, output=tmp_path / "x.csv", progress=False, log=said.append, restarts=2)
    assert (tmp_path / f"crashed-{where}").exists()  # it did crash once
    lost = [m for m in said if "lost while starting" in m]
    assert len(lost) == 1 and lost[0].startswith("cosim: mass1 was lost while starting (") and "SIGKILL" in lost[0]
    assert lost[0].endswith("; starting it again (1 more restart in this run at most)"), lost
    assert (tmp_path / "x.csv").read_bytes() == (tmp_path / "calm.csv").read_bytes()
    (tmp_path / f"crashed-{where}").unlink()
    with pytest.raises(SubsimError, match="killed by SIGKILL"):
        run_scenario(load(sc), stop=0.2, output=tmp_path / "y.csv", progress=False, log=said.append, restarts=0)
    (tmp_path / f"crashed-{where}").unlink()  # one restart: used by the start, none left for the run (a red team)
    said.clear()
    run_scenario(load(sc), stop=0.2, output=tmp_path / "z.csv", progress=False, log=said.append, restarts=1)
    assert [m for m in said if "lost while starting" in m][0].endswith("(0 more restarts in this run at most)")
