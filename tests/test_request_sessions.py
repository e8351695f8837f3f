"""A remote handle sends its requests from a client session of its own and replaces it every
``renew_every`` requests (closing a session is the only way to free the tasks zenoh keeps per query
until its timeout); never while one of its requests is still in flight."""

from __future__ import annotations

import numpy as np

from cosim.handles import InProcessHandle
from cosim.launch import Bus
from cosim.protocol.transport.client import RemoteHandle
from subsims.integrator.subsim import Integrator

TIMES = np.linspace(0.0, 0.4, 5)
INPUTS = {"u": np.arange(10.0).reshape(5, 2)}


def second_handle(bus: Bus, name: str, renew_every: int) -> RemoteHandle:
    handle = RemoteHandle(bus.session, bus.run, name, timeout=30.0, requests=bus.open_requests,
                          renew_every=renew_every)
    handle.wait_ready(10.0)
    return handle


def test_the_request_session_is_replaced_every_renew_every_requests(cosim_bus: Bus) -> None:
    cosim_bus.spawn("subsims.integrator", "renewed")
    handle = second_handle(cosim_bus, "renewed", renew_every=3)
    try:
        sessions = []
        for _ in range(10):
            assert handle.status()["name"] == "renewed"
            sessions.append(str(handle._requests.zid()))
        # requests 1-3 from the first session, 4-6 from the second, 7-9 the third, 10 the fourth
        firsts = [sessions[i] for i in (0, 3, 6, 9)]
        assert sessions == [s for s in firsts for _ in range(3)][:10]
        assert len(set(firsts)) == 4
        assert str(cosim_bus.session.zid()) not in firsts  # not the router's session
    finally:
        handle.close()


def test_no_renewal_while_a_request_is_in_flight(cosim_bus: Bus) -> None:
    """With renew_every=1 every request would renew; the second one, sent while the first is computing, must
    not close the session the first waits on (its reply would be lost: SubsimDied)."""
    params = {"size": 2, "y0": [1.0, -2.0], "compute_delay": 0.3}
    cosim_bus.spawn("subsims.integrator", "busy").handle.configure(params)
    handle = second_handle(cosim_bus, "busy", renew_every=1)
    local = InProcessHandle(Integrator())
    local.configure(params)
    try:
        first = handle.start_run_interval(TIMES, INPUTS)
        second = handle.start_run_interval(TIMES, INPUTS)  # the same trial again, from the same committed state
        want = local.run_interval(TIMES, INPUTS).outputs["y"]
        np.testing.assert_array_equal(first().outputs["y"], want)
        np.testing.assert_array_equal(second().outputs["y"], want)
        before = str(handle._requests.zid())
        handle.status()  # nothing in flight now: this one renews
        assert str(handle._requests.zid()) != before
    finally:
        handle.close()


def test_after_close_a_last_request_still_goes_out(cosim_bus: Bus) -> None:
    """Closing a handle closes its own session; ``SubsimProcess.stop`` still sends ``shutdown`` through it."""
    proc = cosim_bus.spawn("subsims.integrator", "closing")
    proc.handle.status()
    proc.handle.close()
    assert proc.handle._requests is None
    proc.handle.shutdown()
    assert proc.popen.wait(10) == 0
