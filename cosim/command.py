"""The ``cosim`` command's entry point: Ctrl-C is answered before the command's modules are loaded.

Loading :mod:`cosim.cli` (NumPy, Zenoh, the coordinator) takes about 0.2 s; a SIGINT, SIGTERM or SIGHUP then used to
end in Python's traceback of whatever import it fell into. Until the command has read its arguments, one ends it
quietly with the shell's status for it (128 + the signal), as the command itself does later. (Python's own start,
before this module runs, is not covered.)"""

from __future__ import annotations

import os
import signal

_EARLY = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)  # (the run answers the same three: cosim.interrupt)


def _quit(signum: int, _frame: object) -> None:
    try:
        os.write(2, f"cosim: {signal.Signals(signum).name} while starting; nothing was run\n".encode())
    except OSError:  # no stderr to say it on
        pass
    os._exit(128 + signum)  # no clean-up to do yet, and none of the half-imported modules' exit hooks


def main() -> int:
    # a signal its parent ignored (a background job's SIGINT) stays ignored
    before = {s: signal.signal(s, _quit) for s in _EARLY if signal.getsignal(s) is not signal.SIG_IGN}
    from cosim.cli import entry  # the slow part

    def parsed() -> None:  # from here on the command starts things (processes, files) and stops them itself
        for s, handler in before.items():
            signal.signal(s, handler)

    return entry(parsed)


if __name__ == "__main__":
    raise SystemExit(main())
