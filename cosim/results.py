"""Result files: samples stream to disk as each interval commits, diagnostics beside them.

CSV (``time,<subsim>.<output>[<i>],...``) is appended as each interval commits: every row of the
interval, its end included (the next interval's first row, the same time, is skipped), in one
``write``, so the file is complete up to the last committed interval at every moment, even if the
coordinator is killed. Units go to ``<name>.meta.json`` beside it.

NPZ (chosen by suffix; arrays ``columns``, ``units``, ``data``) streams the same rows as float64 to
``<name>.partial`` and is built from it, atomically, when the run ends, however it ends; after a
SIGKILL, ``cosim recover <name>.npz`` builds it.

Diagnostics: ``<name>.diag.csv`` (``x.csv.diag.csv``, ``x.npz.diag.csv``), one row per interval.
Disk full or another write error: :class:`~cosim.outputs.OutputError` (one line), and every file
ends at its last whole interval. See :mod:`cosim.outputs` for the names, locks and atomic writes.
"""

from __future__ import annotations

import csv
import io
import json
import os
import warnings
from collections import deque
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from cosim import interrupt
from cosim.coupler.couplings import SignalRef
from cosim.coupler.relaxation import Interval
from cosim.outputs import (
    AppendFile,
    OutputError,
    OutputLock,
    OutputWriteError,
    atomic_write,
    diag_path,
    is_npz,
    meta_path,
    prefix_digest,
    read_stream,
    reserve_output,
    run_files,
    staged,
    stream_head,
    stream_header,
    stream_path,
    symlink_target,
    write_failure,
    write_npz,
)

if TYPE_CHECKING:
    from cosim.handles import Description

__all__ = ["DIAG_COLUMNS", "ResultWriter", "column_names", "diag_path", "output_units", "read_results",
           "read_units", "recover"]

# Rows formatted per step of ResultWriter.write_steps: about 10 us a row of 22 columns, so a coordinator that
# writes while it waits for a reply looks at the bus every 40 us or so.
ROWS_PER_STEP = 4
DIAG_COLUMNS = ["interval", "t0", "t1", "stages", "largest_residual", "wall_time_s", "halvings", "restarts",
                "length_s", "error"]


def column_names(signals: Sequence[tuple[SignalRef, int]]) -> list[str]:
    return ["time"] + [f"{ref}[{i}]" for ref, size in signals for i in range(size)]


def column_units(signals: Sequence[tuple[SignalRef, int]], units: Mapping[str, str] | None) -> list[str]:
    """Unit of every column ("s" for time; "" where unknown or dimensionless)."""
    units = units or {}
    return ["s"] + [units.get(str(ref), "") for ref, size in signals for _ in range(size)]


def output_units(descriptions: Mapping[str, Description]) -> dict[str, str]:
    """``{"subsim.port": unit}`` of every output port, from the subsims' declarations."""
    return {f"{n}.{p}": port.unit for n, d in descriptions.items() for p, port in d.outputs.items()}


class ResultWriter:
    """Streams committed intervals to ``path`` (.csv or .npz) and its diagnostics file.

    A new run's files are written under staged names (:func:`staged`) until its first interval is in them, and
    only then take the real names: a run that stops before that (a bad setting, an interval that does not
    converge, a kill) leaves what was there, a previous run's results replaced by ``--overwrite`` included.

    ``lock``: the :class:`~cosim.outputs.OutputLock` taken (with the checks) before the run launched
    anything; without one the writer takes it itself (replacing an existing file). The lock is released
    by :meth:`close`.
    """

    def __init__(self, path: Path, signals: Sequence[tuple[SignalRef, int]],
                 units: Mapping[str, str] | None = None, lock: OutputLock | None = None,
                 resume_at: float | None = None, written: Mapping[str, Any] | None = None) -> None:
        """``resume_at``: go on with the files of an interrupted run, cut back to their rows up to that time (a
        resume point's), which they must reach; ``written``: what the run had written up to then (:meth:`written`
        at that time), which they must still hold, byte for byte."""
        self.path, self.signals = Path(path), list(signals)
        self.columns = column_names(self.signals)
        self.units = column_units(self.signals, units)
        self._lock = lock if lock is not None else reserve_output(self.path, overwrite=True)
        self._npz = is_npz(self.path)
        self.t_last: float | None = None  # time of the last row written
        self.rows_written = 0
        self.failed = False
        self._resumed = False  # going on with an interrupted run's files: never removed here
        self._count = 0
        self._data: AppendFile | None = None
        self._diag: AppendFile | None = None
        self._staged: list[tuple[Path, Path]] = []  # (name, file it names) of the files written under staged names
        self._marks: deque[tuple[float, dict[str, Any]]] = deque(maxlen=64)  # (t_last, written) of recent intervals
        if resume_at is not None:
            self._resume(resume_at, written)
            return
        try:
            if self._npz:
                self._data = AppendFile(self._stage(stream_path(self.path)), "the NPZ's streamed samples")
                self._data.append(stream_header(self.columns, self.units))
            else:
                self._write_units(self._stage(meta_path(self.path)))
                self._data = AppendFile(self._stage(self.path), "results")
                self._data.append(_csv_header(self.columns).encode())
            self._diag = AppendFile(self._stage(diag_path(self.path)), "diagnostics")
            self._diag.append((",".join(DIAG_COLUMNS) + "\n").encode())
        except BaseException:  # nothing of this run is in the files yet: leave none behind
            self.failed = True
            self._close_files()
            self._drop_staged()
            self._lock.release()
            raise

    def _stage(self, path: Path) -> Path:
        """Where to write ``path`` until the first interval is in: beside the file it names (a symbolic link's
        target, which the run writes as it always did)."""
        target = symlink_target(path)
        self._staged.append((path, target))
        return staged(target)

    def _drop_staged(self) -> None:
        for _, target in self._staged:
            staged(target).unlink(missing_ok=True)
        self._staged.clear()

    def _promote(self) -> None:
        """The staged files take their real names; what a previous run left under them and this run does not
        write again (its resume point, an NPZ this run builds at its end) goes."""
        try:
            for _, target in self._staged:
                os.replace(staged(target), target)
        except OSError as exc:  # the directory moved or went during the first interval
            self.failed = True
            raise OutputWriteError(f"{write_failure(exc, target)}, then run again") from None
        targets = {staged(target): target for _, target in self._staged}
        for f in (self._data, self._diag):
            if f is not None:
                f.path = targets.get(f.path, f.path)
        names = [name for name, _ in self._staged]
        for path in run_files(self.path):
            if path not in names:
                symlink_target(path).unlink(missing_ok=True)  # (a link stays: it names what this run writes)
        self._staged.clear()

    def sync(self) -> None:
        """Both files' bytes on disk (see :meth:`AppendFile.sync`)."""
        for f in (self._data, self._diag):
            if f is not None:
                f.sync()

    def written(self, t: float) -> dict[str, Any] | None:
        """What the files held when the interval ending at ``t`` was in (bytes and SHA-256 of each), for a resume
        point there; None if that is not known (long ago, or a file was cut back)."""
        for at, marks in reversed(self._marks):
            if at == t:
                return marks
        return None

    def _write_units(self, path: Path) -> None:
        """A CSV's ``.meta.json``: its columns and their units."""
        meta = {"format": "cosim results", "columns": self.columns, "units": self.units}
        atomic_write(path, lambda f: f.write(json.dumps(meta, indent=1).encode() + b"\n"))

    def _resume(self, t: float, written: Mapping[str, Any] | None = None) -> None:
        data = stream_path(self.path) if self._npz else self.path
        rebuilt = False
        try:
            if self._npz and not data.exists():  # the stopped run built its NPZ: stream it again
                if not self.path.exists():
                    raise OutputError(f"neither {self.path} nor {data} exists: nothing to resume")
                columns, rows = read_results(self.path)
                rebuilt = True
                stream = AppendFile(data, "the NPZ's streamed samples")
                try:
                    stream.append(stream_header(columns, [read_units(self.path).get(c, "") for c in columns]))
                    stream.append(np.ascontiguousarray(rows, dtype="<f8").tobytes())
                finally:
                    stream.close(sync=True)
            if self._npz:
                columns, _, rows = read_stream(data)
                row_ends = stream_head(data)[2] + 8 * len(columns) * np.arange(1, rows.shape[0] + 1)
            else:
                columns, rows, row_ends = _csv_rows(data)
            if columns != self.columns:
                raise OutputError(f"{data} has other columns than this run writes: not this run's results")
            kept = _rows_to(rows[:, 0], t, data)
            keep = int(row_ends[kept - 1])
            diag_rows = _diag_rows_to(diag_path(self.path), t)
            digests = {"results": prefix_digest(data, keep), "diagnostics": prefix_digest(diag_path(self.path),
                                                                                          diag_rows[1])}
            if written is not None:  # (a stream rebuilt from the NPZ holds the bytes streamed: the same header, rows)
                for name, path, size in (("results", data, keep), ("diagnostics", diag_path(self.path), diag_rows[1])):
                    if [size, digests[name].hexdigest()] != list(written[name]):
                        raise OutputError(f"{path} is not as the run left it up to its resume point at t = {t:g} "
                                          "(rows removed, added or changed since): it cannot go on from there; run "
                                          "it again from the start with --overwrite")
            self._data = AppendFile(data, "the NPZ's streamed samples" if self._npz else "results", keep=keep,
                                    digest=digests["results"])
            self._diag = AppendFile(diag_path(self.path), "diagnostics", keep=diag_rows[1],
                                    digest=digests["diagnostics"])
            if not self._npz:  # (removed or edited since the stop, it stayed so: a red team)
                self._write_units(meta_path(self.path))
        except BaseException as exc:
            self._close_files()
            if rebuilt and self._data is None:  # refused: the NPZ stays as it was, alone
                data.unlink(missing_ok=True)
            self._lock.release()
            if isinstance(exc, Exception) and not isinstance(exc, OutputError):  # a damaged file: say which
                raise OutputError(f"cannot resume from {self.path} and its companions: {type(exc).__name__}: "
                                  f"{' '.join(str(exc).split())[:200]}") from None
            raise
        self.t_last, self.rows_written, self._count = t, kept, diag_rows[0]
        self._resumed = True

    def rows(self, interval: Interval) -> np.ndarray:
        outputs = interval.outputs
        return np.concatenate([interval.t[:, None], *[outputs[r.subsim][r.port] for r, _ in self.signals]], axis=1)

    def holds(self, interval: Interval) -> bool:
        """Whether ``interval`` is the last one in the files (a signal held back while it was written is raised
        after it is in)."""
        return self.t_last is not None and self.t_last == float(interval.t[-1])

    def write(self, interval: Interval) -> None:
        """Append the interval's rows (all of them; a first row repeating the last written time is skipped)."""
        for _ in self.write_steps(interval):
            pass

    def write_steps(self, interval: Interval) -> Iterator[None]:
        """:meth:`write` in steps: it pauses after formatting every ``ROWS_PER_STEP`` rows, so that a caller
        can do it while waiting for something else and look again between steps. The files are appended
        to in the last step, the interval whole; a signal that stops the run during a step is raised once the
        interval is written (as inside :func:`cosim.interrupt.deferred`)."""
        rows = np.asarray(self.rows(interval), dtype=np.float64)
        if self.t_last is not None and rows.shape[0] and rows[0, 0] == self.t_last:
            rows = rows[1:]
        values: list[list[float]] = [] if self._npz else rows.tolist()
        text: list[str] = []
        try:
            for start in range(0, len(values), ROWS_PER_STEP):
                text.extend(map(_fmt, values[start:start + ROWS_PER_STEP]))
                yield
        except KeyboardInterrupt:  # the signal of a stopping run: this committed interval still goes in whole
            text.extend(map(_fmt, values[len(text):]))
            self._append(interval, rows, text)
            raise
        self._append(interval, rows, text)

    def _append(self, interval: Interval, rows: np.ndarray, text: list[str]) -> None:
        data = rows.astype("<f8").tobytes() if self._npz else "".join(text).encode()
        with interrupt.deferred():  # a signal waits until the interval is written whole
            assert self._data is not None and self._diag is not None, "write after close"
            t = interval.t
            line = (f"{self._count + 1},{float(t[0])!r},{float(t[-1])!r},{interval.stages},"
                    f"{interval.largest_residual:.6e},{interval.wall_time:.6f},{interval.halvings},"
                    f"{interval.restarts},{float(t[-1] - t[0])!r},{interval.error:.3e}\n")
            size = self._data.size
            try:
                self._data.append(data, self._ends_at)
                try:
                    self._diag.append(line.encode(), self._ends_at)
                except OutputWriteError:  # the interval goes in whole or not at all: the two files end together
                    self._data.cut(size)
                    raise
            except OutputWriteError:
                self.failed = True
                raise
            if rows.shape[0]:
                self.t_last = float(rows[-1, 0])
            self.rows_written += rows.shape[0]
            self._count += 1
            marks = {"results": self._data.mark(), "diagnostics": self._diag.mark()}
            if self.t_last is not None and None not in marks.values():
                self._marks.append((self.t_last, marks))
            if self._staged:  # the first interval is in: the files are this run's now
                self._promote()  # (an OutputWriteError if they cannot be: not in the except above, nothing to cut)

    def _ends_at(self) -> str:
        if self._staged:
            return "no interval written"
        where = "no samples written" if self.t_last is None else f"results end at t = {self.t_last:.6g} s"
        if self._npz:
            where += f", kept in {stream_path(self.path)} (`cosim recover {self.path}` builds the NPZ)"
        return where

    def close(self, failed_run: bool = False) -> None:
        """Finish every file (the NPZ from its stream, atomically) and release the lock. After a write
        error the NPZ is not attempted: its stream stays for ``cosim recover``. ``failed_run``: the run stopped
        on an error; if it committed no interval, its staged files are removed (what was there stays), so that
        running it again after a fix needs no ``--overwrite``."""
        with interrupt.deferred():
            try:
                self._close_files()
                if (failed_run and self._count == 0 and not self._resumed) or (self._staged and self.failed):
                    self._drop_staged()  # (nothing of this run is in place: what was there stays)
                    return
                if self._staged:  # a run that ended without an interval (nothing to do): its files all the same
                    self._promote()
                if self._npz and not self.failed:
                    _, _, data = read_stream(stream_path(self.path))
                    try:
                        write_npz(self.path, self.columns, self.units, data)
                    except OutputWriteError as exc:
                        raise OutputWriteError(f"{exc} (every sample is kept in {stream_path(self.path)}: "
                                               f"`cosim recover {self.path}` builds the NPZ)") from None
                    stream_path(self.path).unlink()
            finally:
                self._lock.release()

    def _close_files(self) -> None:
        for f in (self._data, self._diag):
            if f is not None:
                f.close(sync=not self.failed)


def _csv_header(columns: list[str]) -> str:
    """The header line, quoted where a name needs it (an FMU port may be named 'a,b')."""
    text = io.StringIO()
    csv.writer(text, lineterminator="\n").writerow(columns)
    return text.getvalue()


def _fmt(row: list[float]) -> str:
    return ",".join(map(repr, row)) + "\n"  # repr: the shortest text that reads back to the same float


def read_results(path: str | Path) -> tuple[list[str], np.ndarray]:
    """Columns and data (rows x columns) of a CSV or NPZ result file. ValueError for a torn last row."""
    path = Path(path)
    if path.suffix == ".npz":
        with np.load(path) as z:
            return [str(c) for c in z["columns"]], z["data"]
    with path.open() as f:
        columns = next(csv.reader(f))
    with path.open("rb") as f:
        f.seek(0, 2)
        if f.tell() and (f.seek(-1, 2), f.read(1))[1] != b"\n":
            raise ValueError(f"{path} ends in a partial row (an interrupted write): `cosim recover {path}` "
                             "cuts it off")
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "loadtxt: input contained no data")
        data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    if data.size == 0:
        data = np.empty((0, len(columns)))
    return columns, data


def read_units(path: str | Path) -> dict[str, str]:
    """``{column: unit}`` of a result file: the NPZ's ``units``, or the CSV's ``.meta.json`` (empty if
    the file has none, e.g. written by an older cosim)."""
    path = Path(path)
    try:
        if path.suffix == ".npz":
            with np.load(path) as z:
                if "units" not in z.files:
                    return {}
                return dict(zip((str(c) for c in z["columns"]), (str(u) for u in z["units"])))
        meta = json.loads(meta_path(path).read_text())
        return dict(zip(meta["columns"], meta["units"]))
    except (OSError, ValueError, KeyError, TypeError):
        return {}


def recover(path: Path) -> str:
    """Make ``path`` whole after its coordinator was killed; returns what was done (one line).

    NPZ: build it from ``<path>.partial`` (atomically) and remove the stream. CSV: cut a torn last row
    (and one in the diagnostics). Raises OutputError if there is nothing to recover from or a run holds
    the file.
    """
    path = Path(path)
    if path.is_dir():
        raise OutputError(f"{path} is a directory, not a result file (.csv or .npz)")
    if not is_npz(path) and path.suffix.lower() != ".csv":
        raise OutputError(f"{path} is not a result file: cosim writes .csv or .npz")
    lock = OutputLock.acquire(path)
    try:
        if is_npz(path):
            stream = stream_path(path)
            if not stream.exists():
                if path.exists():
                    try:
                        read_results(path)
                    except Exception as exc:  # whatever np.load makes of a file that is not an NPZ of ours
                        raise OutputError(f"{path}: not a cosim result file ({type(exc).__name__}: {exc})") from None
                    return f"{path} is complete (no {stream.name} beside it): nothing to recover"
                raise OutputError(f"neither {path} nor {stream} exists: nothing to recover")
            try:
                columns, units, data = read_stream(stream)
            except (ValueError, KeyError) as exc:
                raise OutputError(f"{stream}: cannot read it ({exc})") from None
            write_npz(path, columns, units, data)
            stream.unlink()
            cut = _cut_torn_row(diag_path(path))
            return f"{path}: {_span(data)} recovered from {stream.name}{cut}{_disagreement(path, data)}"
        if not path.exists():
            raise OutputError(f"{path} does not exist: nothing to recover")
        _check_header(path, "time")  # before anything is cut: never shorten a file that is not ours
        cut = _cut_torn_row(path)
        cut_diag = _cut_torn_row(diag_path(path)) if _has_header(diag_path(path), "interval") else ""
        try:
            _, data = read_results(path)
        except (ValueError, OSError) as exc:
            raise OutputError(f"{path}: not a cosim result file ({exc})") from None
        return f"{path}: {_span(data)}{cut or ' (complete)'}{cut_diag}{_disagreement(path, data)}"
    finally:
        lock.release()


def _csv_rows(path: Path) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Columns and rows of a CSV result file (a torn last row left out), and the byte offset just past each row."""
    if not _has_header(path, "time"):
        raise OutputError(f"{path}: not a cosim result file to resume (no header starting with 'time,')")
    raw = path.read_bytes()
    ends = np.flatnonzero(np.frombuffer(raw, dtype=np.uint8) == ord("\n")) + 1
    columns = next(csv.reader([raw[:ends[0]].decode()]))
    body = raw[ends[0]:ends[-1]]
    rows = np.loadtxt(io.BytesIO(body), delimiter=",", ndmin=2) if body else np.empty((0, len(columns)))
    return columns, rows, ends[1:]


def _rows_to(times: np.ndarray, t: float, path: Path) -> int:
    """How many rows there are up to the one at time ``t``, which must be there."""
    at = np.flatnonzero(times == t)
    if at.size == 0:
        last = f"t = {times[-1]:.9g}" if times.size else "no row"
        raise OutputError(f"{path} has no row at the resume point t = {t!r} (it ends at {last}): run it again "
                          "from the start")
    return int(at[-1]) + 1


def _diag_rows_to(path: Path, t: float) -> tuple[int, int]:
    """Rows of the diagnostics file up to the interval ending at ``t``, and their length in bytes: they must be the
    intervals 1, 2, ... in order, the last one ending at ``t``."""
    if not path.exists():  # (it read "not the diagnostics of a cosim run": a red team)
        raise OutputError(f"{path}, the diagnostics beside the results, is missing (removed since the run stopped): "
                          "run it again from the start with --overwrite")
    if not _has_header(path, "interval"):
        raise OutputError(f"{path}: not the diagnostics of a cosim run to resume")
    raw = path.read_bytes()
    lines = raw[:raw.rfind(b"\n") + 1].splitlines(keepends=True)
    keep, size, end = 0, len(lines[0]), None
    for line in lines[1:]:
        number, _, t1 = line.split(b",")[:3]
        if float(t1) > t:
            break
        if int(number) != keep + 1:
            raise OutputError(f"{path}: interval {keep + 1} is missing (the file was cut or edited): run it again "
                              "from the start (--overwrite instead of --resume)")
        keep, size, end = keep + 1, size + len(line), float(t1)
    if end != t:
        ends = "no interval" if end is None else f"t = {end!r}"
        raise OutputError(f"{path} does not reach the resume point t = {t!r} (it ends at {ends}): run it again from "
                          "the start (--overwrite instead of --resume)")
    return keep, size


def _has_header(path: Path, first: str) -> bool:
    """Whether ``path`` starts with a complete CSV header whose first column is ``first``."""
    try:
        with path.open("rb") as f:
            line = f.readline(1 << 24)  # a header of many thousand columns is still read whole
    except OSError:
        return False
    return line.endswith(b"\n") and line.split(b",", 1)[0].strip() == first.encode()


def _check_header(path: Path, first: str) -> None:
    if not _has_header(path, first):
        raise OutputError(f"{path}: not a cosim result file (its first line is not a header starting with "
                          f"'{first},'): left as it was")


def _disagreement(path: Path, data: np.ndarray) -> str:
    """A note when the diagnostics end at another interval than the results (a kill between an interval's two
    writes), else ''."""
    diag = diag_path(path)
    if not data.shape[0] or not _has_header(diag, "interval"):
        return ""
    try:
        header, rows = read_results(diag)
    except (ValueError, OSError, StopIteration):
        return ""
    end = float(rows[-1, header.index("t1")]) if rows.shape[0] else None
    if end == float(data[-1, 0]):
        return ""
    said = "none" if end is None else f"t = {end:.6g} s"
    return (f"; its diagnostics end at {said}, the results at t = {data[-1, 0]:.6g} s (it was stopped between an "
            "interval's two writes): --resume (or --overwrite) makes them agree")


def _span(data: np.ndarray) -> str:
    if data.shape[0] == 0:
        return "no samples"
    return f"{data.shape[0]} samples, t = {data[0, 0]:.6g} to {data[-1, 0]:.6g} s"


def _cut_torn_row(path: Path) -> str:
    """Truncate ``path`` after its last newline; returns a note if something was cut."""
    if not path.exists():
        return ""
    raw = path.read_bytes()
    end = raw.rfind(b"\n") + 1
    if end == len(raw):
        return ""
    with path.open("r+b") as f:
        f.truncate(end)
    return f"; cut a partial last row ({len(raw) - end} bytes) from {path.name}"
