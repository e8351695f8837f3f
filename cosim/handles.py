"""Coordinator-side subsim handles: one interface, in-process or over Zenoh.

The coupler uses only :class:`SubsimHandle`. ``start_run_interval`` returns at once with a
pending result, so a stage of remote subsims computes concurrently without threads.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import zenoh

from cosim.contract import CosimError, ProtocolError, SubsimDied, SubsimError
from cosim.protocol.bus import alive_key, check_name, rpc_key
from cosim.protocol.messages import ErrorInfo, decode_reply, encode_request
from cosim.runtime import DEFAULT_HISTORY, Runtime
from cosim.subsim import Port, Subsim

Pending = Callable[[], "IntervalResult"]


@dataclass(frozen=True)
class Description:
    name: str
    model: str
    inputs: dict[str, Port]
    outputs: dict[str, Port]
    algebraic: bool
    configured: bool
    time: float | None
    history_limit: int
    protocol: int

    @classmethod
    def from_result(cls, r: Mapping[str, Any]) -> Description:
        def ports(m: Mapping[str, Mapping]) -> dict[str, Port]:
            return {k: Port(p["size"], p.get("unit", ""), p.get("doc", "")) for k, p in m.items()}

        return cls(
            r["name"], r["model"], ports(r["inputs"]), ports(r["outputs"]), r["algebraic"], r["configured"],
            r.get("time"), r["history_limit"], r["protocol"],
        )


@dataclass(frozen=True)
class IntervalResult:
    t: np.ndarray
    outputs: dict[str, np.ndarray]
    end_time: float


@dataclass(frozen=True)
class SubsimState:
    time: float
    state: np.ndarray
    model: str


class SubsimHandle:
    """What the coupler sees of a subsim. Subclasses implement :meth:`_begin`."""

    name: str

    def _begin(self, cmd: str, args: dict[str, Any]) -> Callable[[], dict]:
        """Send ``cmd``; return a function that waits for and returns its checked result."""
        raise NotImplementedError

    def _call(self, cmd: str, **args: Any) -> dict:
        return self._begin(cmd, args)()

    def describe(self) -> Description:
        return Description.from_result(self._call("describe"))

    def configure(self, params: Mapping[str, Any], t0: float = 0.0) -> Description:
        return Description.from_result(self._call("configure", params=dict(params), t0=float(t0)))

    def start_run_interval(
        self, times: np.ndarray, inputs: Mapping[str, np.ndarray], interp: str = "linear", commit: bool = False
    ) -> Pending:
        """Send ``run_interval`` now, wait later. ``commit``: commit the latest trial first, in the same request."""
        args = {"t": np.asarray(times), "inputs": dict(inputs), "interp": interp}
        if commit:
            args["commit"] = True
        wait = self._begin("run_interval", args)
        return lambda: (lambda r: IntervalResult(r["t"], r["outputs"], r["end_time"]))(wait())

    def run_interval(
        self, times: np.ndarray, inputs: Mapping[str, np.ndarray], interp: str = "linear", commit: bool = False
    ) -> IntervalResult:
        return self.start_run_interval(times, inputs, interp, commit)()

    def start_commit(self) -> Callable[[], float]:
        """Send ``commit`` now, wait later: a coordinator commits all subsims in one round trip."""
        wait = self._begin("commit", {})
        return lambda: wait()["time"]

    def commit(self) -> float:
        return self.start_commit()()

    def rollback(self, to_time: float | None = None) -> float:
        return self._call("rollback", **({} if to_time is None else {"to_time": float(to_time)}))["time"]

    def get_state(self) -> SubsimState:
        r = self._call("get_state")
        return SubsimState(r["time"], r["state"], r["model"])

    def set_state(self, snapshot: SubsimState) -> float:
        return self._call("set_state", time=snapshot.time, state=snapshot.state)["time"]

    def status(self) -> dict:
        return self._call("status")

    def shutdown(self) -> None:
        self._call("shutdown")

    def close(self) -> None:
        """Release coordinator-side resources (not the subsim)."""


class InProcessHandle(SubsimHandle):
    """Direct calls on a :class:`Runtime` in this process (runs eagerly; same results as remote)."""

    def __init__(self, model: Subsim | Runtime, name: str | None = None, history_limit: int = DEFAULT_HISTORY):
        self.runtime = model if isinstance(model, Runtime) else Runtime(model, name, history_limit)
        self.name = self.runtime.name

    def _begin(self, cmd: str, args: dict[str, Any]) -> Callable[[], dict]:
        try:
            result = self.runtime.handle(cmd, args)
        except CosimError as exc:
            error = SubsimError(exc.code, exc.message, self.name, cmd)

            def fail() -> dict:  # raised when the caller collects, as a remote error would be
                raise error

            return fail
        return lambda: result


# How long a waiting coordinator polls for a reply before it blocks. A thread blocked in recv() is
# woken through the scheduler, which on a small VM adds 40-60 us to every round trip (measured: a
# bare request/reply 104 -> 45 us when polled). Polling yields the CPU at each turn, and stops after
# this long so that a slow request costs no more than this of busy waiting.
POLL_SECONDS = 0.002


def _first_reply(replies: Any) -> Any:
    """The first reply of a request, or None when the request ended with none."""
    deadline = time.perf_counter() + POLL_SECONDS
    while time.perf_counter() < deadline:
        try:
            reply = replies.try_recv()
        except zenoh.ZError:  # the channel is closed and empty: no reply will come
            return None
        if reply is not None:
            return reply
        os.sched_yield()
    return next(iter(replies), None)


class RemoteHandle(SubsimHandle):
    """Zenoh request/reply to ``cosim/<run>/<name>/rpc``; liveliness reports a dead process at once."""

    def __init__(self, session: zenoh.Session, run: str, name: str, timeout: float = 60.0) -> None:
        self.session, self.run, self.name = session, run, check_name(name, "subsim name")
        self._key = rpc_key(run, name)
        self.timeout = timeout
        # A declared querier costs about 35 us less per request than session.get. Its timeout is fixed
        # at declaration, and a querier declared late may not see the subsim yet, so a request made
        # after ``timeout`` changed goes through session.get instead.
        self._querier = session.declare_querier(self._key, timeout=timeout, consolidation=zenoh.ConsolidationMode.NONE)
        self._querier_timeout = timeout
        self._alive = threading.Event()
        self._died = threading.Event()
        self._liveliness = session.liveliness().declare_subscriber(
            alive_key(run, name), self._on_liveliness, history=True
        )

    def _on_liveliness(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            self._died.clear()
            self._alive.set()
        else:
            self._alive.clear()
            self._died.set()

    @property
    def alive(self) -> bool:
        return self._alive.is_set()

    def wait_alive(self, timeout: float) -> bool:
        """True once the process's liveliness token has been seen (within ``timeout`` seconds)."""
        return self._alive.wait(timeout)

    def wait_ready(self, timeout: float = 10.0) -> None:
        """Wait for the liveliness token and a first answered ``status`` (declarations propagate late)."""
        deadline = time.monotonic() + timeout
        if not self.wait_alive(timeout):
            raise SubsimError("no_responder", f"no process appeared within {timeout:g} s", self.name, "connect")
        while True:
            replies = list(self.session.get(self._key, payload=encode_request("status"), timeout=1.0))
            if replies and replies[0].ok is not None:
                return
            if time.monotonic() > deadline:
                raise SubsimError("no_responder", f"not answering after {timeout:g} s", self.name, "connect")
            time.sleep(0.01)

    def _begin(self, cmd: str, args: dict[str, Any]) -> Callable[[], dict]:
        if self._died.is_set():
            raise SubsimDied("no_responder", "the subsim process is gone (liveliness lost)", self.name, cmd)
        payload = encode_request(cmd, args)
        if self.timeout == self._querier_timeout:
            replies = self._querier.get(payload=payload)
        else:
            replies = self.session.get(
                self._key, payload=payload, timeout=self.timeout, consolidation=zenoh.ConsolidationMode.NONE
            )
        return lambda: self._finish(cmd, replies)

    def _finish(self, cmd: str, replies: Any) -> dict:
        reply = _first_reply(replies)
        if reply is not None:
            if reply.ok is None:
                text = reply.err.payload.to_bytes().decode(errors="replace")
                if self._died.is_set():
                    raise SubsimDied("no_responder", f"the process died during the request ({text})", self.name, cmd)
                raise SubsimError("timeout", f"no reply within {self.timeout:g} s ({text})", self.name, cmd)
            try:
                result = decode_reply(cmd, reply.ok.payload.to_bytes())
            except ProtocolError as exc:
                raise SubsimError(exc.code, f"malformed reply: {exc.message}", self.name, cmd) from None
            if isinstance(result, ErrorInfo):
                raise SubsimError(result.code, result.message, result.subsim, result.command)
            return result
        # zero replies: nobody serves the key (not started, or died mid-request)
        self._died.wait(0.5 if self._alive.is_set() else 0.0)
        reason = "the process died during the request" if self._died.is_set() else "no process serves this subsim"
        raise SubsimDied("no_responder", reason, self.name, cmd)

    def close(self) -> None:
        for entity in (self._querier, self._liveliness):
            try:
                entity.undeclare()
            except Exception:
                pass
