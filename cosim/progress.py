"""Progress of a long run on stderr: percent, simulated time, intervals per second, stages."""

from __future__ import annotations

import sys
import time
from typing import TextIO

from cosim.coupler.relaxation import Interval


class Progress:
    """On a terminal, one line redrawn twice a second; otherwise a line every 10 %."""

    def __init__(self, t_start: float, t_stop: float, stream: TextIO = sys.stderr, enabled: bool = True) -> None:
        self.t_start, self.t_stop, self.stream, self.enabled = t_start, t_stop, stream, enabled
        self.tty = hasattr(stream, "isatty") and stream.isatty()
        self.started = self._shown = time.monotonic()
        self.intervals = self.stages = 0
        self._next_decile = 10

    def update(self, interval: Interval) -> None:
        self.intervals += 1
        self.stages += interval.stages
        if not self.enabled:
            return
        t = float(interval.t[-1])
        pct = 100.0 * (t - self.t_start) / (self.t_stop - self.t_start)
        now = time.monotonic()
        if self.tty and now - self._shown >= 0.5:
            self._shown = now
            self.stream.write("\r" + self.line(t, pct, now) + "   ")
            self.stream.flush()
        elif not self.tty and pct >= self._next_decile:
            self._next_decile = 10 * (int(pct) // 10 + 1)
            self.stream.write(self.line(t, pct, now) + "\n")
            self.stream.flush()

    def line(self, t: float, pct: float, now: float) -> str:
        rate = self.intervals / max(now - self.started, 1e-9)
        return (f"{min(pct, 100.0):5.1f}%  t = {t:.6g} / {self.t_stop:.6g}  {rate:,.0f} intervals/s  "
                f"{self.stages / max(self.intervals, 1):.2f} stages/interval")

    def done(self) -> None:
        if self.enabled and self.tty:
            self.stream.write("\n")
            self.stream.flush()
