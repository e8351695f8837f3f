"""Pytest fixtures for integration tests with real subsim processes (a pytest plugin).

Installed with the package (entry point ``pytest11``), so a user's tests can simply write::

    def test_my_subsim(spawn_subsim):
        handle = spawn_subsim("mypackage.mysubsim", name="thermal")
        handle.configure({"T0": 300.0})
        ...

Each test gets its own router on a free loopback port and its own run id; every process it
spawned is stopped (shutdown, then SIGTERM, then SIGKILL) even when the test fails.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest

from cosim.launch import Bus
from cosim.protocol.transport.client import RemoteHandle


@pytest.fixture
def cosim_bus() -> Iterator[Bus]:
    """A coordinator router on ``tcp/127.0.0.1:<free port>`` with a unique run id."""
    bus = Bus.open()
    try:
        yield bus
    finally:
        bus.close()


@pytest.fixture
def spawn_subsim(cosim_bus: Bus) -> Callable[..., RemoteHandle]:
    """Factory: ``spawn_subsim(module, name=None, timeout=60.0) -> RemoteHandle``."""

    def spawn(module: str, name: str | None = None, timeout: float = 60.0) -> RemoteHandle:
        return cosim_bus.spawn(module, name or module.rsplit(".", 1)[-1], timeout=timeout).handle

    return spawn
