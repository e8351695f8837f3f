"""Result files: samples stream to disk as each interval commits, diagnostics beside them.

CSV (``time,<subsim>.<output>[<i>],...``) is appended and flushed per interval, so an interrupted
run keeps everything up to its last committed interval. NPZ (chosen by suffix) is written when
the run ends, however it ends. Each interval contributes its samples but the last (which is the
next interval's first); the run's final sample is written on close.
Diagnostics: ``<stem>.diag.csv`` with one row per interval.
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from cosim.coupler.couplings import SignalRef
from cosim.coupler.relaxation import Interval

DIAG_COLUMNS = ["interval", "t0", "t1", "stages", "largest_residual", "wall_time_s", "halvings", "length_s", "error"]


def column_names(signals: Sequence[tuple[SignalRef, int]]) -> list[str]:
    return ["time"] + [f"{ref}[{i}]" for ref, size in signals for i in range(size)]


def diag_path(path: Path) -> Path:
    return path.with_name(path.stem + ".diag.csv")


class ResultWriter:
    def __init__(self, path: Path, signals: Sequence[tuple[SignalRef, int]]) -> None:
        self.path, self.signals = path, list(signals)
        self.columns = column_names(self.signals)
        path.parent.mkdir(parents=True, exist_ok=True)
        self._npz = path.suffix == ".npz"
        self._rows: list[np.ndarray] = []
        self._last: np.ndarray | None = None
        self._count = 0
        if not self._npz:
            self._file = path.open("w", newline="")
            self._csv = csv.writer(self._file)
            self._csv.writerow(self.columns)
        self._diag_file = diag_path(path).open("w", newline="")
        self._diag = csv.writer(self._diag_file)
        self._diag.writerow(DIAG_COLUMNS)

    def rows(self, interval: Interval) -> np.ndarray:
        parts = [interval.t[:, None]] + [interval.outputs[r.subsim][r.port] for r, _ in self.signals]
        return np.hstack(parts)

    def write(self, interval: Interval) -> None:
        rows = self.rows(interval)
        self._last = rows[-1]
        if self._npz:
            self._rows.append(rows[:-1])
        else:
            self._csv.writerows(map(_fmt, rows[:-1]))
            self._file.flush()
        self._count += 1
        t = interval.t
        self._diag.writerow([self._count, repr(float(t[0])), repr(float(t[-1])), interval.stages,
                             f"{interval.largest_residual:.6e}", f"{interval.wall_time:.6f}", interval.halvings,
                             repr(float(t[-1] - t[0])), f"{interval.error:.3e}"])
        self._diag_file.flush()

    def close(self) -> None:
        if self._npz:
            data = np.vstack(self._rows + ([self._last[None, :]] if self._last is not None else []))
            if data.size == 0:
                data = np.empty((0, len(self.columns)))
            np.savez(self.path, columns=np.array(self.columns), data=data)
        else:
            if self._last is not None:
                self._csv.writerow(_fmt(self._last))
            self._file.close()
        self._diag_file.close()


def _fmt(row: np.ndarray) -> list[str]:
    return [repr(float(x)) for x in row]


def read_results(path: str | Path) -> tuple[list[str], np.ndarray]:
    """Columns and data (rows x columns) of a CSV or NPZ result file."""
    path = Path(path)
    if path.suffix == ".npz":
        with np.load(path) as z:
            return [str(c) for c in z["columns"]], z["data"]
    with path.open() as f:
        columns = next(csv.reader(f))
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return columns, data
