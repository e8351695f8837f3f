"""python -m cosim.conformance: a shipped subsim passes; a subsim with protocol bugs fails, naming them."""

from __future__ import annotations

import os
import subprocess
import sys
import time
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

# The state model's bugs of an implementation written from the text: configure and set_state keep the history,
# configure leaves an earlier trial committable, and row 0 of run_interval is not the output at t[0].
FORGETFUL = BROKEN.split("class BrokenRuntime")[0] + '''
class BrokenRuntime(Runtime):
    def configure(self, params, t0=0.0):
        kept, trial = list(self.history), self.trial
        result = super().configure(params, t0)
        self.history.extend(kept)
        if trial is not None:
            self.trial = trial._replace(epoch=self.epoch)
        return result

    def set_state(self, time, state):
        kept = list(self.history)
        result = super().set_state(time, state)
        self.history.extend(kept)
        return result

    def run_interval(self, t, inputs, interp="linear", commit=False):
        result = super().run_interval(t, inputs, interp, commit)
        result["outputs"] = {p: np.vstack([v[:1] + 1.0, v[1:]]) for p, v in result["outputs"].items()}
        return result
''' + "\n\nendpoint" + BROKEN.split("\n\nendpoint")[1]


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


@pytest.mark.parametrize(("package", "params"), [
    ("subsims.oscillator", "{}"), ("subsims.integrator", '{"size": 3}'),
    ("subsims.integrator", '{"size": 100000}'),  # a default request cap of 32 GB: not sent (a MemoryError was)
])
def test_a_shipped_subsim_conforms(procs: list, package: str, params: str) -> None:
    code, out = check(procs, "shipped", subsim_command(package, "ENDPOINT", "conf-run", "shipped"), "--params", params)
    assert (code, out) == (0, "")
    assert procs[1].wait(timeout=30) == 0  # the checker's shutdown ended it


def test_ending_by_the_coordinator_leaving(procs: list) -> None:
    """``--ending coordinator``: the checker withdraws its liveliness token instead of sending shutdown; a
    conforming subsim stops serving (and the reference process exits 0)."""
    code, out = check(procs, "left", subsim_command("subsims.integrator", "ENDPOINT", "conf-run", "left"),
                      "--ending", "coordinator")
    assert (code, out) == (0, "")
    assert procs[1].wait(timeout=30) == 0


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


def test_a_subsim_that_keeps_its_history_or_shifts_row_0_fails_naming_each_violation(
        tmp_path: Path, procs: list) -> None:
    (tmp_path / "forgetful_subsim.py").write_text(FORGETFUL)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(ROOT)])}
    code, out = check(procs, "forgetful", [sys.executable, "-m", "forgetful_subsim", "ENDPOINT", "conf-run",
                                           "forgetful"], env=env)
    assert code == 1
    lines = out.splitlines()
    assert lines[0].startswith("FAIL run_interval: output y: row 0 [1.0] is not the output at the committed time"), out
    assert lines[1:] == [
        "FAIL set_state: status.history is 1 after set_state, expected 0 (it clears the history)",
        "FAIL rollback after set_state to a time committed before it: accepted; expected an error ['not_in_history']",
        "FAIL commit of a trial made before configure: accepted; expected an error ['stale_trial']",
        "FAIL configure: status.history is 2 after configure, expected 0 (it clears the history)",
        "FAIL rollback after configure to a time committed before it: accepted; expected an error ['not_in_history']",
    ], out


def test_the_seal_checks_fail_a_subsim_that_answers_every_frame(cosim_bus) -> None:
    """Section 4.1 and 1, which a subsim could skip and still pass every command check: a responder that answers
    frames sealed with no key or another key, replays, seqs far below the window, wildcard queries and an
    oversized body fails each check, by name."""
    import zenoh

    from cosim.conformance import Checker, _check_seals
    from cosim.protocol.keys import rpc_key
    from cosim.protocol.messages import seal_reply
    from cosim.protocol.security import ClientSecurity, zenoh_login
    from cosim.protocol.service import answer
    from cosim.protocol.transport.session import client_config
    from cosim.runtime import Runtime
    from subsims.integrator.subsim import Integrator

    runtime, key = Runtime(Integrator, name="lax"), cosim_bus.key("lax")
    runtime.configure({})

    def respond(query: zenoh.Query) -> None:
        frame = query.payload.to_bytes() if query.payload is not None else b""
        seq = int.from_bytes(frame[-40:-32], "big") if len(frame) >= 40 else 0
        with query:
            query.reply(query.key_expr, seal_reply(key, seq, answer(runtime, frame[:-40])))

    lax = zenoh.open(client_config(cosim_bus.endpoint, 2.0, security=ClientSecurity(
        key, zenoh_login(cosim_bus.secret, cosim_bus.run))))
    try:
        queryable = lax.declare_queryable(rpc_key(cosim_bus.run, "lax"), respond)
        deadline = time.monotonic() + 30  # until the router knows the queryable (declarations propagate late)
        while not cosim_bus.query(rpc_key(cosim_bus.run, "lax"), b"ping", 1.0) and time.monotonic() < deadline:
            time.sleep(0.05)
        c = Checker(lambda payload: None, "lax")
        c.description = runtime.describe()
        _check_seals(c, cosim_bus, "lax", wait=3.0)  # each of them is answered, however loaded the machine
        queryable.undeclare()
    finally:
        lax.close()
    assert [v.split(" was answered")[0].split(" got ")[0] for v in c.violations] == [
        "FAIL seal: an unsealed frame",
        "FAIL seal: a frame sealed with another key",
        "FAIL seal: a seq 2048 below the highest accepted",
        "FAIL seal: a replayed frame (the same seq again)",
        "FAIL seal: a query on cosim/" + cosim_bus.run + "/*/rpc",
        "FAIL request cap: a 1048577-byte body (over the default cap 1048576, section 3)",
    ], c.violations


def test_no_subsim_appearing_is_exit_code_2() -> None:
    done = subprocess.run([sys.executable, "-m", "cosim.conformance", "tcp/127.0.0.1:0", "conf-run", "nobody",
                           "--wait", "0.5"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "no process appeared within 0.5 s" in done.stderr
