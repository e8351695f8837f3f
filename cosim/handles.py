"""Coordinator-side subsim handles: one interface for a subsim in this process or elsewhere.

The driver uses only :class:`SubsimHandle`. ``start_run_interval`` returns at once with a
pending result, so a stage of remote subsims computes concurrently without threads. The remote
handle over Zenoh is :class:`cosim.protocol.transport.client.RemoteHandle`; this module imports
no transport.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cosim.contract import CosimError, SubsimError
from cosim.runtime import DEFAULT_HISTORY, Runtime
from cosim.subsim import Param, Port, Subsim

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
    params: dict[str, Param] = field(default_factory=dict)  # declared parameters (optional in a reply)

    @classmethod
    def from_result(cls, r: Mapping[str, Any]) -> Description:
        def ports(m: Mapping[str, Mapping]) -> dict[str, Port]:
            return {k: Port(p["size"], p.get("unit", ""), p.get("doc", "")) for k, p in m.items()}

        return cls(
            r["name"], r["model"], ports(r["inputs"]), ports(r["outputs"]), r["algebraic"], r["configured"],
            r.get("time"), r["history_limit"], r["protocol"],
            {k: Param(p.get("default"), p.get("unit", ""), p.get("doc", "")) for k, p in r.get("params", {}).items()},
        )


@dataclass(frozen=True)
class IntervalResult:
    t: np.ndarray
    outputs: dict[str, np.ndarray]
    end_time: float


def _interval_result(r: dict) -> IntervalResult:
    return IntervalResult(r["t"], r["outputs"], r["end_time"])


@dataclass(frozen=True)
class SubsimState:
    time: float
    state: np.ndarray
    model: str


class SubsimHandle:
    """What the coupler sees of a subsim. Subclasses implement :meth:`_begin`."""

    name: str
    deadline: float | None = None  # seconds a remote caller waits for a reply (ignored in-process)

    def _begin(self, cmd: str, args: dict[str, Any]) -> Callable[[], dict]:
        """Send ``cmd``; return a function that waits for and returns its checked result."""
        raise NotImplementedError

    def replied(self) -> bool:
        """Whether collecting every request sent so far would return at once (never blocks). In process:
        always (requests run when sent)."""
        return True

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
        return lambda: _interval_result(wait())

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
            error = SubsimError(exc.code, exc.message, self.name, cmd, exc.traceback)

            def fail() -> dict:  # raised when the caller collects, as a remote error would be
                raise error

            return fail
        return lambda: result
