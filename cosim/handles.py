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

from cosim.contract import PROTOCOL_VERSION, CosimError, MalformedReply, SubsimError
from cosim.runtime import DEFAULT_HISTORY, ModelFactory, Runtime, float_samples, maker_name
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
    code: dict[str, str] = field(default_factory=dict)  # module -> digest of its file (cosim.importing.code_digests)
    not_ports: dict[str, str] = field(default_factory=dict)  # variable -> why it is no port (optional in a reply)

    @classmethod
    def from_result(cls, r: Mapping[str, Any]) -> Description:
        def ports(m: Mapping[str, Mapping]) -> dict[str, Port]:
            return {k: Port(p["size"], p.get("unit", ""), p.get("doc", "")) for k, p in m.items()}

        return cls(
            r["name"], r["model"], ports(r["inputs"]), ports(r["outputs"]), r["algebraic"], r["configured"],
            r.get("time"), r["history_limit"], r["protocol"],
            {k: Param(p.get("default"), p.get("unit", ""), p.get("doc", "")) for k, p in r.get("params", {}).items()},
            dict(r.get("code", {})), dict(r.get("not_ports", {})),
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
    # Whether replies are checked against the description (what the subsim's runtime guarantees in this process, a
    # subsim written elsewhere may get wrong): the name and protocol it describes, each run's outputs and times.
    checks_replies = False
    outputs: Mapping[str, Port] | None = None  # the described outputs, once described or configured

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
        return self._described("describe", self._call("describe"))

    def configure(self, params: Mapping[str, Any], t0: float = 0.0) -> Description:
        return self._described("configure", self._call("configure", params=dict(params), t0=float(t0)))

    def _described(self, cmd: str, result: Mapping[str, Any]) -> Description:
        d = Description.from_result(result)
        if self.checks_replies:
            if d.name != self.name:
                raise self._malformed(cmd, f"it describes itself as {d.name!r}, but serves as {self.name!r} (the "
                                           "description's name is the name it was started with, its --name)")
            if d.protocol != PROTOCOL_VERSION:
                raise MalformedReply("version", f"it speaks protocol {d.protocol!r}, this coordinator "
                                     f"{PROTOCOL_VERSION}", self.name, cmd)
        self.outputs = d.outputs
        return d

    def _malformed(self, cmd: str, message: str) -> MalformedReply:
        return MalformedReply("bad_value", message, self.name, cmd)

    def start_run_interval(
        self, times: np.ndarray, inputs: Mapping[str, np.ndarray], interp: str = "linear", commit: bool = False
    ) -> Pending:
        """Send ``run_interval`` now, wait later. ``commit``: commit the latest trial first, in the same request."""
        args = {"t": np.asarray(times), "interp": interp,
                "inputs": {k: v if type(v) is np.ndarray and v.dtype.kind == "f" else self._as_array(k, v)
                           for k, v in inputs.items()}}
        if commit:
            args["commit"] = True
        wait = self._begin("run_interval", args)
        if self.checks_replies and self.outputs is not None:
            return lambda: self._checked(wait(), args["t"])
        return lambda: _interval_result(wait())

    def _as_array(self, port: str, value: Any) -> np.ndarray:
        """Samples given as nested lists (as a handle in this process takes them) as an array, to go on the wire;
        what is no array of real numbers is refused as in this process (not as a wire format or codec error)."""
        try:
            return float_samples(port, value)
        except CosimError as exc:
            raise SubsimError(exc.code, exc.message, self.name, "run_interval") from None

    def _checked(self, r: dict, times: np.ndarray) -> IntervalResult:
        """A run_interval reply that holds what the description and the request say it must, or a one-line error
        naming what it got wrong (a missing output reached the results writer as a KeyError)."""
        outputs, described = r["outputs"], self.outputs
        assert described is not None
        times = np.ascontiguousarray(times, dtype=np.float64)  # as it went on the wire (a caller may give ints)
        if outputs.keys() != described.keys():
            missing, unknown = sorted(described.keys() - outputs.keys()), sorted(outputs.keys() - described.keys())
            parts = [f"missing output(s) {missing}"] if missing else []
            parts += [f"unknown output(s) {unknown}"] if unknown else []
            raise self._malformed("run_interval", f"{'; '.join(parts)} (described: "
                                                  f"{', '.join(described) or 'none'})")
        n = len(times)
        for name, port in described.items():
            if outputs[name].shape != (n, port.size):
                raise self._malformed("run_interval", f"output {name!r} has shape {list(outputs[name].shape)}, "
                                      f"needs [{n}, {port.size}] ({n} samples of its size {port.size})")
        t = r["t"]
        if t.shape != times.shape or t.tobytes() != times.tobytes():
            raise self._malformed("run_interval", "t is not the request's t, bit for bit (it is echoed)")
        if r["end_time"] != times[-1]:
            raise self._malformed("run_interval", f"end_time {r['end_time']!r} is not the request's last time "
                                                  f"{float(times[-1])!r}")
        return IntervalResult(t, outputs, r["end_time"])

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

    def __init__(self, model: Subsim | ModelFactory | Runtime, name: str | None = None,
                 history_limit: int = DEFAULT_HISTORY) -> None:
        try:
            self.runtime = model if isinstance(model, Runtime) else Runtime(model, name, history_limit)
        except CosimError as exc:  # its model cannot be built: as a remote handle's spawn would say it
            label = name or (type(model).__name__ if isinstance(model, Subsim) else maker_name(model) or "model")
            raise SubsimError(exc.code, exc.message, label, "start", exc.traceback) from None
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
