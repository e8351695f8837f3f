"""How the coordinator waits for a reply: polls briefly, then blocks; the request timeout holds either way."""

from __future__ import annotations

import time

import numpy as np
import pytest
import zenoh

from cosim import handles
from cosim.contract import SubsimError
from cosim.handles import InProcessHandle
from cosim.launch import Bus
from subsims.integrator.subsim import Integrator

TIMES = np.linspace(0.0, 0.4, 5)
INPUTS = {"u": np.arange(10.0).reshape(5, 2)}


class _ScriptedReplies:
    """A reply channel that is empty for ``empty_polls`` polls, then holds ``items``, then is closed."""

    def __init__(self, items: list, empty_polls: int) -> None:
        self.items, self.empty_polls, self.polls = list(items), empty_polls, 0

    def try_recv(self) -> object:
        self.polls += 1
        if self.polls <= self.empty_polls:
            return None
        if self.items:
            return self.items.pop(0)
        raise zenoh.ZError("channel is empty and closed")

    def __iter__(self):
        return iter(self.items)


def test_a_reply_that_arrives_while_polling_is_taken(monkeypatch: pytest.MonkeyPatch) -> None:
    # a budget no scheduler delay can use up (the real 2 ms ran out under load before the 4th poll)
    monkeypatch.setattr(handles, "POLL_SECONDS", 3600.0)
    replies = _ScriptedReplies(["reply"], empty_polls=3)
    assert handles._first_reply(replies) == "reply"
    assert replies.polls == 4


def test_a_closed_channel_means_no_reply() -> None:
    assert handles._first_reply(_ScriptedReplies([], empty_polls=2)) is None


def test_after_the_polling_budget_the_wait_blocks(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(handles, "POLL_SECONDS", 0.0)
    replies = _ScriptedReplies(["late reply"], empty_polls=10**9)  # polling would never see it
    assert handles._first_reply(replies) == "late reply"
    assert replies.polls == 0


def test_a_reply_slower_than_the_polling_budget_is_the_same_result(cosim_bus: Bus) -> None:
    params = {"size": 2, "y0": [1.0, -2.0], "compute_delay": 20 * handles.POLL_SECONDS}
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
