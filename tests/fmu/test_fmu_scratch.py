"""Extracted FMUs do not pile up in the temporary directory when their process is killed."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from subsims.fmu.scratch import process_dir, sweep

HOLD = "import sys, time; from subsims.fmu.scratch import process_dir; print(process_dir(sys.argv[1]), flush=True); " \
       "time.sleep(60)"


def holder(prefix: str) -> tuple[subprocess.Popen, Path]:
    proc = subprocess.Popen([sys.executable, "-c", HOLD, prefix], stdout=subprocess.PIPE, text=True)
    return proc, Path(proc.stdout.readline().strip())


def test_a_killed_owners_directory_is_swept_and_a_live_ones_is_kept() -> None:
    prefix = f"cosim-test-scratch-{os.getpid()}-"
    (killed, dead_dir), (alive, live_dir) = holder(prefix), holder(prefix)
    try:
        (dead_dir / "model.so").write_bytes(b"x")
        killed.send_signal(signal.SIGKILL)
        killed.wait(10)
        assert dead_dir.is_dir()  # SIGKILL skipped its clean-up
        mine = process_dir(prefix)  # sweeps first
        assert not dead_dir.exists()
        assert live_dir.is_dir() and mine.is_dir() and mine != live_dir
        sweep(prefix)  # neither owner's lock is free
        assert live_dir.is_dir() and mine.is_dir()
    finally:
        for proc in (killed, alive):
            proc.kill()
            proc.wait(10)
    sweep(prefix)
    assert not live_dir.exists()


def test_a_directory_without_a_lock_goes_only_once_it_is_old(tmp_path: Path) -> None:
    prefix = f"cosim-test-scratch-nolock-{os.getpid()}-"
    young = Path(tempfile.mkdtemp(prefix=prefix))
    try:
        sweep(prefix)
        assert young.is_dir()  # it may be being made this moment
        old = time.time() - 120
        os.utime(young, (old, old))
        sweep(prefix)
        assert not young.exists()
    finally:
        if young.exists():
            young.rmdir()
