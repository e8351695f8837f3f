"""SIGINT, SIGTERM and SIGHUP as an exception a run unwinds through, cleaning up on the way.

Inside :func:`handling` the first of these signals raises :class:`Interrupted` in the main thread,
wherever it is waiting (a stage's replies, a subsim's start), so the ``finally`` blocks of the run
stop the subsims and finish the result files. Code that must not be cut in half (writing one
interval, building the NPZ) runs inside :func:`deferred`: a signal arriving there is raised when
the block ends. Signals after the first are ignored: the run is already stopping, and a second
Ctrl-C must not cut the cleanup short. The exit status is 128 + the signal number (130, 143, 129).
A signal that was ignored when the run started (SIGHUP under ``nohup``) stays ignored.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class Interrupted(KeyboardInterrupt):
    """The run was stopped by a signal."""

    def __init__(self, signum: int) -> None:
        self.signum = signum
        self.name = signal.Signals(signum).name
        super().__init__(self.name)

    @property
    def exit_status(self) -> int:
        return 128 + self.signum


class _State:
    active = False
    depth = 0  # nesting of deferred()
    pending: int | None = None  # a signal that arrived inside deferred()
    raised = False  # the first signal has been raised: ignore the rest
    finished = False  # the run is done (only its cleanup is left): a signal is noted, not raised
    late: int | None = None  # the first signal that came after the run was done


def _handler(signum: int, frame: FrameType | None) -> None:
    if _State.finished:
        _State.late = _State.late or signum
        return
    if _State.raised or _State.pending is not None:
        return
    if _State.depth > 0:
        _State.pending = signum
        return
    _State.raised = True
    raise Interrupted(signum)


def _elsewhere() -> bool:
    """Whether this is not the main thread: a run there installs no handlers (Python runs them in the main thread
    only), so its blocks and its end must not touch the main thread's run (a run ending in a worker thread turned
    Ctrl-C off for the main thread's: an API probe)."""
    return threading.current_thread() is not threading.main_thread()


@contextmanager
def handling(signals: tuple[int, ...] = SIGNALS) -> Iterator[None]:
    """Install the handlers for the duration of the block and restore the old ones. Outside the main
    thread (where Python runs signal handlers) it does nothing."""
    if _elsewhere():
        yield
        return
    # a signal ignored when we started stays ignored: `nohup cosim run ...` must survive the hangup
    old = {s: h for s in signals if (h := signal.getsignal(s)) is not signal.SIG_IGN}
    _State.active, _State.depth, _State.pending, _State.raised = True, 0, None, False
    _State.finished, _State.late = False, None
    for s in old:
        signal.signal(s, _handler)
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        _State.active = False


@contextmanager
def deferred() -> Iterator[None]:
    """A signal arriving inside the block is raised when it ends (not at all if the block raises)."""
    if _elsewhere():
        yield
        return
    _State.depth += 1
    ok = False
    try:
        yield
        ok = True
    finally:
        _State.depth -= 1
        if ok and _State.depth == 0 and _State.pending is not None and not _State.raised and _State.active:
            signum, _State.pending = _State.pending, None
            _State.raised = True
            raise Interrupted(signum)


def finished() -> None:
    """The run is done: what is left (closing files, stopping subsims) finishes whatever comes. A signal held back
    until now, or arriving from now on, is only noted (:func:`late`): stopping would cut short a finished run."""
    if _elsewhere():
        return
    _State.finished = True
    if _State.pending is not None:
        _State.late, _State.pending = _State.pending, None


def late() -> str | None:
    """The name of the first signal that came after :func:`finished`, if any (in the main thread's run)."""
    return None if _State.late is None or _elsewhere() else signal.Signals(_State.late).name


def pending() -> int | None:
    """A signal that arrived inside :func:`deferred` and was not raised (the block raised instead)."""
    return None if _elsewhere() else _State.pending
