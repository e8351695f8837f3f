"""Lines for the user on stderr that survive the reader going away.

``cosim run ... 2>&1 | head -3``, or a ``tee`` that died with its ssh session: the next write gets EPIPE.
A run (or a subsim serving it) must not die of that, so from then on nothing more is written.
"""

from __future__ import annotations

import io
import os
import sys


def say(line: str) -> None:
    """``line`` on stderr, flushed; once stderr is gone, nothing."""
    try:
        print(line, file=sys.stderr, flush=True)
    except OSError:
        sys.stderr = open(os.devnull, "w")  # for the rest of the process


class _PrefixedRaw(io.RawIOBase):
    """Bytes written go to file descriptor ``fd`` with ``prefix`` at the start of every line; nothing is held back,
    and once the reader is gone nothing more is written (as :func:`say`)."""

    def __init__(self, fd: int, prefix: bytes) -> None:
        self._fd, self._prefix, self._at_start, self._gone = fd, prefix, True, False

    def writable(self) -> bool:
        return True

    def fileno(self) -> int:
        return self._fd

    def write(self, b: bytes | bytearray | memoryview) -> int:  # type: ignore[override]
        data = bytes(b)
        out = bytearray()
        *whole, rest = data.split(b"\n")
        for line in whole:
            out += (self._prefix if self._at_start else b"") + line + b"\n"
            self._at_start = True
        if rest:
            out += (self._prefix if self._at_start else b"") + rest
            self._at_start = False
        view = memoryview(out)
        while view and not self._gone:
            try:
                view = view[os.write(self._fd, view):]
            except OSError:
                self._gone = True
        return len(data)


def prefixed_stream(fd: int, prefix: str) -> io.TextIOWrapper:
    """A text stream (with ``buffer``, ``fileno``, ``encoding``, like ``sys.stdout``) onto file descriptor ``fd``
    that puts ``prefix`` (a subsim's name) before each line: what a model prints, told apart from the coordinator's
    output and from other subsims'. Line buffered."""
    return io.TextIOWrapper(io.BufferedWriter(_PrefixedRaw(fd, prefix.encode())), encoding="utf-8",
                            errors="backslashreplace", line_buffering=True)
