"""Result files on disk: their names, the lock a run holds on them, checks before launch, atomic writes.

Every file of a run is named after its results file ``x.csv`` / ``x.npz``, so runs of one scenario
into different files (or formats) never share one:

* ``x.csv.diag.csv`` / ``x.npz.diag.csv``: per-interval diagnostics;
* ``x.csv.meta.json``: columns and units of a CSV (an NPZ holds its own ``units``);
* ``x.npz.partial``: the NPZ's samples streamed as each interval commits; the NPZ is built from it
  when the run ends (then it is removed), or by ``cosim recover x.npz`` after the coordinator was
  killed;
* ``x.csv.lock`` / ``x.npz.lock``: held (``flock``) by the run writing the file, with its pid inside.

A new run writes them under staged names (``.x.csv.staged.tmp-<pid>``) until its first interval is in, so a run
that stops before then leaves the files as they were (a result ``--overwrite`` was to replace included).

The lock is an OS lock, so a run that died (even by SIGKILL) holds nothing: its lock file is taken
over by the next run.
"""

from __future__ import annotations

import errno
import fcntl
import glob
import hashlib
import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

STREAM_MAGIC = b"COSIM-PARTIAL 1\n"


class OutputError(RuntimeError):
    """An output file cannot be used or written; the message is one actionable line."""


class OutputWriteError(OutputError):
    """Writing failed during the run (disk full, I/O error); the files end at their last whole interval."""


def diag_path(path: Path) -> Path:
    return path.with_name(path.name + ".diag.csv")


def meta_path(path: Path) -> Path:
    return path.with_name(path.name + ".meta.json")


def stream_path(path: Path) -> Path:
    return path.with_name(path.name + ".partial")


def resume_path(path: Path) -> Path:
    """Where an interrupted run's latest resume point is kept (``cosim.resume``)."""
    return path.with_name(path.name + ".resume.npz")


STAGED = ".staged.tmp-"  # what a run writes before its first interval is in (removed as stale like atomic writes')


def staged(path: Path) -> Path:
    """Where a new run writes ``path`` until its first interval is written (``.x.csv.staged.tmp-<pid>``)."""
    return path.with_name(f".{path.name}{STAGED}{os.getpid()}")


def symlink_target(path: Path) -> Path:
    """The file ``path`` names: itself, or the target of a symbolic link (a rename onto the link would replace the
    link, where writing through it writes its target)."""
    return path.resolve() if path.is_symlink() else path


def lock_path(path: Path) -> Path:
    return path.with_name(path.name + ".lock")


def is_npz(path: Path) -> bool:
    return path.suffix == ".npz"


def run_files(path: Path) -> list[Path]:
    """Every file a run into ``path`` writes (besides its lock)."""
    if is_npz(path):
        return [path, stream_path(path), diag_path(path), resume_path(path)]
    return [path, meta_path(path), diag_path(path), resume_path(path)]


def describe_oserror(exc: OSError) -> str:
    """``No space left on device`` etc.: the reason without Python's ``[Errno 28]``."""
    return exc.strerror or str(exc)


class OutputLock:
    """An exclusive ``flock`` on ``<path>.lock`` (which holds the owner's pid). Released by :meth:`release`
    or by the death of the process."""

    def __init__(self, path: Path, fd: int) -> None:
        self.path, self.file, self._fd = path, lock_path(path.resolve()), fd

    @classmethod
    def acquire(cls, path: Path) -> OutputLock:
        """Lock ``path`` for this process; OutputError naming the holder if another live run has it.
        The lock sits beside the file a symlink points to, so two names of one file share it."""
        lock = lock_path(path.resolve())
        for _ in range(20):  # the holder may remove the file between our open and our flock: then again
            try:
                fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
            except OSError as exc:
                raise OutputError(f"cannot write {path}: cannot create {lock} ({describe_oserror(exc)}): "
                                  "choose another --output") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = _read_pid(fd)
                os.close(fd)
                raise OutputError(f"{path} is being written by another cosim run (pid {holder or 'unknown'}, "
                                  f"lock {lock}): wait for it to finish or choose another --output") from None
            try:
                same = _same_file(os.fstat(fd), os.stat(lock))
            except FileNotFoundError:
                same = False
            if same:
                try:
                    os.ftruncate(fd, 0)
                    os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
                except OSError as exc:  # a full disk: not even the pid fits
                    held = cls(path, fd)
                    held.release()
                    raise OutputError(f"cannot write {path}: {write_failure(exc, lock)}") from None
                return cls(path, fd)
            os.close(fd)  # we locked a file its holder had just removed: take the new one
        raise OutputError(f"cannot lock {lock}: it keeps being replaced; is another program using it?")

    def release(self) -> None:
        """Remove the lock file and unlock; idempotent."""
        if self._fd is None:
            return
        try:
            if _same_file(os.fstat(self._fd), os.stat(self.file)):
                os.unlink(self.file)
        except OSError:
            pass
        os.close(self._fd)
        self._fd = None

    @property
    def held(self) -> bool:
        return self._fd is not None


def _same_file(a: os.stat_result, b: os.stat_result) -> bool:
    return (a.st_dev, a.st_ino) == (b.st_dev, b.st_ino)


def _read_pid(fd: int) -> int | None:
    try:
        return int(os.pread(fd, 32, 0).split()[0])
    except (OSError, ValueError, IndexError):
        return None


def reserve_output(path: Path, overwrite: bool = False) -> OutputLock:
    """Before anything is launched: lock ``path``, refuse an existing result unless ``overwrite``, and
    prove every file of the run can be created (by creating it: permission bits say nothing to root).

    Raises OutputError (one line: what, and what to do). Nothing existing is modified.
    """
    path = Path(path)
    if path.exists() and path.is_dir():
        raise OutputError(f"--output {path} is a directory: give a file name ending in .csv or .npz")
    for parent in [path.parent, *path.parent.parents]:
        if parent.exists() and not parent.is_dir():
            raise OutputError(f"cannot write {path}: {parent} is a file, not a directory: choose another --output")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create the directory {path.parent} for {path} ({describe_oserror(exc)}): "
                          "choose another --output") from None
    lock = OutputLock.acquire(path)
    try:
        # an atomic write's, a probe's or a staged file left by a kill, of this run's names only (not r.csv.2.csv's:
        # another run's); the lock is ours, so no run writes these now
        names = {name for f in run_files(path) for name in (f, symlink_target(f))}
        for name in names:
            own = glob.escape(f".{name.name}")  # (a [ in a file name is not a pattern)
            for stale in [*name.parent.glob(f"{own}.tmp-*"), *name.parent.glob(f"{own}{STAGED}*")]:
                stale.unlink(missing_ok=True)
        if not overwrite:  # the result, and its companions too (diagnostics, units, an NPZ's stream)
            for f in run_files(path):
                if f.exists():
                    hint = f"recover it with `cosim recover {path}`, " if f == stream_path(path) else ""
                    if resume_path(path).exists():
                        hint = "continue that run with --resume, "
                    raise OutputError(f"{f} exists: {hint}pass --overwrite to replace it, or choose another --output")
        for f in run_files(path):
            probe_writable(f)
    except BaseException:
        lock.release()
        raise
    return lock


def probe_writable(path: Path) -> None:
    """Open an existing ``path`` for appending (writing nothing), or create a file beside it under the name of an
    atomic write of it and remove that again: a kill in between leaves what the next run sweeps as stale, not an
    empty file under the real name (which then read as a result, or a damaged resume point)."""
    if path.exists() or path.is_symlink():
        try:
            fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CLOEXEC)
        except OSError as exc:
            raise OutputError(f"cannot write {path} ({describe_oserror(exc)}): choose another --output") from None
        os.close(fd)
        return
    probe = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_CLOEXEC, 0o644)
    except OSError as exc:
        raise OutputError(f"cannot create {path} ({describe_oserror(exc)}): choose another --output") from None
    os.close(fd)
    os.unlink(probe)


class AppendFile:
    """A file written by whole records: each :meth:`append` is one ``write`` of complete rows, and a
    failed one (disk full, I/O error) is cut back, so the file always ends at the last whole record."""

    def __init__(self, path: Path, what: str, keep: int | None = None, digest: Any = None) -> None:
        """``keep``: go on with the file's first ``keep`` bytes (a resumed run) instead of an empty file; ``digest``:
        their SHA-256 (a ``hashlib`` object), else read from the file. :meth:`mark` tells what is written."""
        self.path, self.what = path, what
        try:
            self._sha: Any = digest if digest is not None else (prefix_digest(path, keep) if keep else hashlib.sha256())
            self.fd: int | None = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_CLOEXEC | (0 if keep else os.O_TRUNC),
                                          0o644)
            if keep:
                os.ftruncate(self.fd, keep)
                os.lseek(self.fd, keep, os.SEEK_SET)
        except OSError as exc:
            raise OutputError(f"cannot create {path} ({describe_oserror(exc)}): choose another --output") from None
        self.size = keep or 0

    def append(self, data: bytes, ends_at: Callable[[], str] = lambda: "") -> None:
        """Write ``data`` completely or not at all (as far as the file's length shows)."""
        assert self.fd is not None, f"{self.path} is closed"
        view, start = memoryview(data), self.size
        try:
            while view:
                n = os.write(self.fd, view)
                view = view[n:]
                self.size += n
        except OSError as exc:
            self.cut(start)
            where = ends_at()
            free = "free space or " if exc.errno in (errno.ENOSPC, errno.EDQUOT) else ""  # (not for a read-only file)
            raise OutputWriteError(f"{failure_reason(exc)} writing {self.path} ({self.what})"
                                   f"{': ' + where if where else ''}; {free}choose another --output, then run "
                                   "again") from None
        if os.fstat(self.fd).st_nlink == 0:  # written to a file no name reaches any more: lost at close
            self.size = start
            raise OutputWriteError(f"{self.path} ({self.what}) was removed during the run (by another program?): "
                                   "what this run wrote there is lost; run again")
        if self._sha is not None:
            self._sha.update(data)

    def mark(self) -> tuple[int, str] | None:
        """(bytes written, their SHA-256): what a resume checks the file still holds; None once it was cut back."""
        return None if self._sha is None else (self.size, self._sha.hexdigest())

    def cut(self, size: int) -> None:
        """Cut the file back to its first ``size`` bytes (what a record written after them would undo), if it can."""
        assert self.fd is not None, f"{self.path} is closed"
        self._sha = None  # (a hash does not go back)
        try:
            os.ftruncate(self.fd, size)
            os.lseek(self.fd, size, os.SEEK_SET)
            self.size = size
        except OSError:
            pass

    def sync(self) -> None:
        """What is written, on disk (before a resume point that counts on it is saved: after a power cut the point
        must not name bytes the file lost)."""
        if self.fd is not None:
            try:
                os.fsync(self.fd)
            except OSError as exc:  # (the kernel may drop the pages that failed: a later write would not say so)
                raise OutputWriteError(f"{write_failure(exc, self.path)} ({self.what}, when its rows were made "
                                       "durable), then run again") from None

    def close(self, sync: bool = True) -> None:
        if self.fd is None:
            return
        try:
            if sync:
                os.fsync(self.fd)
        except OSError:
            pass
        finally:
            os.close(self.fd)
            self.fd = None


def prefix_digest(path: Path, size: int) -> Any:
    """SHA-256 of the first ``size`` bytes of ``path`` (a ``hashlib`` object, to go on with)."""
    sha = hashlib.sha256()
    with open(path, "rb") as f:
        while size > 0:
            chunk = f.read(min(size, 1 << 20))
            if not chunk:
                break
            sha.update(chunk)
            size -= len(chunk)
    return sha


def atomic_write(path: Path, write: Callable[[BinaryIO], None]) -> None:
    """Write ``path`` under a temporary name in its directory, fsync, then rename: readers see the old
    file or the whole new one (a symbolic link's target, the link kept). Raises OutputError (the temporary file is
    removed)."""
    path = symlink_target(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        with open(tmp, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        _remove_quietly(tmp)
        raise OutputWriteError(f"{write_failure(exc, path)}, then run again") from None
    except BaseException:
        _remove_quietly(tmp)
        raise


def _remove_quietly(path: Path) -> None:
    """Remove ``path`` if it is there and can be removed (a read-only file system refuses even that: the write's own
    error is the one to report)."""
    try:
        path.unlink(missing_ok=True)
    except OSError:
        pass


def failure_reason(exc: OSError) -> str:
    """'disk full' (also over a quota), or the system's reason."""
    return "disk full" if exc.errno in (errno.ENOSPC, errno.EDQUOT) else describe_oserror(exc)


def write_failure(exc: OSError, path: Path) -> str:
    """Why writing ``path`` failed and what to do, for a line the user acts on: 'disk full writing x; free space
    or choose another place', 'the directory of x is gone ...', or the system's reason."""
    if exc.errno == errno.ENOENT and not path.parent.exists():
        return f"cannot write {path}: its directory {path.parent} was removed during the run; choose another place"
    free = "free space or " if exc.errno in (errno.ENOSPC, errno.EDQUOT) else ""
    return f"{failure_reason(exc)} writing {path}; {free}choose another place"


# --- the NPZ's streamed samples ------------------------------------------------------------------

def stream_header(columns: list[str], units: list[str]) -> bytes:
    return STREAM_MAGIC + json.dumps({"columns": columns, "units": units}).encode() + b"\n"


def stream_head(path: Path) -> tuple[list[str], list[str], int]:
    """Columns and units of a ``.partial`` stream, and the byte offset of its first row."""
    with path.open("rb") as f:
        if f.read(len(STREAM_MAGIC)) != STREAM_MAGIC:
            raise ValueError(f"{path} is not a cosim sample stream")
        head = json.loads(f.readline())
        return list(head["columns"]), list(head["units"]), f.tell()


def read_stream(path: Path) -> tuple[list[str], list[str], np.ndarray]:
    """Columns, units and the whole rows of a ``.partial`` stream (a torn last row is left out)."""
    columns, units, offset = stream_head(path)
    n = (path.stat().st_size - offset) // (8 * len(columns))
    data = np.fromfile(path, dtype="<f8", count=n * len(columns), offset=offset).reshape(n, len(columns))
    return columns, units, data


def write_npz(path: Path, columns: list[str], units: list[str], data: np.ndarray) -> None:
    """The NPZ (``columns``, ``units``, ``data``), atomically."""
    atomic_write(path, lambda f: np.savez(f, columns=np.array(columns), units=np.array(units), data=data))
