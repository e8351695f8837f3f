"""Progress of a long run on stderr: percent, simulated time, rate, stages per interval, time left.

Hand-written rather than ``rich`` or ``tqdm``: one line, redrawn in place, is all it needs; the
rate and time left are in simulated seconds (which a generic iteration counter does not know),
and it adds no dependency.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import TextIO

from cosim.coupler.relaxation import Interval


def _clock(seconds: float) -> str:
    s = int(round(seconds))
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


class Progress:
    """On a terminal or in a Jupyter notebook, one line redrawn at most twice a second and once more at the end
    (100 % when the run finished). When the stream is neither (a log file, a pipe), nothing: no redraws pile up
    in logs, and the run's summary line says how it went."""

    def __init__(self, t_start: float, t_stop: float, stream: TextIO = sys.stderr, enabled: bool = True,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.t_start, self.t_stop, self.stream, self.clock = t_start, t_stop, stream, clock
        self.tty = hasattr(stream, "isatty") and stream.isatty()
        self.notebook = type(stream).__module__.startswith("ipykernel")  # it redraws on "\r", says no tty
        self.enabled = enabled and (self.tty or self.notebook)
        self.started = clock()
        self._shown = float("-inf")
        self.intervals = self.stages = 0
        self.t = t_start

    def update(self, interval: Interval) -> None:
        self.intervals += 1
        self.stages += interval.stages
        self.t = float(interval.t[-1])
        if not self.enabled:
            return
        now = self.clock()
        if now - self._shown >= 0.5:
            self._shown = now
            self._draw(now)

    def line(self, now: float) -> str:
        """``  42.0%  t = 420 / 1000 s  8.4x real time  3.00 stages/interval  1:09 left``"""
        span = self.t_stop - self.t_start
        done = self.t - self.t_start
        pct = min(100.0, 100.0 * done / span) if span > 0 else 100.0
        wall = max(now - self.started, 1e-9)
        rate = done / wall  # simulated seconds per wall second
        if pct >= 100.0:
            left = f"done in {_clock(wall)}"
        elif rate > 0:
            left = f"{_clock((self.t_stop - self.t) / rate)} left"
        else:
            left = "--:-- left"
        return (f"{pct:5.1f}%  t = {self.t:.6g} / {self.t_stop:.6g} s  {rate:.3g}x real time  "
                f"{self.stages / max(self.intervals, 1):.2f} stages/interval  {left}")

    def _draw(self, now: float, end: str = "") -> None:
        line = self.line(now)  # a terminal clears the rest of the line; a notebook gets spaces over it
        try:
            self.stream.write("\r" + (line + "\x1b[K" if self.tty else line.ljust(100)) + end)
            self.stream.flush()
        except OSError:  # the terminal went away (closed, hung up: EIO): the run goes on without its progress line
            self.enabled = False

    def done(self) -> None:
        """The final state (100 % if the run reached its stop), and a newline."""
        if self.enabled:
            self._draw(self.clock(), "\n")
