"""How the coordinator waits for a reply: it blocks (no polling), a slow reply is the same result, the timeout holds."""

from __future__ import annotations

import os
import signal
import time

import numpy as np
import pytest
import zenoh

from cosim.contract import SubsimDied, SubsimError
from cosim.handles import InProcessHandle
from cosim.launch import Bus
from cosim.protocol.transport.client import RemoteHandle, _Pending
from subsims.integrator.subsim import Integrator

TIMES = np.linspace(0.0, 0.4, 5)
INPUTS = {"u": np.arange(10.0).reshape(5, 2)}


def test_a_waiting_coordinator_blocks_instead_of_spinning(cosim_bus: Bus) -> None:
    """While a subsim computes for 0.5 s the coordinator's thread sleeps: it uses a small fraction of that CPU
    (a polling wait would use all of it, taking a core from the subsims)."""
    remote = cosim_bus.spawn("subsims.integrator", "busy").handle
    remote.configure({"size": 2, "compute_delay": 0.5})
    cpu = time.thread_time()
    remote.run_interval(TIMES, INPUTS)
    assert time.thread_time() - cpu < 0.1


def test_a_reply_slower_than_the_polling_budget_is_the_same_result(cosim_bus: Bus) -> None:
    params = {"size": 2, "y0": [1.0, -2.0], "compute_delay": 0.05}
    remote = cosim_bus.spawn("subsims.integrator", "slow").handle
    local = InProcessHandle(Integrator())
    for handle in (remote, local):
        handle.configure(params)
    got, want = remote.run_interval(TIMES, INPUTS), local.run_interval(TIMES, INPUTS)
    np.testing.assert_array_equal(got.outputs["y"], want.outputs["y"])
    assert got.end_time == want.end_time


@pytest.mark.parametrize("changed", [False, True], ids=["declared", "changed-later"])
def test_a_request_longer_than_the_timeout_fails_with_timeout(cosim_bus: Bus, changed: bool) -> None:
    proc = cosim_bus.spawn("subsims.integrator", f"sleepy-{int(changed)}", timeout=60.0 if changed else 0.5)
    if changed:
        proc.handle.timeout = 0.5  # this request no longer goes through the querier declared with 60 s
    proc.handle.configure({"size": 2, "compute_delay": 3.0})
    start = time.monotonic()
    with pytest.raises(SubsimError) as err:
        proc.handle.run_interval(TIMES, INPUTS)
    assert err.value.code == "timeout" and err.value.subsim == f"sleepy-{int(changed)}"
    assert time.monotonic() - start < 2.5  # the timeout fired; the computation (3 s) had not finished


def test_a_query_that_zenoh_ends_empty_after_its_timeout_is_a_timeout(cosim_bus: Bus) -> None:
    """Under load zenoh's own timeout can end a query with no reply at all, not even its timeout error: with the
    process alive that is a timeout, not a missing process; the same empty ending before the timeout is not."""
    handle = RemoteHandle(cosim_bus.session, cosim_bus.run, "quiet", timeout=0.5)
    try:
        handle._alive.set()  # as if its liveliness token had been seen
        ended = _Pending(iter(()), zenoh.CancellationToken(), None, time.monotonic() - 0.51, time.monotonic() - 0.01)
        err = handle._no_reply("status", ended, None, 0)
        assert type(err) is SubsimError and err.code == "timeout" and "0.5 s" in err.message
        early = _Pending(iter(()), zenoh.CancellationToken(), None, time.monotonic(), time.monotonic() + 60.0)
        err = handle._no_reply("status", early, None, 0)
        assert isinstance(err, SubsimDied) and err.code == "no_responder"
    finally:
        handle.close()


def test_looking_for_the_reply_never_blocks_and_the_reply_it_finds_is_the_result(cosim_bus: Bus) -> None:
    """replied() is what the coordinator asks between steps of writing results: False while the subsim
    computes, True once the reply is in; the reply it took from the channel is the one the wait returns."""
    params = {"size": 2, "y0": [1.0, -2.0], "compute_delay": 0.3}
    remote = cosim_bus.spawn("subsims.integrator", "looked").handle
    local = InProcessHandle(Integrator())
    for handle in (remote, local):
        handle.configure(params)
    assert remote.replied()  # nothing in flight
    want = local.run_interval(TIMES, INPUTS)
    for deadline in (None, 1.0):  # session.get, then the declared querier (requests with a short deadline)
        remote.deadline = deadline
        wait = remote.start_run_interval(TIMES, INPUTS)
        started, looks = time.perf_counter(), 0
        while not remote.replied():
            looks += 1
            time.sleep(0.01)
        assert time.perf_counter() - started >= 0.25 and looks >= 10  # said no while the subsim computed
        np.testing.assert_array_equal(wait().outputs["y"], want.outputs["y"])
    # a query that ends without a reply is "replied" too (waiting would not block), and fails when collected
    pending = _Pending(cosim_bus.session.get("cosim/nobody/serves/this", timeout=0.2), zenoh.CancellationToken(),
                       None, 0.0, 0.0)
    deadline = time.monotonic() + 2.0
    while not pending.ready():
        assert time.monotonic() < deadline
        time.sleep(0.01)
    assert pending.ended and list(pending.all_replies()) == []


def test_a_late_delete_of_a_predecessors_token_is_not_the_subsims_death(cosim_bus: Bus) -> None:
    """A process killed to be replaced loses its liveliness token when the router notices, which can be after
    its successor's token came: the successor's handle then saw a DELETE and called it gone (a replacement
    'died' while being restored, in CI). A token still on the key means the subsim is served."""
    proc = cosim_bus.spawn("subsims.integrator", "successor")
    handle = proc.handle

    class Late:
        kind = zenoh.SampleKind.DELETE

    handle._on_liveliness(Late())  # the predecessor's token, removed late
    assert handle.status()["name"] == "successor" and handle.alive
    os.kill(proc.popen.pid, signal.SIGKILL)  # and a real death is still one
    proc.popen.wait()
    deadline = time.monotonic() + 10
    while handle.alive and time.monotonic() < deadline:
        time.sleep(0.01)
    with pytest.raises(SubsimDied):
        handle.status()
