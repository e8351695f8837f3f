"""The relay that copies a launched subsim's stderr to the coordinator's and keeps its end (cosim.console)."""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Iterator

import pytest

from cosim import console
from cosim.console import StderrRelay


@pytest.fixture
def pipe() -> Iterator[tuple[StderrRelay, int]]:
    """A relay reading a pipe, and the pipe's write end (the 'child')."""
    read, write = os.pipe()
    relay = StderrRelay(os.fdopen(read, "rb"))
    try:
        yield relay, write
    finally:
        try:
            os.close(write)
        except OSError:
            pass
        relay.finish(1.0)


def test_it_copies_everything_and_keeps_the_last_line(pipe, capfd) -> None:
    relay, write = pipe
    os.write(write, b"mass1: a print\nTraceback (most recent call last):\n  ...\nRuntimeError: no calibration\n\n")
    os.close(write)
    assert relay.last_line() == "RuntimeError: no calibration"
    assert capfd.readouterr().err == ("mass1: a print\nTraceback (most recent call last):\n  ...\n"
                                      "RuntimeError: no calibration\n\n")


def test_a_line_written_long_before_the_end_is_not_given_as_why_it_ended(pipe) -> None:
    """A process that exits silently (os._exit(3)) quoted 'mass1: serving run ...' from its start (red team)."""
    relay, write = pipe
    relay.RECENT = 0.05
    os.write(write, b"mass1: serving run r (pid 1)\n")
    time.sleep(0.3)
    os.close(write)
    assert relay.last_line() is None


def test_a_pipe_held_open_by_another_process_is_given_up(pipe) -> None:
    """A subsim that left a child holding its stderr kept a relay thread and a pipe per restart (red team)."""
    relay, _ = pipe  # the write end stays open, as a grandchild's would
    before = threading.active_count()
    relay.finish(0.1)
    deadline = time.monotonic() + 5.0
    while threading.active_count() >= before and time.monotonic() < deadline:
        time.sleep(0.05)
    assert threading.active_count() == before - 1


def test_without_a_stderr_of_its_own_it_writes_nowhere(capfd, monkeypatch: pytest.MonkeyPatch) -> None:
    """A coordinator started with stderr closed (2>&-) has descriptor 2 reused by its own files (the run's lock):
    its subsims' lines went into that file (red team)."""
    monkeypatch.setattr(console.sys, "__stderr__", None)
    monkeypatch.setattr(console.sys, "stderr", None)  # (as Python starts without descriptor 2: both None)
    read, write = os.pipe()
    relay = StderrRelay(os.fdopen(read, "rb"))
    os.write(write, b"into the lock file?\n")
    os.close(write)
    assert relay.last_line() == "into the lock file?"
    assert capfd.readouterr().err == ""
    assert sys.__stderr__ is None



@pytest.mark.parametrize("over", [False, True])
def test_a_long_last_line_is_quoted_whole_up_to_its_cap_and_a_cut_is_said(pipe, over: bool) -> None:
    """A subsim's own 'cannot reach the coordinator ... (something listens there, but its login/TLS refused ours ...)'
    line was quoted cut at 200 characters, mid-word, with nothing saying so (a multi-host probe)."""
    relay, write = pipe
    reach = "orbit: cannot reach the coordinator at tls/10.0.0.1:7447 within 10 s (" + "why " * 80 + "and --tls-ca)"
    last = "y" * (StderrRelay.LINE + 5) if over else reach
    os.write(write, b"x" * (StderrRelay.LINE + 1) + b"\n" + last.encode() + b"\n")
    os.close(write)
    assert relay.last_line() == ("y" * StderrRelay.LINE + " [...]" if over else reach) and len(reach) > 300
