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


@pytest.mark.parametrize("pause", [2.5, 5.0])
def test_a_paused_coordinator_does_not_call_its_subsims_hung(pause: float) -> None:
    """A pause longer than the deadline: the deadline moves on by it (the subsim was called hung, and a healthy
    process replaced). A pause longer than the query's own timeout (4 s): the reply is lost with the query,
    and the error says the pause was the coordinator's own (it read 'no reply within 60 s', and stopped the run
    instead of replacing the subsim)."""
    proc = subprocess.Popen([sys.executable, "-c", COORDINATOR], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(0.3)
        os.kill(proc.pid, signal.SIGSTOP)
        time.sleep(pause)
        os.kill(proc.pid, signal.SIGCONT)
        out, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGCONT)
            proc.kill()
            proc.wait()
    if pause < 4.0:
        assert proc.returncode == 0 and out.strip() == "done", out
    else:
        assert proc.returncode == 3, out
        assert "this coordinator did not run for" in out and "the query timed out meanwhile" in out, out
