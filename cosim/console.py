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


class PrefixedLines(io.TextIOBase):
    """A text stream that says each whole line written to it on stderr after ``prefix`` (a subsim's name): what a
    model prints, told apart from the coordinator's output and from other subsims'."""

    def __init__(self, prefix: str) -> None:
        self.prefix, self._partial = prefix, ""

    def writable(self) -> bool:
        return True

    def write(self, text: str) -> int:
        *lines, self._partial = (self._partial + text).split("\n")
        for line in lines:
            say(self.prefix + line)
        return len(text)

    def flush(self) -> None:
        pass

    def close(self) -> None:
        if self._partial:
            say(self.prefix + self._partial)
            self._partial = ""
        super().close()
