"""docs/tutorial.md, run as a newcomer runs it: its files written to a fresh directory, its commands
run there (``cosim`` and ``python`` are this interpreter), the "second terminal" as a background process.

Markers before each fenced block say what to do with it: ``<!-- file: NAME -->`` write it,
``<!-- run -->`` run each line, ``<!-- patch: NAME -->`` apply the diff to NAME, ``<!-- run: terminal 1 -->``
and ``<!-- run: terminal 2 -->`` start in the background, ``<!-- figure -->`` nothing (a drawing).
A block without a marker fails the test, so nothing in the tutorial goes unrun.
"""

from __future__ import annotations

import json
import os
import re
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm

from cosim.results import read_results

pytestmark = [pytest.mark.slow]  # the inner loop: pytest -m "not slow"

TUTORIAL = Path(__file__).parents[1] / "docs" / "tutorial.md"
BLOCK = re.compile(r"(?:<!-- (?P<marker>[^>]*?) -->\n)?```(?P<lang>\w*)\n(?P<body>.*?)```", re.S)


def blocks() -> list[tuple[str, str]]:
    found = [(m["marker"], m["body"]) for m in BLOCK.finditer(TUTORIAL.read_text())]
    unmarked = [body[:60] for marker, body in found if marker is None]
    assert not unmarked, f"blocks without a marker in {TUTORIAL.name}: {unmarked}"
    return found


def apply_patch(path: Path, diff: str) -> None:
    """A diff of one hunk without a header: ' ' context, '-' removed, '+' added lines."""
    lines = diff.splitlines()
    old = [line[1:] for line in lines if line[:1] in " -"]
    new = [line[1:] for line in lines if line[:1] in " +"]
    text = path.read_text()
    assert text.count("\n".join(old) + "\n") == 1, f"the patch context is not in {path.name} exactly once"
    path.write_text(text.replace("\n".join(old) + "\n", "\n".join(new) + "\n"))


def exact(t: np.ndarray) -> np.ndarray:
    """(x1, v1, x2, v2) of the tutorial's system from the matrix exponential, independent of any model code."""
    m1, k1, m2, k12 = 1.0, 100.0, 0.5, 50.0
    a = np.array([[0, 1, 0, 0], [-(k1 + k12) / m1, 0, k12 / m1, 0], [0, 0, 0, 1], [k12 / m2, 0, -k12 / m2, 0]])
    return np.array([expm(a * ti) @ np.array([0.0, 0.0, 0.1, 0.0]) for ti in t])


def check_results(work: Path, name: str = "twomass-distributed.csv") -> None:
    cols, data = read_results(work / "results" / name)
    assert cols == ["time", "wall.x[0]", "wall.v[0]", "free.x[0]", "free.F[0]"]
    assert data[-1, 0] == pytest.approx(2.0)
    z = exact(data[:, 0])
    assert np.abs(data[:, 1] - z[:, 0]).max() < 1e-6 and np.abs(data[:, 3] - z[:, 2]).max() < 1e-6
    assert np.abs(data[:, 4] - 50.0 * (z[:, 2] - z[:, 0])).max() < 1e-4


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.kill()
    proc.communicate()


CHECK_PANEL = ("python -c \"import numpy as np; from cosim import check_pure; from panel_subsim import PanelSubsim; "
               "t = np.linspace(0, 60, 4); check_pure(PanelSubsim(), {}, t, {'power': np.full((4, 1), 50.0)}); "
               "print('pure')\"")


def test_the_tutorial_runs_as_written(tmp_path: Path) -> None:
    work, bin_dir = tmp_path / "work", tmp_path / "bin"
    work.mkdir()
    bin_dir.mkdir()
    for name, run in (("cosim", f'"{sys.executable}" -m cosim.cli'), ("python", f'"{sys.executable}"')):
        (bin_dir / name).write_text(f'#!/bin/sh\nexec {run} "$@"\n')
        (bin_dir / name).chmod(0o755)
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}"}
    port = str(free_port())  # instead of the tutorial's 7447, which another run may hold
    background: list[subprocess.Popen] = []
    done: list[str] = []
    try:
        for marker, body in blocks():
            kind, _, arg = marker.partition(": ")
            if kind == "file":
                (work / arg).write_text(body)
            elif kind == "patch":
                apply_patch(work / arg, body)
            elif kind == "run" and arg == "":
                for line in body.splitlines():
                    r = subprocess.run(line, shell=True, cwd=work, env=env, capture_output=True, text=True,
                                       timeout=600)
                    assert r.returncode == 0, f"{line}\n{r.stdout}\n{r.stderr}"
                    done.append(line)
                    if line.startswith("cosim run"):
                        check_results(work)
                    if line.startswith("cosim plot"):
                        assert (work / "plots" / "wall.x.png").stat().st_size > 0
            elif kind == "run" and arg == "terminal 1":
                coordinator = subprocess.Popen(body.strip().replace("7447", port), shell=True, cwd=work, env=env,
                                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                background.append(coordinator)
                for line in coordinator.stderr:  # started when it waits for the external subsim
                    if line.startswith("cosim-attach "):
                        attach_env = json.loads(line.split(" ", 1)[1])["env"]  # the two values a user pastes
                        break
            elif kind == "run" and arg == "terminal 2":
                command = body.strip().replace("7447", port)
                for name, value in attach_env.items():
                    command = command.replace(f"{name}=...", f"{name}={value}")
                second = subprocess.Popen(command, shell=True, cwd=work, env=env,
                                          stderr=subprocess.PIPE, text=True)
                background.append(second)
                out, err = coordinator.communicate(timeout=600)
                assert coordinator.returncode == 0, err
                assert second.wait(timeout=60) == 0  # the coordinator's shutdown ends it
                check_results(work, "twomass-remote.csv")
                remote, local = (work / "results" / f"twomass-{n}.csv" for n in ("remote", "distributed"))
                assert remote.read_bytes() == local.read_bytes()  # "the same results"
                done.append("terminal 2")
            else:
                assert kind == "figure", f"unknown marker {marker!r}"
    finally:
        for proc in background:
            stop(proc)
    assert done == ["cosim describe twomass.toml", "cosim run twomass.toml",
                    "cosim plot results/twomass-distributed.csv", "terminal 2",
                    "python -m pytest -q test_wall_mass.py", CHECK_PANEL]
