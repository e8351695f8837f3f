"""Check a running subsim, in any language, against docs/protocol.md.

    python -m cosim.conformance ENDPOINT RUN NAME [--params JSON] [--interval H] [--samples N] [--wait S]
                                [--ending shutdown|coordinator]

The checker is the coordinator: it opens a Zenoh router listening on ENDPOINT (``tcp/127.0.0.1:0``
picks a free port, printed on stderr) with run id RUN, waits for the subsim NAME to appear (start it
with ``--connect <endpoint> --run RUN --name NAME`` and the two environment variables it prints, the
subsim's key and the router login, as ``cosim run`` gives them to an external subsim), then sends it well-formed and
malformed requests and checks every reply: envelope and result types, error codes, that nothing
committed changes on a failed request, determinism, commit / rollback / stale-trial / set_state
semantics and the history they keep, the seals of section 4.1 (no reply to what is not sealed for this
request), the request cap, and that ``shutdown`` (or, with ``--ending coordinator``, the checker's
token withdrawn) ends it. Give it a freshly started subsim: it configures it (with
``--params``, default ``{}``: the model's own defaults) and runs it on zero inputs from t0 = 0.

Each violation is printed on one line (``FAIL <check>: <what>``); the exit code is 0 when there is
none, 1 when there are violations, 2 when the subsim never appeared or the arguments are bad.
"""

from __future__ import annotations

import argparse
import json
import math
import secrets
import sys
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any

import msgpack
import numpy as np

from cosim.contract import COORDINATOR_SIDE, ERROR_CODES, PROTOCOL_VERSION, ProtocolError, SubsimError
from cosim.launch import Bus
from cosim.protocol.keys import alive_key, check_name, rpc_key
from cosim.protocol.messages import (
    REQUESTS,
    ErrorInfo,
    decode_reply,
    encode_request,
    next_seq,
    open_reply,
    seal_request,
)
from cosim.protocol.service import REPLAY_WINDOW, default_request_cap
from cosim.protocol.wire import encode_array
from cosim.subsim import Port

CAP_CHECKED = 64 * 2**20  # bytes: the largest default request cap the checker sends a body over
Send = Callable[[bytes], "bytes | None"]  # request payload -> reply payload (None: no reply at all)


def _pack(obj: Any) -> bytes:
    return msgpack.packb(obj, use_bin_type=True)


def _request(cmd: str, args: dict | None = None, **envelope: Any) -> bytes:
    return _pack({"v": PROTOCOL_VERSION, "cmd": cmd, **({"args": args} if args is not None else {}), **envelope})


class Checker:
    """Runs the checks over ``send``; ``violations`` collects one line per failure."""

    def __init__(self, send: Send, name: str) -> None:
        self.send, self.name = send, name
        self.violations: list[str] = []
        self.checks = 0
        self.description: dict | None = None  # what configure returned

    def fail(self, check: str, what: str) -> None:
        self.violations.append(f"FAIL {check}: {what}")

    def reply(self, check: str, cmd: str, payload: bytes) -> dict | ErrorInfo | None:
        """Send ``payload``; the decoded reply (checked against the result schema of ``cmd``), or None."""
        self.checks += 1
        raw = self.send(payload)
        if raw is None:
            self.fail(check, "no reply (or a Zenoh reply_err: a subsim must always reply with an error payload)")
            return None
        try:
            return decode_reply(cmd, raw)
        except ProtocolError as exc:
            self.fail(check, f"malformed reply [{exc.code}]: {exc.message}")
            return None

    def ok(self, check: str, cmd: str, args: dict | None = None) -> dict | None:
        r = self.reply(check, cmd, encode_request(cmd, args or {}))
        if isinstance(r, ErrorInfo):
            self.fail(check, f"refused: [{r.code}] {r.message}")
            return None
        return r

    def error(self, check: str, payload: bytes, codes: set[str], command: str) -> None:
        """``payload`` must get an error reply with one of ``codes``, naming this subsim and ``command``."""
        r = self.reply(check, command if command in REQUESTS else "status", payload)
        if r is None:
            return
        if not isinstance(r, ErrorInfo):
            self.fail(check, f"accepted; expected an error {sorted(codes)}")
            return
        if r.code not in codes:
            self.fail(check, f"error code {r.code!r}, expected {' or '.join(sorted(codes))} ({r.message})")
        if r.code not in ERROR_CODES or r.code in COORDINATOR_SIDE:
            self.fail(check, f"{r.code!r} is not an error code a subsim may send")
        if r.subsim != self.name:
            self.fail(check, f"error.subsim is {r.subsim!r}, expected {self.name!r}")
        if r.command != command:
            self.fail(check, f"error.command is {r.command!r}, expected {command!r}")
        if not r.message:
            self.fail(check, "error.message is empty")

    def committed(self) -> tuple[float, bytes] | None:
        r = self.ok("get_state", "get_state")
        return None if r is None else (r["time"], r["state"].tobytes())


def run_checks(send: Send, name: str, params: dict | None = None, interval: float = 0.1, samples: int = 5) -> Checker:
    """Every check on a fresh subsim reached through ``send``. Returns the checker with its violations."""
    c = Checker(send, name)
    d = c.ok("describe", "describe")
    if d is None:
        return c
    if d["name"] != name:
        c.fail("describe", f"name is {d['name']!r}, expected {name!r}")
    if d["protocol"] != PROTOCOL_VERSION:
        c.fail("describe", f"protocol is {d['protocol']!r}, expected {PROTOCOL_VERSION}")
    status = c.ok("status before configure", "status")
    if d["configured"] or (status and status["configured"]):
        c.fail("describe", "configured before configure: give the checker a freshly started subsim")
        return c

    before = c.ok("status", "status")
    c.error("not msgpack", b"\xc1", {"decode"}, "?")
    after = c.ok("status", "status")
    if before is not None and after is not None and after["requests"] - before["requests"] != 1:
        c.fail("status", f"requests went from {before['requests']} to {after['requests']} over an undecodable "
               "request and a status: it counts the requests that decoded, this one included (expected +1)")

    for cmd in ("run_interval", "commit", "rollback", "get_state", "set_state"):
        args = {"run_interval": {"t": encode_array(np.array([0.0, 1.0])), "inputs": {}},
                "set_state": {"time": 0.0, "state": encode_array(np.zeros(1))}}.get(cmd, {})
        c.error(f"{cmd} before configure", _request(cmd, args), {"not_configured"}, cmd)

    d = c.ok("configure", "configure", {"params": params or {}, "t0": 0.0})
    if d is None:
        return c
    c.description = d
    if not d["configured"] or d["time"] != 0.0:
        c.fail("configure", f"the description after configure says configured={d['configured']}, time={d['time']}")
    ins = {p: v["size"] for p, v in d["inputs"].items()}
    outs = {p: v["size"] for p, v in d["outputs"].items()}
    t = np.linspace(0.0, interval, samples)
    t[0], t[-1] = 0.0, interval
    zeros = {p: np.zeros((samples, w)) for p, w in ins.items()}
    s0 = c.committed()
    if s0 is None:
        return c

    _malformed(c, t, ins, zeros, params, d, len(s0[1]) // 8)
    if c.committed() != s0:
        c.fail("bad requests", "the committed state changed after refused requests")

    a = c.ok("run_interval", "run_interval", {"t": t, "inputs": zeros})
    if a is None:
        return c
    if a["t"].tobytes() != t.tobytes():
        c.fail("run_interval", "result t is not the request's t, bit for bit")
    if set(a["outputs"]) != set(outs):
        c.fail("run_interval", f"outputs {sorted(a['outputs'])}, described {sorted(outs)}")
    for p, v in a["outputs"].items():
        if p in outs and v.shape != (samples, outs[p]):
            c.fail("run_interval", f"output {p} has shape {list(v.shape)}, expected [{samples}, {outs[p]}]")
    if a["end_time"] != t[-1]:
        c.fail("run_interval", f"end_time {a['end_time']!r}, expected t[n-1] = {t[-1]!r}")
    b = c.ok("run_interval again", "run_interval", {"t": t, "inputs": zeros})
    if b is not None and any(a["outputs"][p].tobytes() != b["outputs"][p].tobytes() for p in a["outputs"]):
        c.fail("determinism", "the same run_interval twice gave different outputs")
    if c.committed() != s0:
        c.fail("run_interval", "changed the committed state (it must only make a trial)")
    st = c.ok("status", "status")
    if st is not None and not st["has_trial"]:
        c.fail("status", "has_trial is false after a successful run_interval")

    r = c.ok("commit", "commit")
    if r is not None and r["time"] != t[-1]:
        c.fail("commit", f"returned time {r['time']!r}, expected {t[-1]!r}")
    s1 = c.committed()
    if s1 is not None and s1[0] != t[-1]:
        c.fail("commit", f"get_state time {s1[0]!r} after commit, expected {t[-1]!r}")
    c.error("commit twice", _request("commit"), {"no_trial"}, "commit")

    t2, t3 = t + interval, t + 2 * interval
    t2[0], t3[0] = t[-1], t2[-1]
    nxt = c.ok("run_interval from the new committed time", "run_interval", {"t": t2, "inputs": zeros})
    for p in outs if nxt is not None else ():  # the same state and the same (zero) inputs at that time
        scale = float(np.max(np.abs(a["outputs"][p]))) if p in a["outputs"] and a["outputs"][p].size else 0.0
        if p in a["outputs"] and p in nxt["outputs"] and not np.allclose(  # to rounding of the output's own scale
                nxt["outputs"][p][0], a["outputs"][p][-1], rtol=1e-9, atol=1e-12 * scale, equal_nan=False):
            c.fail("run_interval", f"output {p}: row 0 {nxt['outputs'][p][0].tolist()} is not the output at the "
                   f"committed time (the committed run's last row {a['outputs'][p][-1].tolist()}): row 0 is at t[0]")
    c.error("commit: true with a grid not starting at the trial's end",
            _request("run_interval", {"t": encode_array(t2), "inputs": {p: encode_array(v) for p, v in zeros.items()},
                                      "commit": True}), {"time_mismatch"}, "run_interval")
    r = c.ok("run_interval with commit: true", "run_interval", {"t": t3, "inputs": zeros, "commit": True})
    s2 = c.committed()
    if r is not None and s2 is not None and s2[0] != t2[-1]:
        c.fail("run_interval with commit: true", f"committed time {s2[0]!r}, expected {t2[-1]!r}")
    r = c.ok("rollback", "rollback")
    if r is not None and s2 is not None and r["time"] != s2[0]:
        c.fail("rollback", f"returned {r['time']!r}, expected the committed time {s2[0]!r}")
    c.error("commit after rollback", _request("commit"), {"no_trial"}, "commit")
    r = c.ok("rollback to an earlier time", "rollback", {"to_time": float(t[-1])})
    if r is not None and (r["time"] != t[-1] or c.committed() != s1):
        c.fail("rollback to an earlier time", "did not restore the committed state of that time bit for bit")

    snap = c.ok("get_state", "get_state")
    if snap is not None:
        before = c.ok("run_interval", "run_interval", {"t": t2, "inputs": zeros})
        c.ok("set_state", "set_state", {"time": snap["time"], "state": snap["state"]})
        c.error("commit of a trial made before set_state", _request("commit"), {"stale_trial"}, "commit")
        if c.committed() != (snap["time"], snap["state"].tobytes()):
            c.fail("set_state", "get_state after set_state(get_state()) is not the same bits")
        if _history_cleared(c, "set_state", float(t[0])):  # it rolled back: put the state back for the rest
            c.ok("set_state", "set_state", {"time": snap["time"], "state": snap["state"]})
        after = c.ok("run_interval after set_state", "run_interval", {"t": t2, "inputs": zeros})
        if before and after and any(before["outputs"][p].tobytes() != after["outputs"][p].tobytes() for p in outs):
            c.fail("set_state", "a run from the restored state differs from the same run before")

    if c.ok("commit", "commit") is not None and c.ok("run_interval", "run_interval", {"t": t3, "inputs": zeros}):
        c.ok("configure again", "configure", {"params": params or {}, "t0": 0.0})  # history [t[-1]], a trial
        c.error("commit of a trial made before configure", _request("commit"), {"stale_trial"}, "commit")
        _history_cleared(c, "configure", float(t[-1]))
    return c


def _history_cleared(c: Checker, after: str, earlier: float) -> bool:
    """After ``set_state`` or ``configure`` the history is empty: ``status`` says 0 and a rollback to a time
    committed before it is ``not_in_history``. True if that rollback was accepted (the state moved)."""
    st = c.ok(f"status after {after}", "status")
    if st is not None and st["history"] != 0:
        c.fail(after, f"status.history is {st['history']} after {after}, expected 0 (it clears the history)")
    check = f"rollback after {after} to a time committed before it"
    r = c.reply(check, "rollback", _request("rollback", {"to_time": earlier}))
    if isinstance(r, ErrorInfo):
        if r.code != "not_in_history":
            c.fail(check, f"error code {r.code!r}, expected not_in_history ({r.message})")
        return False
    if r is not None:
        c.fail(check, "accepted; expected an error ['not_in_history']")
    return r is not None


def _malformed(c: Checker, t: np.ndarray, ins: dict[str, int], zeros: dict, params: dict | None, d: dict,
               k: int) -> None:
    """Requests every subsim must refuse, with the code of docs/protocol.md section 7."""
    arr = {p: encode_array(v) for p, v in zeros.items()}
    run = lambda **kw: _request("run_interval", {"t": encode_array(t), "inputs": arr, **kw})  # noqa: E731
    c.error("empty payload", b"", {"decode"}, "?")
    c.error("not msgpack", b"\xc1", {"decode"}, "?")
    c.error("not a map", _pack([1, 2]), {"decode"}, "?")
    c.error("non-string map key", _pack({1: 1}), {"decode"}, "?")
    c.error("trailing bytes", _request("status") + b"\x00", {"decode"}, "?")
    c.error("duplicate key", b"\x83\xa1v\x01\xa3cmd\xa6status\xa3cmd\xa8shutdown", {"decode"}, "?")
    c.error("version 2", _pack({"v": 2, "cmd": "status"}), {"version"}, "status")
    c.error("version missing", _pack({"cmd": "status"}), {"version"}, "status")
    c.error("version true", _pack({"v": True, "cmd": "status"}), {"version"}, "status")
    c.error("unknown command", _request("fly"), {"unknown_command"}, "fly")
    c.error("cmd not a string", _pack({"v": 1, "cmd": 5}), {"bad_request"}, "?")
    c.error("extra envelope key", _request("status", extra=1), {"bad_request"}, "status")
    c.error("unknown args field", _request("commit", {"force": True}), {"bad_request"}, "commit")
    c.error("t as a list of floats", _request("run_interval", {"t": t.tolist(), "inputs": arr}), {"bad_request"},
            "run_interval")
    c.error("array byte count", _request("run_interval", {"t": {"shape": [t.size], "data": b"\x00" * 8},
                                                           "inputs": arr}), {"bad_request"}, "run_interval")
    c.error("array with a dtype key", _request("run_interval", {"t": {**encode_array(t), "dtype": "<f8"},
                                                                 "inputs": arr}), {"bad_request"}, "run_interval")
    c.error("t not increasing", _request("run_interval", {"t": encode_array(t[::-1].copy()), "inputs": arr}),
            {"bad_value"}, "run_interval")
    c.error("one sample", _request("run_interval", {"t": encode_array(t[:1].copy()), "inputs": arr}),
            {"bad_value"}, "run_interval")
    c.error("t[0] not the committed time", _request("run_interval", {"t": encode_array(t + t[1]), "inputs": arr}),
            {"time_mismatch"}, "run_interval")
    minus = t.copy()
    minus[0] = -0.0
    c.error("t[0] = -0.0 for a committed 0.0", _request("run_interval", {"t": encode_array(minus), "inputs": arr}),
            {"time_mismatch"}, "run_interval")
    c.error("unknown scheme", run(interp="spline"), {"bad_value"}, "run_interval")
    c.error("unknown input", _request("run_interval", {"t": encode_array(t), "inputs": {
        **arr, "__nope__": encode_array(np.zeros((t.size, 1)))}}), {"bad_value"}, "run_interval")
    for p, w in ins.items():
        c.error(f"input {p} missing", _request("run_interval", {"t": encode_array(t), "inputs": {
            k: v for k, v in arr.items() if k != p}}), {"bad_value"}, "run_interval")
        c.error(f"input {p} of the wrong shape", _request("run_interval", {"t": encode_array(t), "inputs": {
            **arr, p: encode_array(np.zeros((t.size, w + 1)))}}), {"bad_value"}, "run_interval")
        nan = np.zeros((t.size, w))
        nan[1, 0] = np.nan
        c.error(f"input {p} with NaN", _request("run_interval", {"t": encode_array(t), "inputs": {
            **arr, p: encode_array(nan)}}), {"bad_value"}, "run_interval")
    c.error("rollback to a time never committed", _request("rollback", {"to_time": 12345.5}), {"not_in_history"},
            "rollback")
    c.error("set_state of the wrong size", _request("set_state", {"time": 0.0, "state": encode_array(
        np.zeros(k + 1))}), {"bad_value"}, "set_state")
    c.error("set_state with NaN time", _request("set_state", {"time": float("nan"), "state": encode_array(
        np.zeros(1))}), {"bad_value"}, "set_state")
    if d.get("params"):  # a model that declares its parameters refuses others
        c.error("configure with an undeclared parameter", _request("configure", {"params": {
            **(params or {}), "__no_such_parameter__": 1.0}}), {"bad_value"}, "configure")


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m cosim.conformance", description=__doc__.split("\n\n")[0])
    p.add_argument("endpoint", help="where to listen, e.g. tcp/127.0.0.1:7447 (port 0: a free one)")
    p.add_argument("run", help="run id the subsim uses (--run)")
    p.add_argument("name", help="the subsim's name (--name)")
    p.add_argument("--params", type=json.loads, default={}, help="configure parameters, JSON (default: {})")
    p.add_argument("--interval", type=float, default=0.1, help="interval length for the runs (default 0.1)")
    p.add_argument("--samples", type=int, default=5, help="samples per interval (default 5)")
    p.add_argument("--wait", type=float, default=60.0, help="seconds to wait for the subsim (default 60)")
    p.add_argument("--ending", choices=("shutdown", "coordinator"), default="shutdown",
                   help="how the checks end it: a shutdown request (default), or the coordinator's liveliness "
                        "token withdrawn (section 3); start it again to check the other")
    args = p.parse_args(argv)
    try:
        check_name(args.run, "run")
        check_name(args.name, "name")
    except ValueError as exc:
        p.error(str(exc))
    if not (math.isfinite(args.interval) and args.interval > 0):
        p.error(f"--interval must be a finite number of seconds > 0, got {args.interval}")
    if args.samples < 2:
        p.error(f"--samples must be at least 2 (both ends of an interval), got {args.samples}")
    if not (math.isfinite(args.wait) and args.wait > 0):
        p.error(f"--wait must be a finite number of seconds > 0, got {args.wait}")
    try:
        bus = Bus.open(args.endpoint, run=args.run, names=[args.name])
    except (ValueError, RuntimeError) as exc:  # a malformed endpoint, a port in use
        print(f"cosim.conformance: {exc}", file=sys.stderr)
        return 2
    with bus:
        print(f"cosim.conformance: listening on {bus.endpoint}, run {bus.run}; start the subsim with "
              f"--connect {bus.endpoint} --run {bus.run} --name {args.name}", file=sys.stderr, flush=True)
        env = " ".join(f"{k}={v}" for k, v in bus.subsim_env(args.name).items())
        print(f"cosim.conformance: and in its environment (its key and the router login): {env}", file=sys.stderr,
              flush=True)
        try:
            bus.attach(args.name, wait=args.wait)
        except SubsimError as exc:
            print(f"cosim.conformance: {exc}", file=sys.stderr)
            return 2
        bus.attached.clear()  # the checker sends shutdown itself, as a check

        key = bus.key(args.name)

        def send(payload: bytes) -> bytes | None:
            """Sealed with the subsim's key (docs/protocol.md 4.1); a reply without its tag counts as none."""
            seq = next_seq()
            replies = list(bus.session.get(rpc_key(bus.run, args.name), payload=seal_request(key, seq, payload),
                                           timeout=30.0))
            if not replies or replies[0].ok is None:
                return None
            body = open_reply(key, seq, replies[0].ok.payload.to_bytes())
            return None if body is None else bytes(body)

        checker = run_checks(send, args.name, args.params, args.interval, args.samples)
        _check_seals(checker, bus, args.name)
        if args.ending == "shutdown":
            _check_shutdown(checker, bus, args.name)
        else:
            _check_coordinator_left(checker, bus, args.name)
    for line in checker.violations:
        print(line)
    print(f"{args.name}: {checker.checks} requests, {len(checker.violations)} violation(s)", file=sys.stderr)
    return 1 if checker.violations else 0


def _check_seals(c: Checker, bus: Bus, name: str, wait: float = 1.0) -> None:
    """Section 4.1 and 3: frames not sealed with the subsim's key, replays, seqs below the window and queries on
    other key expressions get no reply at all; a body over the default request cap gets ``too_large``."""
    key, rpc = bus.key(name), rpc_key(bus.run, name)

    def replies(payload: bytes, on: str = rpc, timeout: float = wait) -> list[bytes]:
        c.checks += 1
        return bus.query(on, payload, timeout)

    status = encode_request("status")
    silent = {
        "an unsealed frame": status,
        "a frame sealed with another key": seal_request(secrets.token_bytes(32), next_seq(), status + b" " * 40),
        f"a seq {2 * REPLAY_WINDOW} below the highest accepted": seal_request(key, next_seq() - 2 * REPLAY_WINDOW,
                                                                            status),
    }
    for what, frame in silent.items():
        if replies(frame):
            c.fail("seal", f"{what} was answered; it must get no reply (section 4.1)")
    seq = next_seq()
    frame = seal_request(key, seq, status)
    if not any(open_reply(key, seq, r) is not None for r in replies(frame, timeout=30.0)):
        c.fail("seal", "a correctly sealed status got no reply with a valid tag")
    elif replies(frame):
        c.fail("seal", "a replayed frame (the same seq again) was answered; it must get no reply (section 4.1)")
    other = f"cosim/{bus.run}/*/rpc"  # (the router's access control keeps `**` queries from subsims anyway)
    if replies(seal_request(key, next_seq(), status), other):
        c.fail("seal", f"a query on {other} was answered; only queries on exactly {rpc} are (section 1)")
    cap = default_request_cap({p: Port(v["size"]) for p, v in (c.description or {}).get("inputs", {}).items()})
    if cap > CAP_CHECKED:  # a body that large would cost the checker (and the machine) gigabytes
        print(f"cosim.conformance: request cap not checked: the default cap for these ports is {cap} bytes (over "
              f"{CAP_CHECKED}); configure it with narrower inputs (--params) to check it", file=sys.stderr)
        return
    seq = next_seq()
    answer = [open_reply(key, seq, r) for r in replies(seal_request(key, seq, b"\x00" * (cap + 1)), timeout=30.0)]
    opened = [bytes(a) for a in answer if a is not None]
    if not opened:
        c.fail("request cap", f"a {cap + 1}-byte body (the default cap {cap} + 1, section 3) got no reply; "
               "expected too_large")
    else:
        r = decode_reply("status", opened[0])
        if not isinstance(r, ErrorInfo) or r.code != "too_large":
            c.fail("request cap", f"a {cap + 1}-byte body (over the default cap {cap}, section 3) got "
                   f"{getattr(r, 'code', 'a result')!r}; expected too_large, before any decoding")


def _check_coordinator_left(c: Checker, bus: Bus, name: str) -> None:
    """When the coordinator's liveliness token goes, the subsim stops serving: its own token goes too."""
    with _token_watch(bus, name) as gone:
        bus.withdraw_token()
        if not gone(10.0):
            c.fail("coordinator left", "the subsim's liveliness token is still there 10 s after the coordinator's "
                   "went; it must stop serving and exit (section 3)")


def _check_shutdown(c: Checker, bus: Bus, name: str) -> None:
    """``shutdown`` replies ``{}`` and the subsim's liveliness token goes away."""
    with _token_watch(bus, name) as gone:
        r = c.ok("shutdown", "shutdown")
        if r is not None and r != {}:
            c.fail("shutdown", f"result {r!r}, expected {{}}")
        if not gone(10.0):
            c.fail("shutdown", "the subsim's liveliness token is still there 10 s after shutdown")


@contextmanager
def _token_watch(bus: Bus, name: str) -> Iterator[Callable[[float], bool]]:
    """Watches subsim ``name``'s liveliness token; yields ``gone(seconds)``: whether it went within that long."""
    went = threading.Event()
    sub = bus.session.liveliness().declare_subscriber(
        alive_key(bus.run, name), lambda s: went.set() if str(s.kind).endswith("DELETE") else None)
    try:
        yield went.wait
    finally:
        sub.undeclare()


if __name__ == "__main__":
    raise SystemExit(main())
