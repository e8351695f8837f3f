"""Results survive interruption and are never silently damaged; the CLI's rough edges are one-line errors.

Each behaviour is checked on ``cosim`` run as a real process, as a user runs it. Every process a test
starts (and every subsim those start) is gone when the test ends, pass or fail.
"""

from __future__ import annotations

import errno
import json
import os
import pty
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
from terminal import as_from_a_terminal

from cosim import __version__, interrupt, resume
from cosim.coupler.couplings import SignalRef
from cosim.coupler.relaxation import Interval
from cosim.outputs import (
    AppendFile,
    OutputError,
    OutputLock,
    OutputWriteError,
    atomic_write,
    diag_path,
    resume_path,
    stream_path,
)
from cosim.results import ResultWriter, read_results, read_units
from cosim.runner import run_scenario
from cosim.scenario import load
from cosim.unified import run_unified

pytestmark = [pytest.mark.slow]  # the inner loop: pytest -m "not slow"

ROOT = Path(__file__).parents[1]
OSCILLATOR = ROOT / "scenarios" / "oscillator.toml"
COSIM = [sys.executable, "-m", "cosim.cli"]
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
H, SAMPLES = 0.05, 5  # the oscillator's interval and samples per interval


def alive(subsim: tuple[int, str]) -> bool:
    """Is the subsim (pid, run id) still running? A pid reused by another process does not count."""
    pid, run_id = subsim
    try:
        if run_id.encode() not in Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0"):
            return False
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"  # a zombie is dead
    except (OSError, IndexError):
        return False


class Run:
    """``cosim ARGS`` as a background process; stderr collected by a thread (so it never blocks)."""

    def __init__(self, *args: str, preexec_fn: Callable[[], object] | None = None) -> None:
        self.proc = subprocess.Popen([*COSIM, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     env=ENV, preexec_fn=preexec_fn or as_from_a_terminal)
        self.err: list[str] = []
        self.out = ""
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.err.append(line)

    def subsims(self) -> list[tuple[int, str]]:
        """(pid, run id) of every subsim that announced itself ("<name>: serving run RUN via EP (pid N)")."""
        return [(int(line.rsplit("pid ", 1)[1].rstrip(")\n")), line.split("serving run ", 1)[1].split()[0])
                for line in list(self.err) if "serving run" in line]

    def wait(self, timeout: float = 120.0) -> int:
        self.proc.wait(timeout)
        assert self.proc.stdout is not None
        self.out = self.proc.stdout.read()  # small: the summary lines
        self._reader.join(timeout)
        return self.proc.returncode

    def own_lines(self) -> list[str]:
        """stderr lines of the coordinator (not the subsims' "serving" lines)."""
        return [line.rstrip("\n") for line in self.err if "serving run" not in line]

    def cleanup(self) -> None:
        subsims = self.subsims()
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
        for subsim in subsims:  # subsims this run started and left behind
            if alive(subsim):
                os.kill(subsim[0], signal.SIGKILL)


@pytest.fixture
def runs() -> Iterator[list[Run]]:
    started: list[Run] = []
    yield started
    for r in started:
        r.cleanup()


def start(runs: list[Run], *args: str, preexec_fn: Callable[[], object] | None = None) -> Run:
    r = Run(*args, preexec_fn=preexec_fn)
    runs.append(r)
    return r


def cosim(*args: str, timeout: float = 120.0, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([*COSIM, *args], capture_output=True, text=True, timeout=timeout, env=ENV, **kw)


def diag_rows(path: Path) -> list[list[str]]:
    if not path.exists():
        return []
    return [line.split(",") for line in path.read_text().splitlines()[1:]]


@pytest.mark.parametrize("method", ["distributed", "unified"])
def test_an_interval_written_as_the_signal_came_counts_as_committed(tmp_path: Path, monkeypatch, method: str) -> None:
    """A signal held back while an interval is appended is raised right after: that interval is in the files, so the
    run's last committed time (the "stopped at t = ..." line) must be its end (once, in CI, it named the one before)."""
    append, calls = ResultWriter._append, []

    def append_then_signal(self, *args, **kwargs):  # noqa: ANN001, ANN202
        append(self, *args, **kwargs)
        calls.append(None)
        if len(calls) == 3:  # the signal arrived inside the third interval's write, held back until it ended
            raise interrupt.Interrupted(signal.SIGHUP)

    monkeypatch.setattr(ResultWriter, "_append", append_then_signal)
    seen: list[float] = []
    out = tmp_path / "osc.csv"
    with pytest.raises(interrupt.Interrupted):
        if method == "unified":  # the satellite's RK-U (the oscillator has no unified reference)
            run_unified(load(ROOT / "scenarios" / "satellite" / "case1.toml"), stop=2.0, output=out,
                        on_interval=lambda iv: seen.append(float(iv.t[-1])))
        else:
            run_scenario(load(OSCILLATOR), stop=10.0, output=out, inprocess=True, progress=False, log=lambda s: None,
                         on_interval=lambda iv: seen.append(float(iv.t[-1])))
    written = diag_rows(out.with_name(out.name + ".diag.csv"))
    assert len(written) == len(seen) == 3 and float(written[-1][2]) == seen[-1]


def test_a_signal_during_the_cleanup_of_a_finished_run_cuts_nothing_short(tmp_path: Path, monkeypatch) -> None:
    """A SIGTERM while the subsims of a finished run were being stopped: the run was reported as interrupted (exit 143)
    and its resume point was already gone, so --resume said 'run it again from the start' (ops probe)."""
    from cosim.runner import Session

    close = Session.close

    def close_under_a_signal(self) -> None:  # noqa: ANN001
        os.kill(os.getpid(), signal.SIGTERM)
        close(self)

    monkeypatch.setattr(Session, "close", close_under_a_signal)
    out = tmp_path / "r.csv"
    try:
        with interrupt.handling():
            report = run_scenario(load(OSCILLATOR), stop=1.0, output=out, inprocess=True, progress=False)
            late = interrupt.late()
    except interrupt.Interrupted:  # (a KeyboardInterrupt: pytest would stop the session on it)
        pytest.fail("the finished run was reported as interrupted")
    assert late == "SIGTERM" and report.summary.t_end == 1.0
    assert read_results(out)[1][-1, 0] == 1.0 and not resume_path(out).exists()


def test_a_run_ending_in_another_thread_leaves_the_main_threads_run_stoppable(tmp_path: Path) -> None:
    """A script running cosim.run in a worker thread while its main thread runs another: the worker's run ended, and
    Ctrl-C no longer stopped the main thread's (an API probe: the worker's end marked the main run finished)."""
    import threading
    import time

    def worker() -> None:
        run_scenario(load(OSCILLATOR), stop=0.2, output=tmp_path / "w.csv", inprocess=True, progress=False)
        os.kill(os.getpid(), signal.SIGTERM)

    thread = threading.Thread(target=worker)
    with pytest.raises(interrupt.Interrupted) as stopped:
        with interrupt.handling():
            thread.start()
            deadline = time.monotonic() + 30.0
            while time.monotonic() < deadline:  # the main thread's run, its intervals written in deferred blocks
                with interrupt.deferred():
                    time.sleep(0.01)
    thread.join()
    assert stopped.value.name == "SIGTERM"


def test_a_signal_with_the_last_interval_written_leaves_a_finished_run(tmp_path: Path, monkeypatch, capsys) -> None:
    """The signal held back while the last interval was written is raised at its end, with only the subsims' last
    commit left: the results are whole, so the run counts as finished (exit 0, no resume point to go on from)."""
    from cosim.cli import main

    append = ResultWriter._append

    def append_then_signal(self, interval, *args, **kwargs):  # noqa: ANN001, ANN202
        append(self, interval, *args, **kwargs)
        if float(interval.t[-1]) >= 1.0:
            raise interrupt.Interrupted(signal.SIGTERM)

    monkeypatch.setattr(ResultWriter, "_append", append_then_signal)
    out = tmp_path / "r.csv"
    try:
        status = main(["run", str(OSCILLATOR), "--stop", "1", "--inprocess", "--quiet", "--output", str(out)])
    except KeyboardInterrupt:
        pytest.fail("the finished run was reported as interrupted")
    assert status == 0
    said = capsys.readouterr()
    assert said.err.strip().splitlines() == [
        f"cosim: SIGTERM came as the run finished; every interval to t = 1 s is in {out}"], said.err
    assert said.out.splitlines() == [f"results: {out}", f"diagnostics: {out}.diag.csv"]  # as a finished run's
    assert read_results(out)[1][-1, 0] == 1.0 and not resume_path(out).exists()


def wait_for_intervals(run: Run, diag: Path, n: int, timeout: float = 120.0) -> None:
    """Until ``n`` intervals are committed (a hang guard, not a measurement)."""
    deadline = time.monotonic() + timeout
    while len(diag_rows(diag)) < n:
        assert run.proc.poll() is None, f"the run ended early: {''.join(run.err)}"
        assert time.monotonic() < deadline, f"fewer than {n} intervals committed in {timeout:g} s"
        time.sleep(0.05)


def assert_whole_intervals(path: Path) -> np.ndarray:
    """The result holds whole intervals: 1 + 4 k rows, each interval's end included, no time twice."""
    if path.suffix == ".csv":
        assert path.read_bytes().endswith(b"\n"), "a partial last row"
    _, data = read_results(path)
    t = data[:, 0]
    assert (data.shape[0] - 1) % (SAMPLES - 1) == 0, data.shape
    assert np.all(np.diff(t) > 0), "a time repeats or goes back"
    assert t[-1] / H == pytest.approx(round(t[-1] / H)), "does not end at an interval end"
    return data


# --- A. interrupted coordinator --------------------------------------------------------------------

@pytest.mark.parametrize(("sig", "suffix"), [
    pytest.param(sig, suffix, id=f"{sig.name}-{suffix[1:]}")
    for sig, suffix in [(signal.SIGINT, ".npz"), (signal.SIGTERM, ".csv"), (signal.SIGTERM, ".npz"),
                        (signal.SIGHUP, ".csv"), (signal.SIGHUP, ".npz")]  # SIGINT-csv: test_cli.py
])
def test_signal_stops_subsims_keeps_every_committed_interval_and_says_where(
    tmp_path: Path, runs: list[Run], sig: int, suffix: str
) -> None:
    out = tmp_path / f"osc{suffix}"
    run = start(runs, "run", str(OSCILLATOR), "--stop", "1000", "--output", str(out))
    diag = out.with_name(out.name + ".diag.csv")
    wait_for_intervals(run, diag, 20)
    subsims = run.subsims()
    assert len(subsims) == 2
    run.proc.send_signal(sig)
    run.proc.wait(120)
    # checked the moment the coordinator is gone: subsims it left would live on ~2 s (their watchdog)
    assert [p for p in subsims if alive(p)] == [], "the coordinator exited without stopping its subsims"
    assert run.wait() == 128 + sig
    committed = diag_rows(diag)
    t_end = float(committed[-1][2])
    lines = run.own_lines()
    assert lines == [f"cosim: stopped by {signal.Signals(sig).name} at t = {t_end:.6g} s; "
                     f"every committed interval is in {out}"], lines
    data = assert_whole_intervals(out)
    assert data.shape[0] == 1 + (SAMPLES - 1) * len(committed) and data[-1, 0] == t_end
    assert not stream_path(out).exists() and not out.with_name(out.name + ".lock").exists()


def test_under_nohup_a_hangup_does_not_stop_the_run(tmp_path: Path, runs: list[Run]) -> None:
    out = tmp_path / "nohup.csv"
    run = start(runs, "run", str(OSCILLATOR), "--stop", "1000", "--output", str(out), "--inprocess",
                preexec_fn=lambda: (as_from_a_terminal(), signal.signal(signal.SIGHUP, signal.SIG_IGN)))  # nohup
    diag = out.with_name(out.name + ".diag.csv")
    wait_for_intervals(run, diag, 5)
    run.proc.send_signal(signal.SIGHUP)
    n = len(diag_rows(diag))
    wait_for_intervals(run, diag, n + 20)  # still committing after the hangup
    run.proc.send_signal(signal.SIGINT)
    assert run.wait() == 130


def test_sigkill_keeps_a_whole_csv_and_subsims_leave_by_themselves(tmp_path: Path, runs: list[Run]) -> None:
    out = tmp_path / "killed.csv"
    run = start(runs, "run", str(OSCILLATOR), "--stop", "1000", "--output", str(out))
    wait_for_intervals(run, out.with_name(out.name + ".diag.csv"), 30)
    subsims = run.subsims()
    assert len(subsims) == 2
    run.proc.kill()
    run.proc.wait()  # not run.wait(): the subsims hold its stderr open until they exit
    killed = time.monotonic()
    deadline = killed + 60  # a hang guard: the figure is printed, not asserted
    while [p for p in subsims if alive(p)] and time.monotonic() < deadline:
        time.sleep(0.02)
    assert [p for p in subsims if alive(p)] == [], "subsims outlived their killed coordinator by 60 s"
    print(f"subsims left {time.monotonic() - killed:.2f} s after their coordinator was SIGKILLed")
    data = assert_whole_intervals(out)
    assert data.shape[0] >= 1 + 4 * 30
    # the rows are those of an uninterrupted run: no interval's end row lost, none written twice
    ref = tmp_path / "ref.csv"
    done = cosim("run", str(OSCILLATOR), "--stop", f"{data[-1, 0]:.6g}", "--output", str(ref), "--inprocess",
                 "--quiet")
    assert done.returncode == 0, done.stderr
    np.testing.assert_allclose(data, read_results(ref)[1], rtol=0, atol=1e-12)


def test_sigkill_npz_is_rebuilt_by_cosim_recover(tmp_path: Path, runs: list[Run]) -> None:
    out = tmp_path / "killed.npz"
    run = start(runs, "run", str(OSCILLATOR), "--stop", "1000", "--output", str(out))
    diag = out.with_name(out.name + ".diag.csv")
    wait_for_intervals(run, diag, 30)
    run.proc.kill()
    run.wait()
    assert not out.exists() and stream_path(out).exists()
    n_committed = len(diag_rows(diag))
    again = cosim("run", str(OSCILLATOR), "--stop", "1", "--output", str(out), "--inprocess")
    assert again.returncode == 2 and f"cosim recover {out}" in again.stderr  # the samples are not overwritten
    done = cosim("recover", str(out))
    assert done.returncode == 0, done.stderr
    assert str(out) in done.stdout and not stream_path(out).exists()
    data = assert_whole_intervals(out)
    assert data.shape[0] >= 1 + (SAMPLES - 1) * n_committed  # the results were written before the diagnostics
    assert read_units(out)["mass1.v[0]"] == "m/s"
    assert cosim("recover", str(out)).stdout.strip().endswith("nothing to recover")


def test_recover_cuts_a_torn_csv_row(tmp_path: Path) -> None:
    out = tmp_path / "torn.csv"
    assert cosim("run", str(OSCILLATOR), "--stop", "0.2", "--output", str(out), "--inprocess").returncode == 0
    with out.open("a") as f:
        f.write("0.2125,0.12")  # what a write cut short would leave
    with pytest.raises(ValueError, match="cosim recover"):
        read_results(out)
    done = cosim("recover", str(out))
    assert done.returncode == 0 and "cut a partial last row" in done.stdout
    assert_whole_intervals(out)


def test_recover_says_when_the_results_and_diagnostics_end_at_different_intervals(tmp_path: Path) -> None:
    """A kill between an interval's two writes leaves its rows without its diagnostics row; `cosim recover` said
    '(complete)' of it (durability probe)."""
    out = tmp_path / "r.csv"
    assert cosim("run", str(OSCILLATOR), "--stop", "0.2", "--output", str(out), "--inprocess").returncode == 0
    assert "diagnostics end" not in cosim("recover", str(out)).stdout  # the two agree
    diag = Path(f"{out}.diag.csv")
    lines = diag.read_text().splitlines()
    diag.write_text("\n".join(lines[:-1]) + "\n")  # the last interval's row never written
    done = cosim("recover", str(out))
    assert done.returncode == 0
    assert (f"(complete); its diagnostics end at t = {float(lines[-2].split(',')[2]):.6g} s, the results at t = 0.2 s "
            "(it was stopped between an interval's two writes): --resume (or --overwrite) makes them agree") \
        in done.stdout, done.stdout


@pytest.mark.parametrize(("name", "content", "words"), [
    ("victim.toml", b'name = "x"\nstop = 2.0', "is not a result file: cosim writes .csv or .npz"),
    ("notes.csv", b"a,b\n1,2\n3,", "not a cosim result file (its first line is not a header starting with 'time,')"),
    ("binary.csv", bytes(range(256)) * 4, "not a cosim result file"),
    ("garbage.npz", b"PK\x03\x04 not really a zip", "not a cosim result file"),
])
def test_recover_leaves_a_file_that_is_not_a_result_file_as_it_was(tmp_path: Path, name: str, content: bytes,
                                                                  words: str) -> None:
    """recover cuts a torn last row: it must be sure the file is one of its own first (it shortened a TOML file)."""
    victim = tmp_path / name
    victim.write_bytes(content)
    done = cosim("recover", str(victim))
    assert done.returncode != 0 and words in done.stderr and "Traceback" not in done.stderr, done.stderr
    assert victim.read_bytes() == content
    folder = cosim("recover", str(tmp_path))
    assert folder.returncode != 0 and "is a directory" in folder.stderr and "Traceback" not in folder.stderr


# --- B. outputs never silently damaged ---------------------------------------------------------------

def test_existing_result_is_refused_before_launch_unless_overwrite(tmp_path: Path) -> None:
    out = tmp_path / "old.csv"
    out.write_text("precious\n")
    done = cosim("run", str(OSCILLATOR), "--stop", "0.1", "--output", str(out))
    assert done.returncode == 2 and out.read_text() == "precious\n"
    assert done.stderr.splitlines() == [f"cosim: {out} exists: pass --overwrite to replace it, or choose another "
                                        "--output"]  # and no subsim announced itself: nothing was launched
    done = cosim("run", str(OSCILLATOR), "--stop", "0.1", "--output", str(out), "--overwrite", "--quiet")
    assert done.returncode == 0, done.stderr
    assert_whole_intervals(out)
    for companion in (".csv.diag.csv", ".csv.meta.json"):  # a companion alone is not replaced silently either
        lone = tmp_path / f"lone{companion}"
        lone.write_text("precious\n")
        done = cosim("run", str(OSCILLATOR), "--stop", "0.1", "--output", str(tmp_path / "lone.csv"))
        assert done.returncode == 2 and lone.read_text() == "precious\n"
        assert done.stderr.splitlines() == [f"cosim: {lone} exists: pass --overwrite to replace it, or choose "
                                            "another --output"]
        lone.unlink()


def test_a_second_run_on_the_same_file_is_refused_naming_the_first(tmp_path: Path, runs: list[Run]) -> None:
    out = tmp_path / "shared.csv"
    first = start(runs, "run", str(OSCILLATOR), "--stop", "1000", "--output", str(out), "--inprocess")
    wait_for_intervals(first, out.with_name(out.name + ".diag.csv"), 5)
    second = cosim("run", str(OSCILLATOR), "--stop", "1", "--output", str(out), "--overwrite")
    assert second.returncode == 2
    assert second.stderr.splitlines() == [f"cosim: {out} is being written by another cosim run (pid {first.proc.pid}, "
                                          f"lock {out}.lock): wait for it to finish or choose another --output"]
    alias = tmp_path / "alias.csv"
    alias.symlink_to(out)  # another name of the same file
    third = cosim("run", str(OSCILLATOR), "--stop", "1", "--output", str(alias), "--overwrite", "--inprocess")
    assert third.returncode == 2 and f"pid {first.proc.pid}" in third.stderr
    first.proc.send_signal(signal.SIGINT)
    assert first.wait() == 130
    assert_whole_intervals(out)  # the first run's file is intact


def test_a_stale_lock_of_a_dead_run_is_taken_over(tmp_path: Path) -> None:
    out = tmp_path / "stale.csv"
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    out.with_name(out.name + ".lock").write_text(f"{dead.pid}\n")  # as a SIGKILLed run leaves it
    done = cosim("run", str(OSCILLATOR), "--stop", "0.1", "--output", str(out), "--inprocess", "--quiet")
    assert done.returncode == 0, done.stderr
    assert not out.with_name(out.name + ".lock").exists()


def test_csv_and_npz_runs_of_one_scenario_have_their_own_diagnostics(tmp_path: Path) -> None:
    for suffix, method in ((".csv", "distributed"), (".npz", "centralized")):
        done = cosim("run", str(OSCILLATOR), "--stop", "0.1", "--output", str(tmp_path / f"x{suffix}"),
                     "--inprocess", "--quiet", "--method", method)
        assert done.returncode == 0, done.stderr
        assert f"diagnostics: {tmp_path / f'x{suffix}.diag.csv'}" in done.stdout
    csv_diag, npz_diag = diag_rows(tmp_path / "x.csv.diag.csv"), diag_rows(tmp_path / "x.npz.diag.csv")
    assert len(csv_diag) == len(npz_diag) == 2 and csv_diag != npz_diag  # different methods, different stages
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.csv", "x.csv.diag.csv", "x.csv.meta.json", "x.npz",
                                                          "x.npz.diag.csv"]


@pytest.fixture
def mount_tmpfs(tmp_path: Path) -> Iterator:
    """``mount_tmpfs(options)`` -> a fresh tmpfs directory (root only); unmounted after the test, pass or fail."""
    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root")
    mounted: list[Path] = []

    def mount(options: str) -> Path:
        where = tmp_path / f"mnt{len(mounted)}"
        where.mkdir()
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(where)], capture_output=True)
        if done.returncode != 0:
            pytest.skip(f"cannot mount a tmpfs here: {done.stderr.decode().strip()}")
        mounted.append(where)
        return where

    try:
        yield mount
    finally:
        for where in mounted:
            subprocess.run(["umount", "-l", str(where)], check=False)


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_disk_full_is_one_error_and_the_file_ends_at_a_whole_interval(mount_tmpfs, suffix: str) -> None:
    out = mount_tmpfs("size=64k") / f"full{suffix}"
    done = cosim("run", str(OSCILLATOR), "--stop", "1000", "--output", str(out), "--inprocess", "--quiet")
    assert done.returncode == 1
    lines = done.stderr.splitlines()
    assert lines[0].startswith("cosim: run stopped: disk full writing "), lines
    # and where the results end and how to go on: with --resume past a resume point, else again from the start
    # (--overwrite); nothing when the results file is not there (the NPZ's samples: said on the first line)
    assert lines[1:] == [] or (len(lines) == 2 and ("once that is fixed, the same command with --resume goes on" in
                                                    lines[1] or "with --overwrite runs it again from the start" in
                                                    lines[1])), lines
    if suffix == ".csv":
        data = assert_whole_intervals(out)
        assert f"results end at t = {data[-1, 0]:.6g} s" in lines[0]
    else:  # the NPZ cannot be built on a full disk: the stream keeps every whole row, and says how to rebuild
        assert not out.exists() and f"cosim recover {out}" in lines[0]
        raw = stream_path(out).read_bytes()
        assert (len(raw) - raw.index(b"\n", 16) - 1) % (8 * 5) == 0


def test_read_only_output_is_refused_before_launch(mount_tmpfs) -> None:
    out = mount_tmpfs("ro,size=64k") / "x.csv"  # root ignores permission bits, not a read-only mount
    done = cosim("run", str(OSCILLATOR), "--stop", "0.1", "--output", str(out))
    assert done.returncode == 2
    assert done.stderr.splitlines() == [f"cosim: cannot write {out}: cannot create {out}.lock (Read-only file "
                                        "system): choose another --output"]


def test_an_append_cut_short_by_enospc_leaves_the_file_at_its_last_record(tmp_path: Path,
                                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    f = AppendFile(tmp_path / "a.csv", "results")
    f.append(b"time,x\n0.0,1.0\n")
    real_write = os.write

    def half_then_full(fd: int, data) -> int:
        if len(data) > 4:
            return real_write(fd, bytes(data[: len(data) // 2]))
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr("cosim.outputs.os.write", half_then_full)
    with pytest.raises(OutputWriteError, match=r"^disk full writing .*a\.csv \(results\): at t = 0"):
        f.append(b"0.5,2.0\n1.0,3.0\n", lambda: "at t = 0")
    monkeypatch.undo()
    f.close()
    assert (tmp_path / "a.csv").read_bytes() == b"time,x\n0.0,1.0\n"


def test_atomic_write_leaves_the_old_file_or_the_whole_new_one(tmp_path: Path) -> None:
    target = tmp_path / "r.npz"
    target.write_bytes(b"old")

    def dies_halfway(f) -> None:
        f.write(b"half of the new")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        atomic_write(target, dies_halfway)
    assert target.read_bytes() == b"old" and [p.name for p in tmp_path.iterdir()] == ["r.npz"]
    atomic_write(target, lambda f: f.write(b"new"))
    assert target.read_bytes() == b"new" and [p.name for p in tmp_path.iterdir()] == ["r.npz"]


def test_atomic_write_on_a_read_only_file_system_is_one_error_not_its_cleanups(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The clean-up of the temporary file raised EROFS too, and that traceback hid the write's own error (ops
    probe: a read-only bind mount over the output directory mid-run printed 40 lines)."""
    def read_only(*args, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr("cosim.outputs.os.replace", read_only)
    monkeypatch.setattr(Path, "unlink", read_only)
    with pytest.raises(OutputWriteError) as err:
        atomic_write(tmp_path / "r.csv.resume.npz", lambda f: f.write(b"x"))
    assert str(err.value) == (f"Read-only file system writing {tmp_path / 'r.csv.resume.npz'}; choose another place, "
                              "then run again")


def test_a_lock_a_full_disk_cannot_hold_the_pid_of_is_one_error_and_left_behind(tmp_path: Path,
                                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr("cosim.outputs.os.pwrite", full)
    with pytest.raises(OutputError) as err:
        OutputLock.acquire(tmp_path / "z.csv")
    assert str(err.value) == (f"cannot write {tmp_path / 'z.csv'}: disk full writing {tmp_path / 'z.csv.lock'}; free "
                              "space or choose another place")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_a_results_file_removed_during_the_run_stops_it_in_one_line(tmp_path: Path, suffix: str) -> None:
    """rm of the results (or of the NPZ's stream) mid-run: the run went on writing into the removed file and ended
    with exit 0 naming a file that did not exist (an NPZ's: a FileNotFoundError traceback at its end)."""
    out = tmp_path / f"r{suffix}"
    seen = []

    def remove_at_the_tenth(interval) -> None:
        seen.append(interval)
        if len(seen) == 10:
            (stream_path(out) if suffix == ".npz" else out).unlink()

    with pytest.raises(OutputWriteError) as err:
        run_scenario(load(OSCILLATOR), stop=2.0, output=out, inprocess=True, progress=False,
                     on_interval=remove_at_the_tenth)
    written = stream_path(out) if suffix == ".npz" else out
    what = "the NPZ's streamed samples" if suffix == ".npz" else "results"
    assert str(err.value) == (f"{written} ({what}) was removed during the run (by another program?): what this run "
                              "wrote there is lost; run again")
    assert len(seen) == 10


def test_a_full_disk_in_the_diagnostics_cuts_the_interval_from_the_results_too(tmp_path: Path) -> None:
    """The two files end at the same interval (the results had one interval more than the diagnostics, 1 of 16 fill
    points in the ops probe)."""
    out = tmp_path / "r.csv"
    writer = ResultWriter(out, [(SignalRef("a", "x"), 1)])

    def interval(t0: float) -> Interval:
        t = np.linspace(t0, t0 + 0.1, 3)
        return Interval(t, {"a": {"x": t[:, None]}}, {}, 2, {})

    writer.write(interval(0.0))
    writer.write(interval(0.1))
    before = (out.read_bytes(), diag_path(out).read_bytes())

    def full(data: bytes, ends_at: Callable[[], str] = lambda: "") -> None:
        raise OutputWriteError(f"disk full writing {diag_path(out)} (diagnostics): {ends_at()}")

    writer._diag.append = full  # the results' append goes through, the diagnostics' fails
    with pytest.raises(OutputWriteError, match=r"results end at t = 0\.2 s"):
        writer.write(interval(0.2))
    writer.close(failed_run=True)
    assert (out.read_bytes(), diag_path(out).read_bytes()) == before
    assert read_results(out)[1][-1, 0] == 0.2


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_overwrite_through_a_symbolic_link_writes_its_target_and_keeps_the_link(tmp_path: Path, suffix: str) -> None:
    """The staged files replaced the link itself, leaving its target with the old results (red team)."""
    (tmp_path / "real").mkdir()
    target, link = tmp_path / "real" / f"t{suffix}", tmp_path / f"link{suffix}"
    target.write_bytes(b"an old run's results")
    link.symlink_to(target)
    run_scenario(load(OSCILLATOR), stop=0.5, output=link, inprocess=True, progress=False)
    assert link.is_symlink() and link.resolve() == target
    assert read_results(target)[1][-1, 0] == 0.5
    assert sorted(p.name for p in (tmp_path / "real").iterdir()) == [target.name]  # no staged file left there


def test_results_that_cannot_take_their_names_are_one_error_and_leave_no_staged_file(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The output directory moved during the first interval: the rename into place raised a FileNotFoundError
    traceback, twice (the close tried again; red team)."""
    writer = ResultWriter(tmp_path / "r.csv", [(SignalRef("a", "x"), 1)])

    def moved(src, dst) -> None:  # noqa: ANN001
        raise FileNotFoundError(errno.ENOENT, "No such file or directory")

    monkeypatch.setattr("cosim.results.os.replace", moved)
    t = np.linspace(0.0, 0.1, 3)
    with pytest.raises(OutputWriteError, match=r"^No such file or directory writing .*r\.csv.*; choose another place"):
        writer.write(Interval(t, {"a": {"x": t[:, None]}}, {}, 2, {}))
    writer.close(failed_run=True)
    assert list(tmp_path.iterdir()) == []


def test_units_from_port_declarations_are_stored_with_both_formats(tmp_path: Path) -> None:
    for suffix in (".csv", ".npz"):
        out = tmp_path / f"u{suffix}"
        assert cosim("run", str(OSCILLATOR), "--stop", "0.1", "--output", str(out), "--inprocess").returncode == 0
        assert read_units(out) == {"time": "s", "mass1.u[0]": "m", "mass1.v[0]": "m/s", "mass2.u[0]": "m",
                                   "mass2.v[0]": "m/s"}
    meta = json.loads((tmp_path / "u.csv.meta.json").read_text())
    assert meta["columns"] == read_results(tmp_path / "u.csv")[0]


def test_a_port_name_with_a_comma_reads_back_as_one_column(tmp_path: Path) -> None:
    """A port may be named 'a,b' (a quoted Modelica name in an FMU): the CSV header quotes it, so the file
    reads back with one name per column (it had one more name than columns)."""
    from cosim.coupler.couplings import SignalRef
    from cosim.coupler.relaxation import Interval

    out = tmp_path / "comma.csv"
    writer = ResultWriter(out, [(SignalRef("m", "a,b"), 1), (SignalRef("m", 'say "x"'), 2)])
    t = np.array([0.0, 0.5, 1.0])
    writer.write(Interval(t, {"m": {"a,b": t[:, None] * 2, 'say "x"': np.ones((3, 2))}}, {}, 1, {}))
    writer.close()
    columns, data = read_results(out)
    assert columns == ["time", "m.a,b[0]", 'm.say "x"[0]', 'm.say "x"[1]']
    assert data.shape == (3, 4) and data[:, 1].tolist() == [0.0, 1.0, 2.0]


# --- C. CLI rough edges ------------------------------------------------------------------------------

@pytest.mark.parametrize("stop", ["-1", "0", "nan", "inf"])
def test_stop_must_be_finite_and_after_the_start(tmp_path: Path, stop: str) -> None:
    done = cosim("run", str(OSCILLATOR), f"--stop={stop}", "--output", str(tmp_path / "x.csv"))
    assert done.returncode == 2
    assert done.stderr.splitlines() == [f"cosim: --stop must be a finite time after the scenario's start (0 s), "
                                        f"got {float(stop):g}"]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("where", ["under_a_file", "a_directory"])
def test_unwritable_output_is_one_line_naming_it(tmp_path: Path, where: str) -> None:
    (tmp_path / "file").write_text("")
    out = tmp_path / "file" / "x.csv" if where == "under_a_file" else tmp_path
    done = cosim("run", str(OSCILLATOR), "--stop", "0.1", "--output", str(out))
    assert done.returncode == 2
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and str(out) in lines[0] and "--output" in lines[0], lines


def test_listen_port_in_use_is_one_line_naming_the_port(tmp_path: Path) -> None:
    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen(1)
        port = held.getsockname()[1]
        done = cosim("run", str(OSCILLATOR), "--stop", "0.1", "--output", str(tmp_path / "x.csv"),
                     "--listen", f"tcp/127.0.0.1:{port}")
    assert done.returncode == 2
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and f"port {port} is already in use" in lines[0] and "pick another port" in lines[0]


def test_describe_into_a_closed_pipe_exits_quietly() -> None:
    read, write = os.pipe()
    os.close(read)  # like `| head -1` once head has gone
    try:
        done = subprocess.run([*COSIM, "describe", str(OSCILLATOR)], stdout=write, stderr=subprocess.PIPE,
                              text=True, timeout=60, env=ENV)
    finally:
        os.close(write)
    assert done.returncode == 141 and done.stderr == ""


def test_version() -> None:
    done = cosim("--version")
    assert done.returncode == 0 and done.stdout.strip() == f"cosim {__version__} (protocol 1)"


def test_a_signal_after_the_command_is_done_does_not_change_its_exit_status(tmp_path: Path) -> None:
    """A SIGTERM in the last milliseconds of a finished run (after its summary, as the interpreter exits) killed it:
    rc -15 for a run whose files were whole (red team). The command's entry point leaves no signal to act then."""
    script = ("import os, signal, sys\nfrom cosim.cli import entry\n"
              f"sys.argv = ['cosim', 'run', {str(OSCILLATOR)!r}, '--stop', '0.1', '--inprocess', '--quiet', "
              f"'--output', {str(tmp_path / 'x.csv')!r}]\n"
              "status = entry()\nfor s in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):\n"
              "    os.kill(os.getpid(), s)\nprint('exiting with', status)\nsys.exit(status)\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120, env=ENV)
    assert done.returncode == 0 and done.stdout.splitlines()[-1] == "exiting with 0", (done.returncode, done.stderr)


# sends the signal to itself as the command starts loading cosim.cli (its ~0.2 s of imports), or as it builds
# its argument parser, then runs the command
_SIGNAL_WHILE_STARTING = """import importlib.abc, os, signal, sys
class Hook(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name == "cosim.cli":
            os.kill(os.getpid(), signal.{signal})
signal.signal(signal.{signal}, signal.SIG_IGN if {ignored} else signal.SIG_DFL)  # (not as the suite was started)
if "{when}" == "loading":
    sys.meta_path.insert(0, Hook())
else:
    import cosim.cli
    build = cosim.cli.build_parser
    def build_parser():
        os.kill(os.getpid(), signal.{signal})
        return build()
    cosim.cli.build_parser = build_parser
import cosim.command
sys.argv = ["cosim", "--version"]
sys.exit(cosim.command.main())
"""


@pytest.mark.parametrize("when", ["loading", "parsing"])
@pytest.mark.parametrize("name", ["SIGINT", "SIGTERM", "SIGHUP"])  # (SIGHUP ended it silently: durability probe)
def test_a_signal_while_the_command_starts_ends_it_in_one_line(name: str, when: str) -> None:
    """Ctrl-C in the first 0.2 s of `cosim` printed a KeyboardInterrupt traceback through importlib (a SIGTERM
    killed it, rc -15): one line and 128 + the signal, until the command has read its arguments."""
    script = _SIGNAL_WHILE_STARTING.format(signal=name, ignored=False, when=when)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60, env=ENV)
    number = getattr(signal, name)
    assert (done.returncode, done.stdout) == (128 + number, ""), (done.returncode, done.stdout, done.stderr)
    assert done.stderr == f"cosim: {name} while starting; nothing was run\n"


def test_a_signal_while_the_command_loads_with_its_stderr_gone_still_ends_it_so() -> None:
    """Its line cannot be written (the reader of stderr went away): the exit status is still 143, not 1."""
    read, write = os.pipe()
    os.close(read)
    try:
        done = subprocess.run([sys.executable, "-c", _SIGNAL_WHILE_STARTING.format(
            signal="SIGTERM", ignored=False, when="loading")], stdout=subprocess.PIPE, stderr=write, timeout=60,
            env=ENV)
    finally:
        os.close(write)
    assert done.returncode == 128 + signal.SIGTERM


def test_a_signal_the_parent_ignored_stays_ignored_while_the_command_loads() -> None:
    """A background job's SIGINT is ignored from the start: the command must not start answering it."""
    script = _SIGNAL_WHILE_STARTING.format(signal="SIGINT", ignored=True, when="loading")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60, env=ENV)
    assert (done.returncode, done.stdout.strip()) == (0, f"cosim {__version__} (protocol 1)"), done.stderr


def test_progress_on_a_terminal_shows_time_rate_and_time_left_and_ends_at_100(tmp_path: Path) -> None:
    master, slave = pty.openpty()
    proc = subprocess.Popen([*COSIM, "run", str(OSCILLATOR), "--stop", "2", "--inprocess", "--output",
                             str(tmp_path / "p.csv")], stdout=subprocess.PIPE, stderr=slave, env=ENV)
    os.close(slave)
    chunks: list[bytes] = []

    def drain() -> None:
        while True:
            try:
                data = os.read(master, 4096)
            except OSError:  # EIO: every writer of the terminal has closed it
                return
            if not data:
                return
            chunks.append(data)

    reader = threading.Thread(target=drain, daemon=True)
    reader.start()
    try:
        proc.communicate(timeout=120)
        reader.join(30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        os.close(master)
    assert proc.returncode == 0
    text = b"".join(chunks).decode().replace("\r\n", "\n")  # the terminal turns \n into \r\n
    frames = [f.strip() for f in text.replace("\x1b[K", "").split("\r")]
    first, last = frames[1], frames[-1]
    assert "t = 0.05 / 2 s" in first and "x real time" in first and "left" in first, first
    assert last.startswith("100.0%  t = 2 / 2 s") and "done in" in last, last


def test_progress_is_silent_when_stderr_is_not_a_terminal(tmp_path: Path) -> None:
    done = cosim("run", str(OSCILLATOR), "--stop", "2", "--inprocess", "--output", str(tmp_path / "q.csv"))
    assert done.returncode == 0 and done.stderr == ""


@pytest.mark.parametrize("rows", [0, 1])
def test_plot_of_an_empty_or_one_row_result_is_a_clear_error(tmp_path: Path, rows: int) -> None:
    pytest.importorskip("matplotlib")
    path = tmp_path / "r.csv"
    path.write_text("time,m.x[0]\n" + "0.0,1.0\n" * rows)
    done = cosim("plot", str(path), "--out", str(tmp_path / "png"))
    assert done.returncode == 2
    expected = "no samples" if rows == 0 else "only one sample (t = 0): nothing to plot against time"
    assert done.stderr.splitlines() == [f"cosim plot: {path}: {expected}" + (
        " (the run stopped before its first interval was committed)" if rows == 0 else "")]


def test_a_signal_during_an_interval_write_waits_for_the_whole_interval(tmp_path: Path,
                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    from cosim import interrupt
    from cosim.coupler.couplings import SignalRef
    from cosim.coupler.relaxation import Interval
    from cosim.results import ResultWriter

    out = tmp_path / "w.csv"
    writer = ResultWriter(out, [(SignalRef("m", "x"), 1)], {"m.x": "m"})
    real_append = AppendFile.append

    def signalled_append(self, data, *args) -> None:  # SIGTERM arrives between the rows and the diagnostics
        real_append(self, data, *args)
        if self.what == "results":
            os.kill(os.getpid(), signal.SIGTERM)

    monkeypatch.setattr(AppendFile, "append", signalled_append)
    t = np.linspace(0.0, 1.0, 5)
    with interrupt.handling():
        with pytest.raises(interrupt.Interrupted) as caught:
            writer.write(Interval(t, {"m": {"x": t[:, None] ** 2}}, {}, 2, {}))
        os.kill(os.getpid(), signal.SIGHUP)  # while stopping, a second signal changes nothing
        writer.close()
    assert caught.value.exit_status == 143
    assert read_results(out)[1].shape == (5, 2) and len(diag_rows(out.with_name("w.csv.diag.csv"))) == 1


def test_an_npz_that_cannot_be_built_keeps_its_stream_and_says_how_to_recover(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from cosim import results
    from cosim.coupler.couplings import SignalRef
    from cosim.coupler.relaxation import Interval

    out = tmp_path / "w.npz"
    writer = results.ResultWriter(out, [(SignalRef("m", "x"), 1)], {"m.x": "m"})
    t = np.linspace(0.0, 1.0, 5)
    writer.write(Interval(t, {"m": {"x": t[:, None] ** 2}}, {}, 2, {}))

    def full(*args) -> None:
        raise OutputWriteError(f"disk full writing {out}; free space or choose another place, then run again")

    monkeypatch.setattr(results, "write_npz", full)
    with pytest.raises(OutputWriteError, match=rf"kept in {stream_path(out)}: `cosim recover {out}`"):
        writer.close()
    monkeypatch.undo()
    assert not out.exists() and stream_path(out).exists() and not out.with_name("w.npz.lock").exists()
    assert "5 samples" in results.recover(out)
    assert read_results(out)[1].shape == (5, 2)


def test_a_signal_between_the_steps_of_a_write_still_writes_the_whole_interval(tmp_path: Path,
                                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """The coordinator writes an interval in steps while it waits (ResultWriter.write_steps); a signal that
    stops the run while a step formats rows must not lose that committed interval: it is written whole, then the
    stop goes on (the steps run outside deferred(), so that the wait is not held up)."""
    import cosim.results as results
    from cosim import interrupt
    from cosim.coupler.couplings import SignalRef
    from cosim.coupler.relaxation import Interval
    from cosim.results import ResultWriter

    out = tmp_path / "s.csv"
    writer = ResultWriter(out, [(SignalRef("m", "x"), 1)], {"m.x": "m"})
    real_fmt, calls = results._fmt, [0]

    def signalled_fmt(row: list) -> str:  # SIGTERM while the sixth row is formatted (the second step)
        calls[0] += 1
        if calls[0] == 6:
            os.kill(os.getpid(), signal.SIGTERM)
        return real_fmt(row)

    monkeypatch.setattr(results, "_fmt", signalled_fmt)
    t = np.linspace(0.0, 1.0, 11)
    with interrupt.handling():
        steps = writer.write_steps(Interval(t, {"m": {"x": t[:, None] ** 2}}, {}, 2, {}))
        with pytest.raises(interrupt.Interrupted):
            for _ in steps:
                pass
        writer.close()
    data = read_results(out)[1]
    assert data.shape == (11, 2) and np.array_equal(data[:, 1], t**2)
    assert len(diag_rows(out.with_name("s.csv.diag.csv"))) == 1


@pytest.mark.parametrize("stopped", [False, True])
def test_a_run_whose_terminal_goes_away_goes_on_and_exits_as_it_ends(tmp_path: Path, stopped: bool) -> None:
    """The terminal closed under a run with SIGHUP ignored (`trap '' HUP`, a job the shell does not hang up): the
    next progress redraw met EIO and the run stopped at t = 138 of 400 with exit 1 (durability probe). It goes on
    and exits 0 at its end; stopped by a SIGTERM meanwhile, 143 (a first fix said 0 there: red team)."""
    master, slave = pty.openpty()
    out = tmp_path / "h.csv"
    stop = "2000" if stopped else "200"
    proc = subprocess.Popen([*COSIM, "run", str(ROOT / "scenarios" / "satellite" / "case1.toml"), "--stop", stop,
                             "--inprocess", "--output", str(out)], stdout=slave, stderr=slave, env=ENV,
                            preexec_fn=as_from_a_terminal)
    os.close(slave)
    try:
        first = os.read(master, 4096)  # the first progress frame: the run is under way
        assert b"real time" in first or b"%" in first, first
        os.close(master)  # the terminal goes away: every later write to it fails with EIO
        master = -1
        if stopped:  # once it has a resume point (1 s was too short for its first on a loaded machine)
            deadline = time.monotonic() + 60.0
            while not resume_path(out).exists() and time.monotonic() < deadline and proc.poll() is None:
                time.sleep(0.05)
            proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=120)
    finally:
        if master >= 0:
            os.close(master)
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    if stopped:
        assert proc.returncode == 128 + signal.SIGTERM and resume_path(out).exists()
    else:
        assert proc.returncode == 0 and out.read_text().splitlines()[-1].startswith("200.0,")


def test_a_signal_while_a_resume_point_is_saved_is_raised_once_it_is_saved(tmp_path: Path, monkeypatch) -> None:
    """A SIGINT while a resume point was written cut the write short: no resume point (at the first checkpoint: nothing
    resumable), and 'stopped at t = 4.8 s' with the files at 5.2 (durability probe)."""
    import cosim.runner as runner

    save, saves = runner.save_resume, []

    def save_under_a_signal(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        saves.append(None)
        if len(saves) == 2:
            os.kill(os.getpid(), signal.SIGINT)  # arrives inside the save
        save(*args, **kwargs)

    monkeypatch.setattr(runner, "save_resume", save_under_a_signal)
    scenario = tmp_path / "osc.toml"
    scenario.write_text(OSCILLATOR.read_text() + "\n[run]\ncheckpoint_every = 10\n")
    out, seen = tmp_path / "s.csv", []
    with pytest.raises(interrupt.Interrupted):
        with interrupt.handling():
            run_scenario(load(scenario), stop=5.0, output=out, inprocess=True, progress=False, log=lambda s: None,
                         on_interval=lambda iv: seen.append(float(iv.t[-1])))
    point = resume.load(resume_path(out)).point
    assert len(saves) == 2 and point.t == pytest.approx(1.0)  # the second checkpoint, at interval 20, is saved
    assert read_results(out)[1][-1, 0] == seen[-1]  # the last committed time said is the files' end


def test_the_rows_a_resume_point_names_are_on_disk_before_it_is_saved(tmp_path: Path, monkeypatch) -> None:
    """The resume point was fsynced, the results and diagnostics it names were not: after a power cut the point could
    name bytes the files lost, and the resume would be refused (durability probe, from the code)."""
    import cosim.runner as runner

    events: list[str] = []
    fsync, save = os.fsync, runner.save_resume

    def fsync_seen(fd: int) -> None:
        events.append(os.readlink(f"/proc/self/fd/{fd}"))
        fsync(fd)

    def save_seen(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        events.append("save")
        save(*args, **kwargs)

    monkeypatch.setattr(os, "fsync", fsync_seen)
    monkeypatch.setattr(runner, "save_resume", save_seen)
    scenario = tmp_path / "osc.toml"
    scenario.write_text(OSCILLATOR.read_text() + "\n[run]\ncheckpoint_every = 10\n")
    out = tmp_path / "s.csv"
    run_scenario(load(scenario), stop=1.0, output=out, inprocess=True, progress=False, log=lambda s: None)
    first = events.index("save")
    assert {str(out), f"{out}.diag.csv"} <= set(events[:first]), events[:first]


def test_a_failed_fsync_stops_the_run_before_a_resume_point_names_those_rows(tmp_path: Path, monkeypatch) -> None:
    """fsync failing with EIO was swallowed and the resume point saved anyway, naming rows a failed fsync may have
    dropped (red team)."""
    fsync = os.fsync

    def failing(fd: int) -> None:
        if os.readlink(f"/proc/self/fd/{fd}").endswith(".csv"):
            raise OSError(errno.EIO, "Input/output error")
        fsync(fd)

    monkeypatch.setattr(os, "fsync", failing)
    scenario = tmp_path / "osc.toml"
    scenario.write_text(OSCILLATOR.read_text() + "\n[run]\ncheckpoint_every = 10\n")
    out = tmp_path / "s.csv"
    with pytest.raises(OutputWriteError, match=r"Input/output error .*\(results, when its rows were made durable\)"):
        run_scenario(load(scenario), stop=1.0, output=out, inprocess=True, progress=False, log=lambda s: None)
    assert not resume_path(out).exists()


def test_an_npz_that_cannot_be_built_at_the_runs_end_is_told_to_recover_not_resume(tmp_path: Path, monkeypatch,
                                                                                     capsys) -> None:
    """Disk full as the NPZ was built from its stream after the last interval: the run said '--resume goes on from
    t = 40 s', which then refused, 'nothing to resume' (a red team). Every interval is in the stream: recover."""
    import cosim.results
    from cosim.cli import main as cosim_main
    from cosim.outputs import OutputWriteError, resume_path

    def full(path, *args):
        raise OutputWriteError(f"disk full writing {path}")

    monkeypatch.setattr(cosim.results, "write_npz", full)
    out = tmp_path / "x.npz"
    sc = tmp_path / "s.toml"  # a resume point every 2 intervals: the last one at the stop
    sc.write_text(OSCILLATOR.read_text() + "\n[run]\ncheckpoint_every = 2\n")
    assert cosim_main(["run", str(sc), "--stop", "0.5", "--output", str(out), "--inprocess", "--quiet"]) == 1
    err = capsys.readouterr().err.splitlines()
    assert err[-1] == (f"cosim: every interval to t = 0.5 s, the run's stop, is in {stream_path(out)} (`cosim recover "
                       f"{out}` builds the NPZ from it): nothing is left to run"), err
    assert not any("--resume" in line for line in err) and not resume_path(out).exists()
    monkeypatch.undo()
    assert cosim_main(["recover", str(out)]) == 0 and out.exists()


def test_a_resume_point_that_cannot_be_saved_does_not_stop_the_run(tmp_path: Path, monkeypatch) -> None:
    """The output directory made immutable mid-run (chattr +i): the results file, open, could still be written, but
    the resume point could not, and the run stopped (a red team). It goes on, said once; the results are whole."""
    import cosim.runner
    from cosim.outputs import OutputWriteError, resume_path
    from cosim.runner import run_scenario
    from cosim.scenario import load, parse

    saved = cosim.runner.save_resume
    calls: list[float] = []

    def refused(path, point):
        calls.append(point.point.t)
        if len(calls) == 1:
            return saved(path, point)  # the first is saved; the directory is locked after it
        raise OutputWriteError(f"Operation not permitted writing {path}; choose another place, then run again")

    base = load(OSCILLATOR)
    sc = parse({**base.raw, "run": {"checkpoint_every": 5}}, base.path)
    run_scenario(sc, stop=0.5, output=tmp_path / "calm.csv", inprocess=True, progress=False)
    monkeypatch.setattr(cosim.runner, "save_resume", refused)
    said: list[str] = []
    run_scenario(sc, stop=0.5, output=tmp_path / "x.csv", inprocess=True, progress=False, log=said.append)
    assert len(calls) == 2 and said == [
        f"cosim: the resume point at t = 0.5 could not be saved (Operation not permitted writing "
        f"{resume_path(tmp_path / 'x.csv')}; choose another place); the run goes on, and an interrupted run goes on "
        "(--resume) from the last point saved, if any"]
    assert (tmp_path / "x.csv").read_bytes() == (tmp_path / "calm.csv").read_bytes()


def test_a_resume_point_that_cannot_be_removed_at_the_end_does_not_fail_a_finished_run(tmp_path: Path,
                                                                                       monkeypatch) -> None:
    """The output directory made immutable after a resume point was saved: the finished run raised PermissionError
    removing it, a traceback and exit 1 for a run whose results were whole (a review)."""
    from cosim.outputs import resume_path
    from cosim.runner import run_scenario
    from cosim.scenario import load, parse

    base = load(OSCILLATOR)
    sc = parse({**base.raw, "run": {"checkpoint_every": 2}}, base.path)
    import cosim.runner

    out = tmp_path / "x.csv"

    class Kept(type(Path())):  # a resume point in a directory that no longer lets it go
        def unlink(self, missing_ok: bool = False) -> None:
            raise PermissionError(1, "Operation not permitted", str(self))

    monkeypatch.setattr(cosim.runner, "resume_path", lambda output: Kept(resume_path(output)))
    said: list[str] = []
    report = run_scenario(sc, stop=0.5, output=out, inprocess=True, progress=False, log=said.append)
    assert report.summary.intervals == 10 and resume_path(out).exists()
    assert said == [f"cosim: {resume_path(out)} could not be removed (Operation not permitted): the run is finished, "
                    "delete it"]
