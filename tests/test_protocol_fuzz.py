"""Property-based fuzzing of the wire format (cosim.protocol) and of the server's ``answer``.

Claims under test:

* ``decode_request`` and ``decode_reply`` are total: whatever the bytes, they return or raise
  ``ProtocolError``, never anything else, and a structurally wrong message is rejected with the
  documented error code (docs/protocol.md). Their catch-all turns an unexpected exception (a bug in
  a checker) into code ``internal``, and ``answer``'s into an ``internal`` reply: every test below
  asserts that code never comes out, so a crash inside the decoders fails the test instead of passing
  as "an error reply" (``test_a_crashing_checker_fails_the_fuzz_assertions`` shows it does).
* ``answer(runtime, payload)`` turns garbage into a decodable error reply and leaves the
  runtime's committed state (time, state, history) untouched.
* ``encode_request`` -> ``decode_request`` gives back the arguments; arrays bit for bit
  (-0.0, subnormals, NaN payloads, huge and tiny magnitudes, any input dtype or byte order).

The generators are driven by the schemas in ``cosim.protocol.messages`` (REQUESTS, RESULTS), so a
new command or field is fuzzed without editing this file.

Generated inputs per run (``max_examples``; derandomized and without the example database, so CI
sees the same inputs on every run):

    test_decode_request_random_bytes                 4000
    test_decode_request_random_msgpack               1500   (each also decoded truncated)
    test_decode_request_rejects_malformed_requests   2000
    test_decode_reply_random                         1000   (each also decoded truncated)
    test_decode_reply_rejects_malformed_results       700
    test_decode_reply_ignores_unknown_fields          100
    test_answer_garbage_is_an_error_reply             600
    test_answer_out_of_contract_requests              300
    test_request_round_trip                           600
    test_reply_round_trip                             200
                                             total  11000
"""

from __future__ import annotations

import math
import re
import struct
from pathlib import Path
from typing import Any

import msgpack
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, event, given, settings
from hypothesis import strategies as st

from cosim.contract import ERROR_CODES, ProtocolError
from cosim.protocol.messages import (
    PROTOCOL_VERSION,
    REQUESTS,
    RESULTS,
    ErrorInfo,
    decode_reply,
    decode_request,
    encode_request,
    encode_result,
)
from cosim.protocol.service import answer
from cosim.protocol.wire import (
    MAX_NDIM,
    MAX_NESTING,
    Checker,
    Fields,
    _t_array_checked,
    t_any_map,
    t_array,
    t_array_map,
    t_bool,
    t_float,
    t_int,
    t_param_decls,
    t_params,
    t_port_map,
    t_str,
    t_str_map,
)
from cosim.runtime import Runtime
from subsims.integrator.subsim import Integrator


def fuzz(max_examples: int):
    """Reproducible settings: fixed seed per test, no example database, no per-example deadline."""
    return settings(
        max_examples=max_examples,
        derandomize=True,
        database=None,
        deadline=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much, HealthCheck.data_too_large],
    )


def pack(obj: Any) -> bytes:
    return msgpack.packb(obj, use_bin_type=True)


# --- generic msgpack values -------------------------------------------------------------------

INT64 = st.integers(-(2**63), 2**64 - 1)  # everything msgpack can carry
leaves = st.one_of(
    st.none(),
    st.booleans(),
    INT64,
    st.floats(),  # includes NaN, inf, -0.0, subnormals
    st.text(max_size=12),
    st.binary(max_size=24),
    st.builds(msgpack.ExtType, st.integers(0, 127), st.binary(max_size=8)),
)
junk = st.recursive(
    leaves,
    lambda inner: st.one_of(
        st.lists(inner, max_size=4),
        st.dictionaries(st.text(max_size=8), inner, max_size=4),
    ),
    max_leaves=8,
)
NAMES = st.text(min_size=1, max_size=8)


def not_(*types: type) -> st.SearchStrategy:
    """Junk that is none of ``types`` (bool counts as its own type, not as int)."""

    def ok(v: Any) -> bool:
        if isinstance(v, bool):
            return bool not in types
        return not isinstance(v, types)

    return junk.filter(ok)


# --- arrays -----------------------------------------------------------------------------------

SHAPES = st.lists(st.integers(0, 3), min_size=1, max_size=MAX_NDIM)
SPECIAL = [
    0.0,
    -0.0,
    5e-324,
    -5e-324,
    2.2250738585072009e-308,
    2.225073858507201e-308,
    1.7976931348623157e308,
    -1.7976931348623157e308,
    1e-300,
    1e300,
    math.inf,
    -math.inf,
    math.nan,
]


@st.composite
def arrays(draw: st.DrawFn, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """float64 arrays from raw bytes (any bit pattern) or from special and random floats."""
    if shape is None:
        shape = tuple(draw(SHAPES))
    n = math.prod(shape)
    if draw(st.booleans()):
        a = np.frombuffer(draw(st.binary(min_size=8 * n, max_size=8 * n)), dtype="<f8").reshape(shape)
    else:
        values = draw(st.lists(st.one_of(st.sampled_from(SPECIAL), st.floats()), min_size=n, max_size=n))
        a = np.array(values, dtype=np.float64).reshape(shape)
    # the encoder must cope with any layout and byte order
    layout = draw(st.sampled_from(["c", "fortran", "big-endian", "strided"]))
    if layout == "fortran":
        a = np.asfortranarray(a)
    elif layout == "big-endian":
        a = a.astype(">f8")
    elif layout == "strided" and a.ndim >= 1:
        wide = np.repeat(a, 2, axis=-1)
        a = wide[..., ::2]
    return a


def wire_array(a: np.ndarray) -> dict:
    a = np.ascontiguousarray(a, dtype="<f8")
    return {"shape": list(a.shape), "data": a.tobytes()}


def _sized(shape: list[int], extra: int) -> dict:
    return {"shape": shape, "data": b"\x00" * (8 * math.prod(shape) + extra)}


bad_arrays = st.one_of(
    # byte count does not match the shape
    st.tuples(SHAPES, st.integers(-64, 64).filter(lambda k: k != 0))
    .filter(lambda sk: 8 * math.prod(sk[0]) + sk[1] >= 0)
    .map(lambda sk: _sized(*sk)),
    st.tuples(SHAPES, st.binary(max_size=40))
    .filter(lambda sb: len(sb[1]) != 8 * math.prod(sb[0]))
    .map(lambda sb: {"shape": sb[0], "data": sb[1]}),
    # huge declared shapes with little data
    st.just({"shape": [2**40, 2**40], "data": b"\x00" * 8}),
    st.just({"shape": [2**40, 2**40], "data": b""}),
    st.tuples(st.lists(st.integers(2**31, 2**64 - 1), min_size=1, max_size=MAX_NDIM), st.binary(max_size=16)).map(
        lambda sb: {"shape": sb[0], "data": sb[1]}
    ),
    # zero-size arrays whose other dimensions do not fit in memory addressing
    st.lists(st.integers(2**62, 2**64 - 1), min_size=1, max_size=MAX_NDIM - 1).map(
        lambda s: {"shape": [0, *s], "data": b""}
    ),
    # negative dimensions
    st.lists(st.integers(-(2**63), 4), min_size=1, max_size=MAX_NDIM)
    .filter(lambda s: min(s) < 0)
    .map(lambda s: {"shape": s, "data": b"\x00" * 8 * abs(math.prod(s)) if abs(math.prod(s)) < 64 else b""}),
    # too many or no dimensions
    st.lists(st.integers(0, 2), min_size=MAX_NDIM + 1, max_size=3 * MAX_NDIM).map(lambda s: _sized(s, 0)),
    st.just({"shape": [], "data": b"\x00" * 8}),
    # wrong types inside the array map
    not_(list).map(lambda s: {"shape": s, "data": b""}),
    st.lists(not_(int), min_size=1, max_size=3).map(lambda s: {"shape": s, "data": b""}),
    st.lists(st.booleans(), min_size=1, max_size=3).map(lambda s: {"shape": s, "data": b"\x00" * 8}),
    not_(bytes).map(lambda d: {"shape": [1], "data": d}),
    # missing or extra keys, or not a map at all
    st.sampled_from([{"shape": [1]}, {"data": b"\x00" * 8}, {}]),
    st.tuples(NAMES.filter(lambda k: k not in ("shape", "data")), junk).map(
        lambda kv: {"shape": [1], "data": b"\x00" * 8, kv[0]: kv[1]}
    ),
    not_(dict),
)


def nested(depth: int, leaf: Any = 0) -> Any:
    for i in range(depth):
        leaf = [leaf] if i % 2 else {"k": leaf}
    return leaf


# --- schema-driven value strategies --------------------------------------------------------------


def _is_opt_float(check: Checker) -> bool:
    return check.__qualname__.startswith("t_opt")


finite = st.floats(allow_nan=False, allow_infinity=False)
numbers = st.one_of(finite, INT64, st.sampled_from([-0.0, 5e-324, 1.7976931348623157e308]))
params_values = st.recursive(
    st.one_of(st.none(), st.booleans(), INT64, finite, st.text(max_size=8)),
    lambda inner: st.one_of(st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=6), inner, max_size=3)),
    max_leaves=10,
)
port = st.fixed_dictionaries(
    {"size": st.integers(1, 2**63 - 1)}, optional={"unit": st.text(max_size=4), "doc": st.text(max_size=8)}
)


def valid(check: Checker) -> st.SearchStrategy:
    """Python values (arrays as ndarrays) that ``check`` accepts once encoded."""
    if check is t_str:
        return st.text(max_size=12)
    if check is t_bool:
        return st.booleans()
    if check is t_int:
        return INT64
    if check is t_float:
        return numbers
    if _is_opt_float(check):
        return st.none() | numbers
    if check is t_array:
        return arrays()
    if check is t_array_map:
        return st.dictionaries(NAMES, arrays(), max_size=3)
    if check is t_port_map:
        return st.dictionaries(NAMES, port, max_size=3)
    if check is t_params:
        return st.dictionaries(st.text(max_size=6), params_values, max_size=4)
    if check is t_param_decls:
        decl = st.fixed_dictionaries({}, optional={"default": params_values, "unit": st.text(max_size=4),
                                                   "doc": st.text(max_size=8)})
        return st.dictionaries(NAMES, decl, max_size=3)
    if check is t_any_map:
        return st.dictionaries(st.text(max_size=6), params_values, max_size=4)
    if check is t_str_map:
        return st.dictionaries(NAMES, st.text(max_size=16), max_size=3)
    raise AssertionError(f"no strategy for checker {check!r}: extend tests/test_protocol_fuzz.py")


def invalid(check: Checker) -> st.SearchStrategy:
    """(wire value, acceptable error codes) that ``check`` must reject."""
    bad = {"bad_request"}
    if check is t_str:
        return st.tuples(not_(str), st.just(bad))
    if check is t_bool:
        return st.tuples(not_(bool), st.just(bad))
    if check is t_int:
        return st.tuples(not_(int), st.just(bad))
    if check is t_float or _is_opt_float(check):
        kinds = (int, float) if check is t_float else (int, float, type(None))
        return st.one_of(
            st.tuples(not_(*kinds), st.just(bad)),
            st.tuples(st.sampled_from([math.nan, math.inf, -math.inf]), st.just({"bad_value"})),
        )
    if check is t_array:
        return st.tuples(bad_arrays, st.just(bad))
    if check is t_array_map:
        return st.tuples(
            st.one_of(not_(dict), st.dictionaries(NAMES, bad_arrays, min_size=1, max_size=2)), st.just(bad)
        )
    if check is t_port_map:
        bad_port = st.one_of(
            not_(dict),
            st.just({}),
            st.just({"unit": "m"}),
            st.integers(-(2**63), 0).map(lambda n: {"size": n}),
            not_(int).map(lambda s: {"size": s}),
            not_(str).map(lambda u: {"size": 1, "unit": u}),
        )
        return st.tuples(st.one_of(not_(dict), st.dictionaries(NAMES, bad_port, min_size=1, max_size=2)), st.just(bad))
    if check is t_params:
        return st.tuples(
            st.one_of(
                not_(dict),
                st.integers(MAX_NESTING + 1, 200).map(lambda d: {"p": nested(d)}),
                st.binary(max_size=8).map(lambda b: {"blob": b}),
                st.builds(msgpack.ExtType, st.integers(0, 127), st.binary(max_size=4)).map(lambda e: {"x": [e]}),
            ),
            st.just(bad),
        )
    if check is t_param_decls:
        bad_decl = st.one_of(not_(dict), not_(str).map(lambda u: {"unit": u}), not_(str).map(lambda d: {"doc": d}))
        return st.tuples(st.one_of(not_(dict), st.dictionaries(NAMES, bad_decl, min_size=1, max_size=2)), st.just(bad))
    if check is t_any_map:
        return st.tuples(not_(dict), st.just(bad))
    if check is t_str_map:
        return st.tuples(st.one_of(not_(dict), st.dictionaries(NAMES, not_(str), min_size=1, max_size=2)), st.just(bad))
    raise AssertionError(f"no strategy for checker {check!r}")


def to_wire(v: Any) -> Any:
    if isinstance(v, np.ndarray):
        return wire_array(v)
    if isinstance(v, dict):
        return {k: to_wire(x) for k, x in v.items()}
    if isinstance(v, list):
        return [to_wire(x) for x in v]
    return v


@st.composite
def valid_fields(draw: st.DrawFn, fields: Fields) -> dict:
    """Every required field and a random subset of the optional ones."""
    out = {}
    for name, (check, required) in fields.items():
        if required or draw(st.booleans()):
            out[name] = draw(valid(check))
    return out


COMMANDS = sorted(REQUESTS)

# --- decode_request ----------------------------------------------------------------------------


def expect_protocol_error(payload: bytes, codes: set[str] | None = None) -> ProtocolError:
    try:
        request = decode_request(payload)
    except ProtocolError as exc:
        no_crash(exc)
        assert isinstance(exc.message, str) and exc.message
        if codes is not None:
            assert exc.code in codes, f"code {exc.code!r} ({exc.message}) not in {codes}"
        return exc
    raise AssertionError(f"decoded {request!r}; expected a ProtocolError with code in {codes}")


def no_crash(exc: ProtocolError) -> None:
    """A documented rejection, not the decoders' catch-all for an unexpected exception (code ``internal``)."""
    assert exc.code in ERROR_CODES
    assert exc.code != "internal", f"the decoder crashed: {exc.message}"


def decode_totally(payload: bytes) -> None:
    """Either a valid request or a ProtocolError: nothing else may escape."""
    try:
        request = decode_request(payload)
    except ProtocolError as exc:
        no_crash(exc)
        return
    assert request.cmd in REQUESTS


@fuzz(4000)
@given(st.binary(max_size=200))
def test_decode_request_random_bytes(payload: bytes) -> None:
    decode_totally(payload)


envelopes = st.fixed_dictionaries(
    {},
    optional={
        "v": st.one_of(st.just(PROTOCOL_VERSION), junk),
        "cmd": st.one_of(st.sampled_from(COMMANDS), junk),
        "args": st.one_of(
            st.sampled_from(COMMANDS).flatmap(
                lambda c: st.dictionaries(st.sampled_from([*REQUESTS[c], "x"]), junk, max_size=4)
            ),
            junk,
        ),
    },
)


@pytest.mark.slow
@fuzz(1500)
@given(st.one_of(junk, envelopes, st.dictionaries(junk.filter(lambda k: not isinstance(k, (dict, list))), junk)))
def test_decode_request_random_msgpack(value: Any) -> None:
    try:
        payload = pack(value)
    except (TypeError, ValueError):  # e.g. unhashable or unpackable keys
        assume(False)
    decode_totally(payload)
    # and the same bytes with a truncated tail
    if len(payload) > 1:
        decode_totally(payload[: len(payload) // 2])


REQUEST_MUTATIONS = [
    "missing_field",
    "unknown_field",
    "wrong_type",
    "wrong_type",
    "bad_array",
    "bad_array",
    "bad_array",
    "nested_junk",
    "version",
    "envelope_field",
    "cmd_type",
    "cmd_unknown",
    "args_type",
    "non_string_key",
]
ARRAY_FIELDS = {
    cmd: [k for k, (check, _) in fields.items() if check in (t_array, t_array_map)] for cmd, fields in REQUESTS.items()
}


@st.composite
def malformed_requests(draw: st.DrawFn) -> tuple[bytes, set[str], str, str]:
    """(payload, acceptable error codes, "cmd/mutation", text the error message must contain)"""
    kind = draw(st.sampled_from(REQUEST_MUTATIONS))
    if kind == "bad_array":
        cmd = draw(st.sampled_from([c for c in COMMANDS if ARRAY_FIELDS[c]]))
    elif kind in ("missing_field", "wrong_type", "nested_junk"):
        cmd = draw(st.sampled_from([c for c in COMMANDS if REQUESTS[c]]))
    else:
        cmd = draw(st.sampled_from(COMMANDS))
    fields = REQUESTS[cmd]
    args = to_wire(draw(valid_fields(fields)))
    msg: dict[Any, Any] = {"v": PROTOCOL_VERSION, "cmd": cmd, "args": args}
    required = [k for k, (_, req) in fields.items() if req]
    if kind == "missing_field" and not required:
        kind = "unknown_field"
    codes, mention = {"bad_request"}, ""
    if kind == "missing_field":
        name = draw(st.sampled_from(required))
        del args[name]
        mention = f"missing required field {name!r}"
    elif kind == "unknown_field":
        args[draw(NAMES.filter(lambda k: k not in fields))] = draw(junk)
        mention = "unknown field"
    elif kind == "wrong_type":
        name = draw(st.sampled_from(sorted(fields)))
        args[name], codes = draw(invalid(fields[name][0]))
        mention = f"args.{name}"
    elif kind == "bad_array":
        name = draw(st.sampled_from(ARRAY_FIELDS[cmd]))
        mention = f"args.{name}"
        bad = draw(bad_arrays)
        if fields[name][0] is t_array_map:  # one bad array among good ones
            good = {k: wire_array(a) for k, a in draw(st.dictionaries(NAMES, arrays(), max_size=2)).items()}
            bad = {**good, draw(NAMES.filter(lambda k: k not in good)): bad}
        args[name] = bad
    elif kind == "nested_junk":
        name = draw(st.sampled_from(sorted(fields)))
        mention = f"args.{name}"
        if fields[name][0] is t_params:
            args[name] = {"p": nested(draw(st.integers(MAX_NESTING + 1, 200)))}
        else:
            args[name] = nested(draw(st.integers(1, 200)), draw(junk))
    elif kind == "version":
        v = draw(st.one_of(st.just("absent"), not_(int), INT64.filter(lambda v: v != PROTOCOL_VERSION)))
        if v == "absent":
            del msg["v"]
        else:
            msg["v"] = v
        codes = {"version"}
    elif kind == "envelope_field":
        msg[draw(NAMES.filter(lambda k: k not in msg))] = draw(junk)
    elif kind == "cmd_type":
        msg["cmd"] = draw(not_(str))
    elif kind == "cmd_unknown":
        msg["cmd"] = draw(st.text(max_size=20).filter(lambda c: c not in REQUESTS))
        codes = {"unknown_command"}
    elif kind == "args_type":
        msg["args"] = draw(not_(dict))
    elif kind == "non_string_key":
        args[draw(st.one_of(INT64, st.booleans(), st.none()))] = 1
        codes = {"decode"}
    return pack(msg), codes, f"{cmd}/{kind}", mention


@pytest.mark.slow
@fuzz(2000)
@given(malformed_requests())
def test_decode_request_rejects_malformed_requests(case: tuple[bytes, set[str], str, str]) -> None:
    payload, codes, what, mention = case
    event(what.split("/")[1])  # pytest --hypothesis-show-statistics shows the mix of mutations
    exc = expect_protocol_error(payload, codes)
    assert mention in exc.message, f"{what}: {exc.message!r} does not say {mention!r}"


def test_a_crashing_checker_fails_the_fuzz_assertions(monkeypatch: pytest.MonkeyPatch) -> None:
    """The assertions above can fail: a checker that raises something other than ProtocolError is seen."""
    import cosim.protocol.messages as messages

    def broken(value: Any, path: str) -> Any:
        raise ZeroDivisionError("checker bug")

    fields = {**REQUESTS["set_state"], "time": (broken, True)}
    monkeypatch.setitem(messages.REQUESTS, "set_state", fields)
    payload = encode_request("set_state", {"time": 0.0, "state": np.zeros(2)})
    with pytest.raises(AssertionError, match="crashed.*ZeroDivisionError"):
        decode_totally(payload)
    with pytest.raises(AssertionError, match="catch-all.*ZeroDivisionError"):
        assert_error_reply(answer(fresh_runtime(), payload), RUNTIME)
    monkeypatch.setitem(messages.RESULTS, "commit", {"time": (broken, True)})
    with pytest.raises(AssertionError, match="crashed.*ZeroDivisionError"):
        decode_reply_totally("commit", encode_result({"time": 1.0}))


@given(arrays())
def test_the_array_fast_path_gives_what_the_checked_path_gives(a: np.ndarray) -> None:
    """t_array's fast path (well-formed arrays) and the full check it falls back to: the same read-only array."""
    wire = wire_array(a)
    fast, checked = t_array(wire, "x"), _t_array_checked(wire, "x")
    assert (fast.shape, fast.dtype, fast.tobytes()) == (checked.shape, checked.dtype, checked.tobytes())
    assert not fast.flags.writeable and not checked.flags.writeable


def test_named_hostile_arrays_are_rejected() -> None:
    """The shapes the brief names, spelled out (the fuzzers above also draw them)."""
    for shape, data in [
        ([2**40, 2**40], b"\x00" * 8),
        ([0, 2**63 - 1], b""),
        ([0, 2**64 - 1], b""),
        ([-1], b""),
        ([-2, -4], b"\x00" * 64),
        ([1] * (MAX_NDIM + 1), b"\x00" * 8),
        ([], b"\x00" * 8),
        ([3], b"\x00" * 23),
    ]:
        payload = pack({"v": 1, "cmd": "set_state", "args": {"time": 0.0, "state": {"shape": shape, "data": data}}})
        exc = expect_protocol_error(payload, {"bad_request"})
        assert "args.state" in exc.message, exc.message


def test_deep_nesting_is_a_protocol_error() -> None:
    head = pack({"v": 1, "cmd": "configure", "args": {"params": {"a": None}}})
    assert head.endswith(b"\xc0")
    for depth, code in [(MAX_NESTING + 1, "bad_request"), (5000, "decode"), (200_000, "decode")]:
        expect_protocol_error(head[:-1] + b"\x91" * depth + b"\xc0", {code})


# --- decode_reply ------------------------------------------------------------------------------

reply_cmds = st.one_of(st.sampled_from(sorted(RESULTS)), st.text(max_size=10))
reply_envelopes = st.fixed_dictionaries(
    {},
    optional={
        "v": st.one_of(st.just(PROTOCOL_VERSION), junk),
        "ok": st.one_of(st.booleans(), junk),
        "result": junk,
        "error": st.one_of(st.dictionaries(st.sampled_from(["code", "message", "subsim", "command", "x"]), junk), junk),
    },
)


def decode_reply_totally(cmd: str, payload: bytes) -> None:
    try:
        out = decode_reply(cmd, payload)
    except ProtocolError as exc:
        if cmd in RESULTS:
            no_crash(exc)
        else:  # asking for a command with no result schema is the caller's bug: the catch-all names it
            assert exc.code in ERROR_CODES and (exc.code != "internal" or "KeyError" in exc.message), exc.message
        return
    assert isinstance(out, (dict, ErrorInfo))


@pytest.mark.slow
@fuzz(1000)
@given(reply_cmds, st.one_of(st.binary(max_size=200), junk.map(pack), reply_envelopes.map(pack)))
def test_decode_reply_random(cmd: str, payload: bytes) -> None:
    decode_reply_totally(cmd, payload)
    decode_reply_totally(cmd, payload[: len(payload) // 2])


@st.composite
def malformed_results(draw: st.DrawFn) -> tuple[str, bytes, set[str]]:
    cmd = draw(st.sampled_from(sorted(RESULTS)))
    fields = RESULTS[cmd]
    result = to_wire(draw(valid_fields(fields)))
    msg: dict[str, Any] = {"v": PROTOCOL_VERSION, "ok": True, "result": result}
    required = [k for k, (_, req) in fields.items() if req]
    kind = draw(st.sampled_from(["missing_field", "wrong_type", "version", "ok_type", "result_type", "error"]))
    if kind in ("missing_field", "wrong_type") and not required:
        kind = "result_type"
    codes = {"bad_request"}
    if kind == "missing_field":
        del result[draw(st.sampled_from(required))]
    elif kind == "wrong_type":
        name = draw(st.sampled_from(sorted(fields)))
        result[name], codes = draw(invalid(fields[name][0]))
    elif kind == "version":
        msg["v"] = draw(not_(int) | INT64.filter(lambda v: v != PROTOCOL_VERSION))
        codes = {"version"}
    elif kind == "ok_type":
        msg["ok"] = draw(not_(bool))
    elif kind == "result_type":
        msg["result"] = draw(not_(dict))
    else:  # an error reply with a missing or mistyped field
        error = {"code": "internal", "message": "m", "subsim": "s", "command": cmd}
        name = draw(st.sampled_from(sorted(error)))
        if draw(st.booleans()):
            del error[name]
        else:
            error[name] = draw(not_(str))
        msg = {"v": PROTOCOL_VERSION, "ok": False, "error": error}
    return cmd, pack(msg), codes


@pytest.mark.slow
@fuzz(700)
@given(malformed_results())
def test_decode_reply_rejects_malformed_results(case: tuple[str, bytes, set[str]]) -> None:
    cmd, payload, codes = case
    with pytest.raises(ProtocolError) as info:
        decode_reply(cmd, payload)
    no_crash(info.value)
    assert info.value.code in codes


def _same(a: Any, b: Any) -> bool:
    """Equality with arrays compared bit for bit and floats by their bits (so -0.0 != 0.0)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a64 = np.ascontiguousarray(a, dtype="<f8")
        return (
            isinstance(b, np.ndarray)
            and b.dtype == np.dtype("<f8")
            and a64.shape == b.shape
            and (a64.tobytes() == b.tobytes())
        )
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, float) or isinstance(b, float):
        return isinstance(b, (int, float)) and struct.pack("<d", float(a)) == struct.pack("<d", float(b))
    return type(a) is type(b) and a == b


@fuzz(100)
@given(st.data())
def test_decode_reply_ignores_unknown_fields(data: st.DataObject) -> None:
    cmd = data.draw(st.sampled_from(sorted(RESULTS)))
    result = data.draw(valid_fields(RESULTS[cmd]))
    extra = data.draw(st.dictionaries(NAMES.filter(lambda k: k not in RESULTS[cmd]), junk, max_size=3))
    envelope_extra = data.draw(st.dictionaries(NAMES.filter(lambda k: k not in ("v", "ok", "result")), junk))
    msg = {"v": PROTOCOL_VERSION, "ok": True, "result": {**to_wire(result), **extra}, **envelope_extra}
    decoded = decode_reply(cmd, pack(msg))
    assert isinstance(decoded, dict)
    assert _same(result, decoded)


# --- the server's answer() ---------------------------------------------------------------------


def _committed(rt: Runtime) -> tuple:
    return (
        rt.time,
        rt.state.tobytes(),
        [(t, s.tobytes()) for t, s in rt.history],
        rt.epoch,
        type(rt.model),
        {k: p.size for k, p in rt.inputs.items()},
    )


def fresh_runtime() -> Runtime:
    """A size-2 integrator with two committed intervals (so a history) and one pending trial."""
    rt = Runtime(Integrator(), "fuzzed")
    rt.configure({"size": 2, "y0": [1.0, -2.0]}, t0=0.0)
    for t0 in (0.0, 0.5):
        times = np.linspace(t0, t0 + 0.5, 3)
        rt.run_interval(times, {"u": np.ones((3, 2))})
        rt.commit()
    rt.run_interval(np.linspace(1.0, 1.5, 3), {"u": np.ones((3, 2))})
    return rt


RUNTIME = fresh_runtime()
garbage = st.one_of(
    st.binary(max_size=120),
    junk.map(pack),
    envelopes.map(pack),
    malformed_requests().map(lambda case: case[0]),
)


def assert_error_reply(reply: bytes, rt: Runtime) -> ErrorInfo:
    info = decode_reply("status", reply)  # any command: an error reply does not depend on it
    assert isinstance(info, ErrorInfo)
    assert info.code in ERROR_CODES and info.message and info.subsim == rt.name
    assert info.code != "internal", f"answer() took its catch-all: {info.message}"
    return info


@fuzz(600)
@given(garbage)
def test_answer_garbage_is_an_error_reply(payload: bytes) -> None:
    try:
        decode_request(payload)
    except ProtocolError:
        pass
    else:
        assume(False)  # a valid request is not garbage
    rt = RUNTIME
    before, trial = _committed(rt), rt.trial
    assert_error_reply(answer(rt, payload), rt)
    assert _committed(rt) == before
    assert rt.trial is trial  # a rejected request does not even touch the pending trial


out_of_contract = st.one_of(
    # run_interval: wrong start time, non-increasing or non-finite times, bad inputs, bad scheme
    st.tuples(finite.filter(lambda t: t != 1.0), st.integers(2, 5)).map(
        lambda a: ("run_interval", {"t": np.linspace(a[0], a[0] + 1, a[1]), "inputs": {"u": np.zeros((a[1], 2))}})
    ),
    st.lists(finite, min_size=1, max_size=5)
    .map(lambda ts: ("run_interval", {"t": np.array([1.0, *sorted(ts, reverse=True)]), "inputs": {"u": np.zeros(1)}}))
    .filter(lambda c: np.any(np.diff(c[1]["t"]) <= 0) or c[1]["t"].size < 2),
    st.sampled_from([math.nan, math.inf, -math.inf]).map(
        lambda x: ("run_interval", {"t": np.array([1.0, x]), "inputs": {"u": np.zeros((2, 2))}})
    ),
    st.lists(st.integers(0, 4), min_size=1, max_size=3)
    .filter(lambda s: tuple(s) != (3, 2))
    .map(lambda s: ("run_interval", {"t": np.array([1.0, 1.2, 1.4]), "inputs": {"u": np.zeros(s)}})),
    st.sampled_from([math.nan, math.inf]).map(
        lambda x: ("run_interval", {"t": np.array([1.0, 2.0]), "inputs": {"u": np.array([[0.0, x], [0.0, 0.0]])}})
    ),
    NAMES.filter(lambda n: n != "u").map(
        lambda n: ("run_interval", {"t": np.array([1.0, 2.0]), "inputs": {n: np.zeros((2, 2))}})
    ),
    st.text(max_size=8)
    .filter(lambda s: s not in ("linear", "cubic", "lagrange"))
    .map(lambda s: ("run_interval", {"t": np.array([1.0, 2.0]), "inputs": {"u": np.zeros((2, 2))}, "interp": s})),
    # rollback to a time that is not in the history
    finite.filter(lambda t: t not in (0.0, 0.5, 1.0)).map(lambda t: ("rollback", {"to_time": t})),
    # set_state with a state of the wrong size or with NaN
    arrays()
    .filter(lambda a: a.shape != (2,) or not np.all(np.isfinite(a)))
    .map(lambda a: ("set_state", {"time": 3.0, "state": a})),
    # configure with bad parameters (the old configuration must survive)
    st.sampled_from(
        [
            {"size": 0},
            {"size": -1},
            {"size": "two"},
            {"size": [2]},
            {"y0": [1.0, 2.0, 3.0]},
            {"size": 3, "y0": [1.0]},
            {"y0": "zero"},
            {"y0": None},
        ]
    ).map(lambda p: ("configure", {"params": p})),
)


@fuzz(300)
@given(out_of_contract)
def test_answer_out_of_contract_requests(case: tuple[str, dict]) -> None:
    cmd, args = case
    rt = fresh_runtime() if cmd == "rollback" else RUNTIME  # a failed rollback discards the trial
    before = _committed(rt)
    info = assert_error_reply(answer(rt, encode_request(cmd, args)), rt)
    assert info.command == cmd
    # configure {"y0": None} gives a NaN initial state: bad_value, the parameters' fault
    assert info.code in {"bad_value", "time_mismatch", "not_in_history"}
    assert _committed(rt) == before


# --- round trips -------------------------------------------------------------------------------


@fuzz(600)
@given(st.data())
def test_request_round_trip(data: st.DataObject) -> None:
    cmd = data.draw(st.sampled_from(COMMANDS))
    args = data.draw(valid_fields(REQUESTS[cmd]))
    request = decode_request(encode_request(cmd, args))
    assert request.cmd == cmd
    assert _same(args, request.args), (args, request.args)


def test_round_trip_special_values() -> None:
    specials = np.array(SPECIAL)
    nan_payload = np.frombuffer(bytes.fromhex("0100000000f8ff7f") + bytes.fromhex("ffffffffffffffff"), "<f8")
    for args in (
        {"time": -0.0, "state": specials},
        {"time": 5e-324, "state": nan_payload},
        {"time": 1.7976931348623157e308, "state": specials.reshape(-1)[::-1].astype(">f8")},
    ):
        out = decode_request(encode_request("set_state", args)).args
        assert _same(args, out)
        assert math.copysign(1.0, out["time"]) == math.copysign(1.0, args["time"])


def test_array_valued_parameters_travel_as_lists() -> None:
    """A remote configure must accept what an in-process one accepts (numpy arrays in params)."""
    params = {"y0": np.array([-0.0, 5e-324, 1.5]), "gains": {"k": np.arange(4.0).reshape(2, 2)}, "n": np.int64(3)}
    out = decode_request(encode_request("configure", {"params": params})).args["params"]
    assert out == {"y0": [-0.0, 5e-324, 1.5], "gains": {"k": [[0.0, 1.0], [2.0, 3.0]]}, "n": 3}
    assert math.copysign(1.0, out["y0"][0]) == -1.0


@fuzz(200)
@given(st.data())
def test_reply_round_trip(data: st.DataObject) -> None:
    cmd = data.draw(st.sampled_from(sorted(RESULTS)))
    result = data.draw(valid_fields(RESULTS[cmd]))
    decoded = decode_reply(cmd, encode_result(result))
    assert _same(result, decoded)


def test_worked_example_in_the_docs_matches_the_encoder() -> None:
    """docs/protocol.md section 9 shows these bytes; they must stay what the code produces."""
    doc = (Path(__file__).resolve().parents[1] / "docs" / "protocol.md").read_text()
    shown = {m[0]: bytes.fromhex(m[1]) for m in re.findall(r"<!-- example-(\w+) -->\n```\n([0-9a-f]+)\n```", doc)}
    request = encode_request(
        "run_interval", {"t": np.array([0.0, 0.5]), "inputs": {"u": np.array([[1.0], [2.0]])}, "interp": "linear"}
    )
    assert shown["request"] == request
    rt = Runtime(Integrator(), "integrator")
    rt.configure({})
    assert shown["reply"] == answer(rt, request) == answer(rt, request)


def test_numbers_may_be_any_msgpack_int_or_float() -> None:
    """docs/protocol.md: a *number* is a msgpack int or a float 32/64; a boolean is not a number."""
    for t0, packed_as in [(0.5, "float32"), (0.5, "float64"), (3, "int")]:
        payload = msgpack.packb(
            {"v": 1, "cmd": "configure", "args": {"params": {}, "t0": t0}}, use_single_float=packed_as == "float32"
        )
        assert (b"\xca" in payload) == (packed_as == "float32")
        assert decode_request(payload).args["t0"] == t0
    expect_protocol_error(pack({"v": 1, "cmd": "configure", "args": {"params": {}, "t0": True}}), {"bad_request"})
