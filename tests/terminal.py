"""Signal dispositions of a command typed at a terminal, for the runs that signal tests stop.

A process inherits ignored signals: a suite started in the background (``cmd &`` in a script) ignores
SIGINT, one under ``nohup`` SIGHUP, and ``cosim run`` by design keeps an ignored signal ignored. The
runs these tests interrupt must not depend on how the suite itself was started.
"""

from __future__ import annotations

import signal


def as_from_a_terminal() -> None:
    """``preexec_fn``: SIGINT, SIGTERM and SIGHUP at their defaults in the child."""
    for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(s, signal.SIG_DFL)
