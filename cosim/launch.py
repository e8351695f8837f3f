"""Start subsim processes on this machine and stop them reliably.

Used by ``cosim run`` and by the pytest fixtures in :mod:`cosim.testing`.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from dataclasses import dataclass, field

import zenoh

from cosim.contract import SubsimError
from cosim.protocol.keys import coordinator_alive_key, new_run_id
from cosim.protocol.transport.client import RemoteHandle
from cosim.protocol.transport.session import client_config, open_router


def subsim_command(
    module: str, endpoint: str, run: str, name: str, model: str | None = None, python: str = sys.executable
) -> list[str]:
    """``python -m module`` for a subsim package, or ``python -m cosim.serve model`` for any class."""
    head = [python, "-m", "cosim.serve", model] if model else [python, "-m", module]
    return [*head, "--connect", endpoint, "--run", run, "--name", name]


@dataclass
class SubsimProcess:
    """A local subsim process and its handle."""

    name: str
    popen: subprocess.Popen
    handle: RemoteHandle

    def stop(self, grace: float = 3.0) -> int:
        """Ask for ``shutdown``, then SIGTERM, then SIGKILL; always reaps the process."""
        if self.popen.poll() is None and self.handle.alive:
            try:
                self.handle.timeout = min(self.handle.timeout, grace)  # the handle is closed below anyway
                self.handle.shutdown()
            except Exception:
                pass
        try:
            return self.popen.wait(grace)
        except subprocess.TimeoutExpired:
            self.popen.terminate()
        try:
            return self.popen.wait(grace)
        except subprocess.TimeoutExpired:
            self.popen.kill()
            return self.popen.wait()
        finally:
            self.handle.close()


@dataclass
class Bus:
    """The coordinator's router session, its endpoint and the run id that namespaces every key."""

    session: zenoh.Session
    endpoint: str
    run: str
    processes: list[SubsimProcess] = field(default_factory=list)

    @classmethod
    def open(cls, listen: str = "tcp/127.0.0.1:0", run: str | None = None) -> Bus:
        session, endpoint = open_router(listen)
        bus = cls(session, endpoint, run or new_run_id())
        bus._token = session.liveliness().declare_token(coordinator_alive_key(bus.run))
        return bus

    def open_requests(self) -> zenoh.Session:
        """A client session of this router: each handle sends its requests from one of these (RemoteHandle)."""
        return zenoh.open(client_config(self.endpoint, 10.0))

    def attach(self, name: str, timeout: float = 60.0, wait: float = 10.0) -> RemoteHandle:
        """Handle to a subsim that is (or soon will be) serving ``name`` in this run."""
        handle = RemoteHandle(self.session, self.run, name, timeout=timeout, requests=self.open_requests)
        try:
            handle.wait_ready(wait)
        except Exception:
            handle.close()
            raise
        return handle

    def spawn(
        self,
        module: str,
        name: str,
        timeout: float = 60.0,
        wait: float = 20.0,
        quiet: bool = False,
        model: str | None = None,
    ) -> SubsimProcess:
        """Start ``python -m module`` (or ``cosim.serve model``) as subsim ``name``; wait until it answers."""
        env = dict(os.environ)
        env.setdefault("PYTHONUNBUFFERED", "1")
        popen = subprocess.Popen(
            subsim_command(module, self.endpoint, self.run, name, model),
            env=env,
            stdout=subprocess.DEVNULL if quiet else None,
            stderr=subprocess.DEVNULL if quiet else None,
        )
        handle = RemoteHandle(self.session, self.run, name, timeout=timeout, requests=self.open_requests)
        proc = SubsimProcess(name, popen, handle)
        self.processes.append(proc)
        try:
            _wait_ready_or_exit(handle, popen, wait)
        except BaseException:
            proc.stop(grace=1.0)
            raise
        return proc

    def close(self) -> None:
        """Stop every spawned process, then close the session (the order matters: see zenoh-notes P1)."""
        for proc in reversed(self.processes):
            proc.stop()
        self.processes.clear()
        self.session.close()

    def __enter__(self) -> Bus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _wait_ready_or_exit(handle: RemoteHandle, popen: subprocess.Popen, wait: float) -> None:
    deadline = time.monotonic() + wait
    while time.monotonic() < deadline:
        if popen.poll() is not None:
            raise SubsimError("no_responder", f"process exited with code {popen.returncode}", handle.name, "spawn")
        if handle.wait_alive(0.05):
            handle.wait_ready(max(deadline - time.monotonic(), 0.1))
            return
    raise SubsimError("no_responder", f"did not come up within {wait:g} s", handle.name, "spawn")
