"""Lines for the user on stderr that survive the reader going away.

``cosim run ... 2>&1 | head -3``, or a ``tee`` that died with its ssh session: the next write gets EPIPE.
A run (or a subsim serving it) must not die of that, so from then on nothing more is written.
"""

from __future__ import annotations

import codecs
import io
import math
import os
import select
import sys
import threading
import time
from collections.abc import Callable


class _Gone:
    stream: object = None  # the stderr whose reader went away: nothing more is written to it


def say(line: str) -> None:
    """``line`` on stderr, flushed; once that stderr is gone, nothing (a stream put in its place is written to: a
    library must not replace the caller's sys.stderr, as this did)."""
    stream = sys.stderr
    if stream is None or stream is _Gone.stream:
        return
    try:
        print(line, file=stream, flush=True)
    except OSError:
        _Gone.stream = stream


class _PrefixedRaw(io.RawIOBase):
    """Bytes written go to file descriptor ``fd`` with ``prefix`` at the start of every line; nothing is held back,
    and once the reader is gone nothing more is written (as :func:`say`)."""

    def __init__(self, fd: int, prefix: bytes, once: bool = False) -> None:
        self._fd, self._prefix, self._at_start, self._gone = fd, prefix, True, False
        self._once = once  # a line that starts with the prefix already keeps it alone (the subsim's own lines)

    def writable(self) -> bool:
        return True

    def fileno(self) -> int:
        return self._fd

    def _head(self, line: bytes) -> bytes:
        if not self._at_start or (self._once and line.startswith(self._prefix)):
            return b""
        return self._prefix

    def write(self, b: bytes | bytearray | memoryview) -> int:  # type: ignore[override]
        data = bytes(b)
        out = bytearray()
        *whole, rest = data.split(b"\n")
        for line in whole:
            out += self._head(line) + line + b"\n"
            self._at_start = True
        if rest:
            out += self._head(rest) + rest
            self._at_start = False
        view = memoryview(out)
        while view and not self._gone:
            try:
                view = view[os.write(self._fd, view):]
            except OSError:
                self._gone = True
        return len(data)


def prefixed_stream(fd: int, prefix: str, once: bool = False) -> io.TextIOWrapper:
    """A text stream (with ``buffer``, ``fileno``, ``encoding``, like ``sys.stdout``) onto file descriptor ``fd``
    that puts ``prefix`` (a subsim's name) before each line: what a model prints, told apart from the coordinator's
    output and from other subsims'. Line buffered. ``once``: a line that starts with ``prefix`` already is left as it
    is (the subsim's own lines on its stderr)."""
    return io.TextIOWrapper(io.BufferedWriter(_PrefixedRaw(fd, prefix.encode(), once)), encoding="utf-8",
                            errors="backslashreplace", line_buffering=True)


class StderrRelay:
    """A child process's stderr, copied to this process's as it comes (a thread waiting on the pipe), with its last
    bytes kept: the line a process that failed to start left there (a model's ``__init__`` raising, a syntax error
    in a package's ``__main__``) belongs in the error that says it exited, not only on a terminal."""

    KEPT = 4096  # bytes of the end kept
    LINE = 800  # characters of its last line quoted (a subsim's own "cannot reach" line is 300-400: it was cut at 200)
    RECENT = 2.0  # s: what it wrote longer before its end was noticed is not why it ended (a silent os._exit)

    def __init__(self, pipe: io.BufferedReader | None) -> None:
        self._tail = b""
        self._written = -math.inf  # when it last wrote (monotonic)
        self._abandoned = False
        self._thread = None
        if pipe is not None:
            self._pipe = pipe
            self._thread = threading.Thread(target=self._copy, daemon=True, name="subsim-stderr")
            self._thread.start()

    def _copy(self) -> None:
        fd = self._pipe.fileno()
        write: Callable[[bytes], None] | None = _stderr_writer()
        poller = select.poll()
        poller.register(fd, select.POLLIN)
        while not self._abandoned:
            if not poller.poll(250):  # (woken 4 times a second to see whether it was given up)
                continue
            try:
                data = os.read(fd, 65536)
            except OSError:
                break
            if not data:
                break
            self._tail, self._written = (self._tail + data)[-self.KEPT:], time.monotonic()
            if write is not None:
                try:
                    write(data)
                except OSError:  # our stderr is gone: keep draining the child's (it must never block on it)
                    write = None
        self._pipe.close()

    def finish(self, timeout: float = 1.0) -> None:
        """Wait (up to ``timeout`` s) until everything the child wrote is copied, as at its end; then give the pipe
        up (a process it left behind, holding its stderr, would keep the thread and the pipe for its lifetime)."""
        if self._thread is not None:
            self._thread.join(timeout)
            self._abandoned = True

    def last_line(self, timeout: float = 0.5) -> str | None:
        """The child's last non-blank line on stderr (at most ``LINE`` characters, a cut said) if it wrote it lately;
        else None."""
        self.finish(timeout)
        if time.monotonic() - self._written > self.RECENT:
            return None
        lines = [x.strip() for x in self._tail.decode(errors="replace").splitlines() if x.strip()]
        if not lines:
            return None
        return lines[-1] if len(lines[-1]) <= self.LINE else f"{lines[-1][:self.LINE]} [...]"


def _stderr_writer() -> Callable[[bytes], None]:
    """Where a child's stderr is copied, looked up at each write: ``sys.stderr`` when something was put in its place
    (a notebook's stream, a test's capture), decoded as UTF-8 (a notebook showed none of it: an API probe); else this
    process's stderr descriptor, if it has one. Raises OSError once that descriptor is gone (a chunk a replaced
    stream cannot take is dropped alone)."""
    decode = codecs.getincrementaldecoder("utf-8")("backslashreplace").decode  # (a character split across reads)

    def write(data: bytes) -> None:
        stream = sys.stderr
        if stream is not None and stream is not sys.__stderr__:
            text = decode(data)
            try:
                stream.write(text)
                stream.flush()
            except (UnicodeError, ValueError, TypeError):  # this chunk (a stream that cannot encode it): not the rest
                pass
            return
        out = _stderr_fd()
        while data and out >= 0:
            data = data[os.write(out, data):]

    return write


def _stderr_fd() -> int:
    """This process's stderr, or -1 if it started without one (descriptor 2 may be another file of ours now)."""
    try:
        return sys.__stderr__.fileno() if sys.__stderr__ is not None else -1
    except (OSError, ValueError):
        return -1
