"""The decisions docs/protocol.md states and the code must keep: duplicate keys, trailing bytes,
the nesting depth of params, the bit-exact start time, the order of a request's checks."""

from __future__ import annotations

import hashlib
import hmac

import msgpack
import numpy as np
import pytest

from cosim.contract import ProtocolError, SubsimError
from cosim.handles import InProcessHandle
from cosim.protocol.messages import (
    REQUESTS,
    Request,
    decode_reply,
    decode_request,
    encode_request,
    encode_result,
    open_reply,
    open_request,
    seal_reply,
    seal_request,
)
from cosim.protocol.service import answer
from cosim.protocol.wire import MAX_NESTING
from cosim.runtime import Runtime
from subsims.integrator.subsim import Integrator


def code_of(payload: bytes) -> str:
    with pytest.raises(ProtocolError) as err:
        decode_request(payload)
    return err.value.code


def pairs(*items: tuple[str, object]) -> bytes:
    """A msgpack map written pair by pair (a msgpack writer would keep its keys unique)."""
    assert len(items) < 16
    return bytes([0x80 | len(items)]) + b"".join(
        msgpack.packb(k) + (v if isinstance(v, bytes) else msgpack.packb(v)) for k, v in items
    )


def test_a_request_repeating_a_key_anywhere_is_undecodable() -> None:
    assert decode_request(pairs(("v", 1), ("cmd", "status"))).cmd == "status"
    assert code_of(pairs(("v", 1), ("cmd", "status"), ("cmd", "shutdown"))) == "decode"  # in the envelope
    params = pairs(("size", 1), ("y0", 2))
    ok = pairs(("v", 1), ("cmd", "configure"), ("args", pairs(("params", params))))
    assert decode_request(ok).args["params"] == {"size": 1, "y0": 2}
    params = pairs(("size", 1), ("size", 2))  # deep inside
    assert code_of(pairs(("v", 1), ("cmd", "configure"), ("args", pairs(("params", params))))) == "decode"


def test_trailing_bytes_after_the_message_are_undecodable() -> None:
    good = encode_request("status")
    assert decode_request(good).cmd == "status"
    for tail in (b"\x00", b"\xc0", encode_request("shutdown")):
        assert code_of(good + tail) == "decode"


def test_a_reply_repeating_a_key_keeps_the_last_value() -> None:
    reply = encode_result({"time": 1.0})
    assert reply.endswith(b"\x81\xa4time\xcb" + np.float64(1.0).byteswap().tobytes())
    doubled = reply[:-len(b"\x81\xa4time") - 9] + b"\x82\xa4time\xcb" + np.float64(1.0).byteswap().tobytes() + \
        b"\xa4time\xcb" + np.float64(2.0).byteswap().tobytes()
    assert decode_reply("commit", doubled) == {"time": 2.0}


def nested(levels: int) -> object:
    """A parameter value whose deepest value sits ``levels`` levels below the params map (the value itself is 1)."""
    value: object = 0.0
    for _ in range(levels - 1):
        value = [value]
    return value


def configure_payload(value: object) -> bytes:
    return msgpack.packb({"v": 1, "cmd": "configure", "args": {"params": {"p": value}}}, use_bin_type=True)


def test_params_nest_at_most_max_nesting_levels_counting_the_value_of_a_parameter_as_level_1() -> None:
    assert MAX_NESTING == 32
    assert decode_request(configure_payload(nested(1))).args["params"] == {"p": 0.0}
    decode_request(configure_payload(nested(MAX_NESTING)))
    assert code_of(configure_payload(nested(MAX_NESTING + 1))) == "bad_request"
    # maps count like lists
    deep: object = 0.0
    for _ in range(MAX_NESTING):
        deep = {"k": deep}
    assert code_of(configure_payload(deep)) == "bad_request"


def test_the_start_time_must_equal_the_committed_time_bit_for_bit() -> None:
    h = InProcessHandle(Integrator())
    h.configure({})
    with pytest.raises(SubsimError) as err:
        h.run_interval(np.array([-0.0, 0.5]), {"u": np.zeros((2, 1))})
    assert err.value.code == "time_mismatch" and "-0.0" in err.value.message
    assert h.run_interval(np.array([0.0, 0.5]), {"u": np.zeros((2, 1))}).end_time == 0.5
    h.configure({}, t0=-0.0)
    assert h.run_interval(np.array([-0.0, 0.5]), {"u": np.zeros((2, 1))}).end_time == 0.5


X = {"x": np.zeros(1)}  # an input the integrator does not have


@pytest.mark.parametrize(
    ("args", "code", "words"),
    [
        # every check fails here; the first in the documented order wins
        ({"t": np.array([1.0, 0.5]), "inputs": X, "interp": "spline", "commit": True}, "no_trial", "commit"),
        ({"t": np.array([1.0, 0.5]), "inputs": X, "interp": "spline"}, "bad_value", "increasing"),
        ({"t": np.array([1.0]), "inputs": X, "interp": "spline"}, "bad_value", "at least 2"),
        ({"t": np.array([1.0, 1.5]), "inputs": X, "interp": "spline"}, "time_mismatch", "committed time"),
        ({"t": np.array([0.0, 0.5]), "inputs": X, "interp": "spline"}, "bad_value", "interp"),
        ({"t": np.array([0.0, 0.5]), "inputs": X}, "bad_value", "unknown ['x']"),
    ],
)
def test_run_interval_checks_in_the_documented_order(args: dict, code: str, words: str) -> None:
    rt = Runtime(Integrator)
    payload = encode_request("run_interval", args)
    assert decode_reply("run_interval", answer(rt, payload)).code == "not_configured"
    rt.configure({})
    info = decode_reply("run_interval", answer(rt, payload))
    assert info.code == code and words in info.message, info.message


def test_sealed_frames_are_the_bytes_of_section_4_1() -> None:
    key, seq, body = bytes(range(32)), 2**63 + 5, encode_request("status")
    seq8 = seq.to_bytes(8, "big")
    frame = seal_request(key, seq, body)
    assert frame == body + seq8 + hmac.new(key, b"cosim-request\0" + seq8 + body, hashlib.sha256).digest()
    assert open_request(key, frame) == (seq, body)
    reply = encode_result({"time": 1.0})
    sealed = seal_reply(key, seq, reply)
    assert sealed == reply + hmac.new(key, b"cosim-reply\0" + seq8 + reply, hashlib.sha256).digest()
    assert open_reply(key, seq, sealed) == reply
    for bad in (frame[:-1] + bytes([frame[-1] ^ 1]), frame[:39], b""):
        assert open_request(key, bad) is None
    assert open_reply(key, seq + 1, sealed) is None and open_reply(key, seq, sealed[:31]) is None
    assert open_request(bytes(32), frame) is None and open_reply(bytes(32), seq, sealed) is None


def test_a_command_without_arguments_decodes_alike_in_any_spelling() -> None:
    for cmd in REQUESTS:
        if REQUESTS[cmd]:
            continue
        body = encode_request(cmd)
        assert body == msgpack.packb({"v": 1, "cmd": cmd, "args": {}})
        reordered = pairs(("args", {}), ("cmd", cmd), ("v", 1))
        for payload in (body, memoryview(body), reordered, pairs(("v", 1), ("cmd", cmd))):
            assert decode_request(payload) == Request(cmd, {})
