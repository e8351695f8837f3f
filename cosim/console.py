"""Lines for the user on stderr that survive the reader going away.

``cosim run ... 2>&1 | head -3``, or a ``tee`` that died with its ssh session: the next write gets EPIPE.
A run (or a subsim serving it) must not die of that, so from then on nothing more is written.
"""

from __future__ import annotations

import os
import sys


def say(line: str) -> None:
    """``line`` on stderr, flushed; once stderr is gone, nothing."""
    try:
        print(line, file=sys.stderr, flush=True)
    except OSError:
        sys.stderr = open(os.devnull, "w")  # for the rest of the process
