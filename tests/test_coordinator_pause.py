"""A coordinator that does not run for a while (Ctrl-Z, SIGSTOP, a debugger, a paused VM) does not blame its subsims.

The coordinator here is a process of its own, stopped with SIGSTOP and continued with SIGCONT; its subsim (a
child in its own process group) runs on. Each request has a 1 s deadline.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable

import pytest

pytestmark = pytest.mark.zenoh

COORDINATOR = """
import sys, numpy as np
from cosim.contract import SubsimHung
from cosim.launch import Bus
with Bus.open() as bus:
    handle = bus.spawn("subsims.integrator", "worker", quiet=True).handle
    handle.configure({"compute_delay": 0.05})
    handle.deadline = 1.0
    t = np.linspace(0.0, 0.4, 5)
    print("ready", flush=True)
    try:
        for _ in range(60):
            handle.run_interval(t, {"u": np.zeros((5, 1))})
    except SubsimHung as exc:
        print(f"hung: {exc}", flush=True)
        sys.exit(3)
    print("done", flush=True)
"""


def paused(proc: subprocess.Popen, when: Callable[[], None], seconds: float) -> tuple[str, str]:
    """Stop the coordinator ``proc`` for ``seconds`` once ``when()`` returns, and its output once it has ended; it is
    continued and killed if the test fails meanwhile."""
    try:
        when()
        os.kill(proc.pid, signal.SIGSTOP)
        time.sleep(seconds)
        os.kill(proc.pid, signal.SIGCONT)
        return proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGCONT)
            proc.kill()
            proc.wait()


@pytest.mark.parametrize("pause", [2.5, 5.0])
def test_a_paused_coordinator_does_not_call_its_subsims_hung(pause: float) -> None:
    """A pause longer than the deadline: the deadline moves on by it (the subsim was called hung, and a healthy
    process replaced). A pause longer than the query's own timeout (4 s): the reply is lost with the query,
    and the error says the pause was the coordinator's own (it read 'no reply within 60 s', and stopped the run
    instead of replacing the subsim)."""
    proc = subprocess.Popen([sys.executable, "-c", COORDINATOR], stdout=subprocess.PIPE, text=True)

    def ready() -> None:
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(0.3)

    out, _ = paused(proc, ready, pause)
    if pause < 4.0:
        assert proc.returncode == 0 and out.strip() == "done", out
    else:
        assert proc.returncode == 3, out
        assert "this coordinator did not run for" in out and "the query timed out meanwhile" in out, out


@pytest.mark.slow
def test_subsims_that_leave_a_paused_coordinator_use_one_restart_between_them(tmp_path) -> None:
    """A coordinator stopped for longer than its subsims wait for it (the router's 10 s link lease and 2 s): every
    subsim leaves, as it should. Each loss used a restart and was called a death: a 15 s pause stopped a three-subsim
    run with two restarts, its subsims said 'died' (ops probe). Now all of them together use one restart, the lines
    say they left in the coordinator's pause, and the run ends with the results of an undisturbed one."""
    from pathlib import Path

    scenario = Path(__file__).parents[1] / "scenarios" / "oscillator.toml"
    run = [sys.executable, "-m", "cosim.cli", "run", str(scenario), "--stop", "150", "--restarts", "1"]
    clean = subprocess.run([*run, "--output", str(tmp_path / "clean.csv"), "--inprocess"], capture_output=True,
                           text=True, timeout=300)
    assert clean.returncode == 0, clean.stderr
    proc = subprocess.Popen([*run, "--output", str(tmp_path / "paused.csv")], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    diag = tmp_path / "paused.csv.diag.csv"

    def mid_run() -> None:
        deadline = time.monotonic() + 60
        while (not diag.exists() or diag.read_text().count("\n") < 200) and time.monotonic() < deadline:
            time.sleep(0.05)

    _, err = paused(proc, mid_run, 14.0)  # the subsims leave after the link's 10 s lease and 2 s of grace
    assert proc.returncode == 0, err
    # each found gone (it left) or its reply lost in the pause (a request in flight when the pause began), as it falls
    replaced = [line for line in err.splitlines() if "replaced (" in line]
    assert len(replaced) == 2 and all("this coordinator did not run for" in line for line in replaced), err
    assert "replaced (1 of 1)" in replaced[0] and "replaced (the restart of that pause, 1 of 1 used)" in replaced[1]
    assert (tmp_path / "paused.csv").read_bytes() == (tmp_path / "clean.csv").read_bytes()
