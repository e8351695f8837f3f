"""python -m cosim.conformance: a shipped subsim passes; a subsim with protocol bugs fails, naming them."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from cosim.launch import subsim_command

pytestmark = [pytest.mark.slow]  # the inner loop: pytest -m "not slow"

ROOT = Path(__file__).parents[1]

# A subsim with two protocol bugs, served by hand (as a subsim in another language would be): it
# compares the start time with float equality (so t[0] = -0.0 passes for 0.0), and rollback keeps the trial.
BROKEN = '''
import sys

import numpy as np
import zenoh

from cosim.protocol.security import ClientSecurity
from cosim.protocol.transport.server import CommandServer
from cosim.protocol.transport.session import client_config
from cosim.runtime import Runtime
from subsims.integrator.subsim import Integrator


class BrokenRuntime(Runtime):
    def run_interval(self, t, inputs, interp="linear", commit=False):
        t = np.array(t, dtype=float)
        t[0] += 0.0  # -0.0 + 0.0 is 0.0: as if the times were compared with ==
        return super().run_interval(t, inputs, interp, commit)

    def rollback(self, to_time=None):
        trial = self.trial
        result = super().rollback(to_time)
        if to_time is None:
            self.trial = trial
        return result


endpoint, run, name = sys.argv[1:4]
security = ClientSecurity.from_env()  # the key and login the checker printed, as any subsim reads them
session = zenoh.open(client_config(endpoint, 10.0, security=security))
server = CommandServer(session, run, BrokenRuntime(Integrator, name=name), key=security.key)
try:
    server.serve()
finally:
    server.close()
    session.close()
'''



def check(procs: list, name: str, start_subsim: list[str], *options: str, env: dict | None = None) -> tuple[int, str]:
    """Run the checker on a free port, start the subsim once it listens; (exit code, stdout)."""
    checker = subprocess.Popen([sys.executable, "-m", "cosim.conformance", "tcp/127.0.0.1:0", "conf-run", name,
                                "--wait", "30", *options], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    procs.append(checker)
    first, second = checker.stderr.readline(), checker.stderr.readline()
    assert "listening on tcp/127.0.0.1:" in first, first
    endpoint = first.split("listening on ")[1].split(",")[0]
    secrets = dict(word.split("=", 1) for word in second.split(": ")[-1].split())  # the subsim's key and login
    assert set(secrets) == {"COSIM_SECRET", "COSIM_ZENOH_AUTH"}, second
    procs.append(subprocess.Popen([arg.replace("ENDPOINT", endpoint) for arg in start_subsim],
                                  env={**(env or os.environ), **secrets}, stderr=subprocess.DEVNULL))
    out, err = checker.communicate(timeout=300)
    assert f"{name}: " in err and "violation(s)" in err, err
    return checker.returncode, out


@pytest.mark.parametrize(("package", "params"), [("subsims.oscillator", "{}"), ("subsims.integrator", '{"size": 3}')])
def test_a_shipped_subsim_conforms(procs: list, package: str, params: str) -> None:
    code, out = check(procs, "shipped", subsim_command(package, "ENDPOINT", "conf-run", "shipped"), "--params", params)
    assert (code, out) == (0, "")
    assert procs[1].wait(timeout=30) == 0  # the checker's shutdown ended it


def test_a_broken_subsim_fails_naming_each_violation(tmp_path: Path, procs: list) -> None:
    (tmp_path / "broken_subsim.py").write_text(BROKEN)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(ROOT)])}
    code, out = check(procs, "broken", [sys.executable, "-m", "broken_subsim", "ENDPOINT", "conf-run", "broken"],
                      env=env)
    assert code == 1
    assert out.splitlines() == [
        "FAIL t[0] = -0.0 for a committed 0.0: accepted; expected an error ['time_mismatch']",
        "FAIL commit after rollback: accepted; expected an error ['no_trial']",
    ]


def test_no_subsim_appearing_is_exit_code_2() -> None:
    done = subprocess.run([sys.executable, "-m", "cosim.conformance", "tcp/127.0.0.1:0", "conf-run", "nobody",
                           "--wait", "0.5"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "no process appeared within 0.5 s" in done.stderr
