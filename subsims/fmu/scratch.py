"""Scratch directories for extracted FMUs that do not outlive their process, even one that was killed.

A process removes its own directory at exit; SIGKILL (or a crash inside an FMU binary) skips that. So the
process holds a lock on a file in its directory for as long as it lives, and every new directory first
removes this user's old ones whose lock is free: their owner is gone. A lock, not a PID, because a
process in another PID namespace sharing the temporary directory would look dead by its PID.
"""

from __future__ import annotations

import atexit
import fcntl
import os
import shutil
import tempfile
import time
from pathlib import Path

LOCK = ".owner.lock"
_held: dict[str, tuple[Path, int]] = {}  # prefix -> (this process's directory, the fd holding its lock)


def process_dir(prefix: str) -> Path:
    """This process's directory ``<tmp>/<prefix>XXXX``, made on the first call and removed at exit."""
    if prefix in _held:
        return _held[prefix][0]
    sweep(prefix)
    path = Path(tempfile.mkdtemp(prefix=prefix))
    fd = os.open(path / LOCK, os.O_RDWR | os.O_CREAT, 0o600)
    fcntl.flock(fd, fcntl.LOCK_EX)
    _held[prefix] = (path, fd)
    atexit.register(_remove, prefix)
    return path


def _remove(prefix: str) -> None:
    path, fd = _held.pop(prefix)
    shutil.rmtree(path, ignore_errors=True)
    os.close(fd)


def sweep(prefix: str, min_age: float = 60.0) -> None:
    """Remove this user's ``<prefix>*`` directories whose owner died: their lock is free, or they have none and
    are older than ``min_age`` seconds (one being made this moment has none yet)."""
    for path in Path(tempfile.gettempdir()).glob(prefix + "*"):
        try:
            st = path.stat()
            if st.st_uid != os.getuid() or not path.is_dir():
                continue
            fd = os.open(path / LOCK, os.O_RDWR)
        except FileNotFoundError:
            if time.time() - st.st_mtime >= min_age:
                shutil.rmtree(path, ignore_errors=True)
            continue
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:  # held: its owner lives
            continue
        else:
            shutil.rmtree(path, ignore_errors=True)
        finally:
            os.close(fd)
