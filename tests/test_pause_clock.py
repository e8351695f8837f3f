"""A subsim process that stood still for longer than its lease (SIGSTOP, a suspended machine) answers nothing more:
what counts as standing still. (The processes themselves: tests/test_recovery.py, external subsims.)"""

from __future__ import annotations

import pytest

from cosim.protocol.transport import server
from cosim.protocol.transport.server import PauseClock


class Clocks:
    """Wall and CPU time, moved by hand."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.wall = self.cpu = 100.0
        monkeypatch.setattr(server.time, "monotonic", lambda: self.wall)
        monkeypatch.setattr(server.time, "process_time", lambda: self.cpu)

    def advance(self, wall: float, cpu: float = 0.0) -> None:
        self.wall += wall
        self.cpu += cpu


def test_wall_time_past_the_lease_without_cpu_time_is_a_pause_and_stays_one(monkeypatch: pytest.MonkeyPatch) -> None:
    clocks = Clocks(monkeypatch)
    clock = PauseClock(lease=2.0)
    clocks.advance(0.25, 0.01)
    assert clock.stood_still() is None and clock.tick() is None
    clocks.advance(1.9)  # under the lease: a slow tick, not a replaced process
    assert clock.tick() is None
    clocks.advance(2.5, 0.001)  # SIGSTOP for 2.5 s
    assert clock.stood_still() == pytest.approx(2.5)  # asked by a query before the watcher ticks
    assert clock.tick() == pytest.approx(2.5)
    clocks.advance(0.25, 0.01)
    assert clock.stood_still() == pytest.approx(2.75)  # not forgotten at the tick: it answers nothing more


def test_a_process_busy_that_long_is_no_pause(monkeypatch: pytest.MonkeyPatch) -> None:
    """A model in native code holding the GIL for longer than the lease keeps the watcher from ticking, but it runs."""
    clocks = Clocks(monkeypatch)
    clock = PauseClock(lease=2.0)
    clocks.advance(30.0, 29.0)
    assert clock.stood_still() is None and clock.tick() is None
    clocks.advance(30.0, 14.0)  # starved to less than half a core: the link's lease did not hold either
    assert clock.tick() == pytest.approx(30.0)
