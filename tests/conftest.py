"""Markers (registered in pyproject.toml; ``--strict-markers`` is on).

- ``slow``: over ~5 s each on 2 cores (the paper-claim runs, the heavy fuzzers, figure rendering, long co-simulations).
  ``pytest -m "not slow"`` is the inner loop; plain ``pytest`` (CI) runs everything.
- ``zenoh``: starts real processes and talks over the Zenoh bus. Tests that use the ``cosim_bus`` or
  ``spawn_subsim`` fixtures get it here; the others that launch processes carry it explicitly.
- ``paper``: checks a claim or a printed number of one of the papers or reports the subsims come from.
"""

from __future__ import annotations

import subprocess
from collections.abc import Iterator

import pytest

BUS_FIXTURES = {"cosim_bus", "spawn_subsim"}


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if BUS_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.zenoh)


@pytest.fixture
def procs() -> Iterator[list[subprocess.Popen]]:
    """Processes a test starts by hand: killed (if still running) and reaped when the test ends, even on failure."""
    started: list[subprocess.Popen] = []
    yield started
    for p in started:
        if p.poll() is None:
            p.kill()
        p.communicate()
