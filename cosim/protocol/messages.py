"""Request and reply messages: schemas, encoding and total (never-raising) decoding.

Request:  ``{"v": 1, "cmd": <command>, "args": {...}}``
Reply:    ``{"v": 1, "ok": true, "result": {...}}`` or
          ``{"v": 1, "ok": false, "error": {"code", "message", "subsim", "command"}}``

Requests are strict (unknown fields are errors); replies ignore unknown fields so a subsim may
report more than this version knows. See docs/protocol.md.

Over a bus every request and reply is *sealed* with the subsim's key (section 4.1 of docs/protocol.md):

    request frame:  body || seq (8 bytes, big-endian) || HMAC-SHA256(key, "cosim-request" 0 seq body)
    reply frame:    body || HMAC-SHA256(key, "cosim-reply" 0 seq body)

A subsim accepts each ``seq`` once, and none more than a small window below the highest it accepted
(``cosim.protocol.service.REPLAY_WINDOW``), so a recorded request cannot be replayed; the reply tag
binds each reply to its request.
"""

from __future__ import annotations

import functools
import hashlib
import hmac
import itertools
import time
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from cosim.contract import PROTOCOL_VERSION, ProtocolError
from cosim.protocol.wire import (
    Fields,
    check_fields,
    encode_array,
    pack,
    t_any_map,
    t_array,
    t_array_map,
    t_bool,
    t_float,
    t_int,
    t_opt,
    t_param_decls,
    t_params,
    t_port_map,
    t_str,
    t_str_map,
    unpack_map,
)

DESCRIPTION_FIELDS: Fields = {
    "name": (t_str, True),
    "model": (t_str, True),
    "inputs": (t_port_map, True),
    "outputs": (t_port_map, True),
    "algebraic": (t_bool, True),
    "configured": (t_bool, True),
    "time": (t_opt(t_float), False),
    "history_limit": (t_int, True),
    "protocol": (t_int, True),
    "params": (t_param_decls, False),
    "code": (t_str_map, False),
    "not_ports": (t_str_map, False),
}

REQUESTS: dict[str, Fields] = {
    "describe": {},
    "configure": {"params": (t_params, True), "t0": (t_float, False)},
    "run_interval": {
        "t": (t_array, True), "inputs": (t_array_map, True), "interp": (t_str, False), "commit": (t_bool, False),
    },
    "commit": {},
    "rollback": {"to_time": (t_float, False)},
    "get_state": {},
    "set_state": {"time": (t_float, True), "state": (t_array, True)},
    "status": {},
    "shutdown": {},
}

RESULTS: dict[str, Fields] = {
    "describe": DESCRIPTION_FIELDS,
    "configure": DESCRIPTION_FIELDS,
    "run_interval": {"t": (t_array, True), "outputs": (t_array_map, True), "end_time": (t_float, True)},
    "commit": {"time": (t_float, True)},
    "rollback": {"time": (t_float, True)},
    "get_state": {"time": (t_float, True), "state": (t_array, True), "model": (t_str, True)},
    "set_state": {"time": (t_float, True)},
    "status": {
        "name": (t_str, True),
        "configured": (t_bool, True),
        "time": (t_opt(t_float), False),
        "has_trial": (t_bool, True),
        "history": (t_int, True),
        "requests": (t_int, True),
        "pid": (t_int, False),
    },
    "shutdown": {},
}

ERROR_FIELDS: Fields = {
    "code": (t_str, True),
    "message": (t_str, True),
    "subsim": (t_str, True),
    "command": (t_str, True),
    "traceback": (t_str, False),
}


class Request(NamedTuple):  # one per request served: a tuple costs a fraction of a frozen dataclass
    cmd: str
    args: dict[str, Any]


@dataclass(frozen=True)
class ErrorInfo:
    code: str
    message: str
    subsim: str
    command: str
    traceback: str | None = None


_SCALARS = frozenset({str, int, float, bool, type(None)})  # exactly these types go to the wire as they are


def _to_wire(value: Any) -> Any:
    """Arrays become array maps, recursively through maps and lists."""
    if isinstance(value, np.ndarray):
        return encode_array(value)
    if isinstance(value, dict):  # a result map is mostly scalars: no call for those
        return {k: v if type(v) in _SCALARS else _to_wire(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_to_wire(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _plain(value: Any) -> Any:
    """Parameters are plain values (see ``t_params``): arrays become nested lists, numpy scalars numbers."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


class VersionMismatch(ProtocolError):
    """The other end speaks another protocol ``version``: another cosim version (or an implementation of another)."""

    def __init__(self, version: int) -> None:
        super().__init__("version", f"protocol version {version} not supported (this end speaks {PROTOCOL_VERSION})")
        self.version = version


def _check_version(msg: dict) -> None:
    v = msg.get("v")
    if isinstance(v, bool) or not isinstance(v, int):
        raise ProtocolError("version", f"field 'v' must be the protocol version integer, got {v!r}"[:120])
    if v != PROTOCOL_VERSION:
        raise VersionMismatch(v)


_ENVELOPE = frozenset({"v", "cmd", "args"})
# The body of each command without arguments, and its command: a request that is byte for byte one of these
# (what encode_request sends) decodes to the same Request as through msgpack and the schema, for less.
_BARE_BODY = {cmd: pack({"v": PROTOCOL_VERSION, "cmd": cmd, "args": {}}) for cmd, f in REQUESTS.items() if not f}
_BARE_CMD = {body: cmd for cmd, body in _BARE_BODY.items()}
_BARE_MAX = max(map(len, _BARE_CMD))


def encode_request(cmd: str, args: dict[str, Any] | None = None) -> bytes:
    if not args and cmd in _BARE_BODY:
        return _BARE_BODY[cmd]
    fields = REQUESTS.get(cmd, {})
    wire = {k: _plain(v) if fields.get(k, (None,))[0] is t_params else _to_wire(v) for k, v in (args or {}).items()}
    return pack({"v": PROTOCOL_VERSION, "cmd": cmd, "args": wire})


def decode_request(payload: bytes) -> Request:
    """Decode and validate a request. Raises only ``ProtocolError``."""
    if type(payload) in (bytes, memoryview) and len(payload) <= _BARE_MAX:
        cmd = _BARE_CMD.get(bytes(payload))
        if cmd is not None:
            return Request(cmd, {})
    try:
        msg = unpack_map(payload, unique_keys=True)
        _check_version(msg)
        cmd = msg.get("cmd")
        if cmd is None:
            raise ProtocolError("bad_request", "field 'cmd' is missing: every request names its command")
        if not isinstance(cmd, str):
            raise ProtocolError("bad_request", f"field 'cmd' must be a string, got {type(cmd).__name__}")
        if cmd not in REQUESTS:
            raise ProtocolError("unknown_command", f"unknown command {cmd[:40]!r}; known: {', '.join(REQUESTS)}")
        if not msg.keys() <= _ENVELOPE:
            extra = set(msg) - _ENVELOPE
            raise ProtocolError("bad_request", f"unknown envelope field(s) {sorted(map(str, extra))}")
        args = check_fields(msg.get("args", {}), REQUESTS[cmd], "args")
        return Request(cmd, args)
    except ProtocolError:
        raise
    except Exception as exc:  # a checker bug must still not escape as anything but a protocol error
        raise ProtocolError("internal", f"undecodable request ({type(exc).__name__})") from None  # a bug, not the peer


_HEAD = pack({"v": PROTOCOL_VERSION, "cmd": ""})[:-1]  # a map's count, "v", the version, "cmd" (then the name)


def peek_command(body: bytes | memoryview) -> str | None:
    """The command of a request laid out as :func:`encode_request` lays it out, read without decoding;
    ``None`` for any other layout. A hint (e.g. which thread answers it), never a decision: the request is
    still decoded and checked in full."""
    head = len(_HEAD)
    if body[1:head] != _HEAD[1:] or len(body) <= head:
        return None
    size = body[head] - 0xA0  # a fixstr (at most 31 bytes): every command name
    if not 0 < size < 32:
        return None
    return bytes(body[head + 1 : head + 1 + size]).decode("ascii", "replace")


def request_command(payload: bytes) -> str:
    """Best-effort command name of a payload, for error replies to requests that failed to decode."""
    try:
        cmd = unpack_map(payload, unique_keys=True).get("cmd")
        return cmd if isinstance(cmd, str) else "?"
    except Exception:
        return "?"


def encode_result(result: dict[str, Any]) -> bytes:
    return pack({"v": PROTOCOL_VERSION, "ok": True, "result": _to_wire(result)})


def encode_error(code: str, message: str, subsim: str, command: str, traceback: str | None = None) -> bytes:
    err = {"code": code, "message": message, "subsim": subsim, "command": command}
    if traceback is not None:
        err["traceback"] = traceback
    return pack({"v": PROTOCOL_VERSION, "ok": False, "error": err})


def decode_reply(cmd: str, payload: bytes) -> dict[str, Any] | ErrorInfo:
    """Decode a reply to ``cmd``: the checked result map, or the error it carries."""
    try:
        msg = unpack_map(payload)
        _check_version(msg)
        ok = t_bool(msg.get("ok"), "ok")
        if not ok:
            e = check_fields(msg.get("error"), ERROR_FIELDS, "error", strict=False)
            return ErrorInfo(e["code"], e["message"], e["subsim"], e["command"], e.get("traceback"))
        return check_fields(t_any_map(msg.get("result"), "result"), RESULTS[cmd], "result", strict=False)
    except ProtocolError:
        raise
    except Exception as exc:
        raise ProtocolError("internal", f"undecodable reply ({type(exc).__name__})") from None  # a bug, not the peer


# --- sealed frames ------------------------------------------------------------------------------

SEQ_BYTES = 8
TAG_BYTES = 32
SEAL_BYTES = SEQ_BYTES + TAG_BYTES
_REQUEST = b"cosim-request\0"
_REPLY = b"cosim-reply\0"

# One counter per process, started from the clock: strictly increasing across every handle of this
# coordinator, and above the numbers of an earlier coordinator process of the same run.
_sequence = itertools.count(time.time_ns())


def next_seq() -> int:
    return next(_sequence)


class Sealer:
    """Seals and opens the frames of one key (docs/protocol.md 4.1).

    The HMAC state after the key and each domain prefix is computed once; every frame copies it, which
    costs less than half of keying a new HMAC (tags are identical). Safe to share between threads."""

    __slots__ = ("_request", "_reply")

    def __init__(self, key: bytes) -> None:
        self._request = hmac.new(key, _REQUEST, hashlib.sha256)
        self._reply = hmac.new(key, _REPLY, hashlib.sha256)

    def seal_request(self, seq: int, body: bytes) -> bytes:
        seq8 = seq.to_bytes(SEQ_BYTES, "big")
        mac = self._request.copy()
        mac.update(seq8)
        mac.update(body)
        return body + seq8 + mac.digest()

    def open_request(self, frame: bytes) -> tuple[int, memoryview] | None:
        """``(seq, body)`` of a request sealed with this key; ``None`` when the frame is not (short, wrong tag)."""
        end = len(frame) - SEAL_BYTES
        if end < 0:
            return None
        body = memoryview(frame)[:end]  # no copy of a large body
        seq8 = frame[end:end + SEQ_BYTES]
        mac = self._request.copy()
        mac.update(seq8)
        mac.update(body)
        if not hmac.compare_digest(mac.digest(), frame[end + SEQ_BYTES:]):
            return None
        return int.from_bytes(seq8, "big"), body

    def seal_reply(self, seq: int, body: bytes) -> bytes:
        mac = self._reply.copy()
        mac.update(seq.to_bytes(SEQ_BYTES, "big"))
        mac.update(body)
        return body + mac.digest()

    def open_reply(self, seq: int, frame: bytes) -> memoryview | None:
        """The body of a reply to request ``seq`` sealed with this key; ``None`` when it is not."""
        end = len(frame) - TAG_BYTES
        if end < 0:
            return None
        body = memoryview(frame)[:end]
        mac = self._reply.copy()
        mac.update(seq.to_bytes(SEQ_BYTES, "big"))
        mac.update(body)
        if not hmac.compare_digest(mac.digest(), frame[end:]):
            return None
        return body


@functools.lru_cache(maxsize=64)
def sealer(key: bytes) -> Sealer:
    """The :class:`Sealer` of ``key`` (kept: a process seals with few keys)."""
    return Sealer(key)


def seal_request(key: bytes, seq: int, body: bytes) -> bytes:
    return sealer(key).seal_request(seq, body)


def open_request(key: bytes, frame: bytes) -> tuple[int, memoryview] | None:
    """``(seq, body)`` of a request sealed with ``key``; ``None`` when the frame is not (short, wrong tag)."""
    return sealer(key).open_request(frame)


def seal_reply(key: bytes, seq: int, body: bytes) -> bytes:
    return sealer(key).seal_reply(seq, body)


def open_reply(key: bytes, seq: int, frame: bytes) -> memoryview | None:
    """The body of a reply to request ``seq`` sealed with ``key``; ``None`` when it is not."""
    return sealer(key).open_reply(seq, frame)
