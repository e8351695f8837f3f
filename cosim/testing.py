"""Pytest fixtures for integration tests with real subsim processes (a pytest plugin).

Installed with the package (entry point ``pytest11``), so a user's tests can simply write::

    def test_my_subsim(spawn_subsim):
        handle = spawn_subsim("mymodule:Thermal", name="thermal")    # or a package: "mypackage.mysubsim"
        handle.configure({"T0": 300.0})
        ...

Each test gets its own router on a free loopback port and its own run id; every process it
spawned is stopped (shutdown, then SIGTERM, then SIGKILL) even when the test fails.
"""

from __future__ import annotations

import importlib.util
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from cosim.importing import add_search_path, load_model
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
    """Factory: ``spawn_subsim(target, name=None, timeout=60.0, start_timeout=20.0) -> RemoteHandle``.

    ``target`` is a subsim package run as ``python -m target`` (``"subsims.oscillator"``) or any model
    class as ``"module:Class"``, served by ``python -m cosim.serve`` (``"wall_mass:WallMass"``). The
    process starts in the test's working directory, so modules there are found. ``name`` defaults to
    the last part of the module name. ``timeout``: seconds each request may take before it fails as hung (a
    model stuck in ``advance`` fails the test then); ``start_timeout``: seconds the process has to come up (a
    model whose imports are slow). A process that exits before it is up fails the test with its exit status and
    the last line it wrote on stderr (its traceback's last line, say); what a subsim prints reaches the test's
    stderr (``capfd`` reads it)."""

    def spawn(target: str, name: str | None = None, timeout: float = 60.0,
              start_timeout: float = 20.0) -> RemoteHandle:
        _check_importable(target)
        module, _, cls = target.partition(":")
        name = name or module.rsplit(".", 1)[-1]
        return cosim_bus.spawn(module, name, timeout=timeout, wait=start_timeout, model=target if cls else None).handle

    return spawn


def _check_importable(target: str) -> None:
    """A target that cannot be imported, said here in one line (the process would only exit with code 2, its
    reason in the test's captured stderr). Like the process, this looks in the working directory too."""
    add_search_path(Path.cwd())
    try:
        if ":" in target:
            load_model(target)
        elif importlib.util.find_spec(target) is None:
            raise ValueError(f"no module named {target!r}")
    except (ValueError, ImportError) as exc:
        raise ValueError(f"spawn_subsim({target!r}): {exc}") from None
