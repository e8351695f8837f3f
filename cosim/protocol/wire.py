"""Field types of the wire format: msgpack values checked and converted, never trusted.

Every checker takes ``(value, path)`` and returns the converted value or raises
``ProtocolError`` naming ``path`` (e.g. ``args.inputs.R``) and what was expected.
Arrays travel as ``{"shape": [int, ...], "data": <bin: little-endian float64>}``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import msgpack
import numpy as np

from cosim.contract import ProtocolError

Checker = Callable[[Any, str], Any]

MAX_NDIM = 4
MAX_NESTING = 32
_F8 = np.dtype("<f8")


def bad(path: str, expected: str, value: Any) -> ProtocolError:
    shown = type(value).__name__ if not isinstance(value, (int, float, str, bool)) else repr(value)[:60]
    return ProtocolError("bad_request", f"{path}: expected {expected}, got {shown}")


def pack(obj: Any) -> bytes:
    return msgpack.packb(obj, use_bin_type=True)


def _unique_keys(pairs: list[tuple[Any, Any]]) -> dict:
    out = dict(pairs)
    if len(out) != len(pairs):
        seen: set = set()
        raise ValueError(f"duplicate map key {next(k for k, _ in pairs if k in seen or seen.add(k))!r}"[:80])
    return out


def unpack_map(payload: bytes, unique_keys: bool = False) -> dict:
    """Decode a msgpack payload that must be a map; any failure is a ``decode`` error.

    Trailing bytes after the map are an error. ``unique_keys``: a map anywhere in the payload that
    repeats a key is an error too (requests); otherwise the last value of a repeated key wins (replies)."""
    try:
        if unique_keys:
            obj = msgpack.unpackb(payload, raw=False, strict_map_key=True, object_pairs_hook=_unique_keys)
        else:
            obj = msgpack.unpackb(payload, raw=False, strict_map_key=True)
    except Exception as exc:  # msgpack raises several unrelated types on garbage
        raise ProtocolError("decode", f"payload is not valid msgpack ({type(exc).__name__}: {exc})"[:200]) from None
    if not isinstance(obj, dict):
        raise ProtocolError("decode", f"payload must be a msgpack map, got {type(obj).__name__}")
    return obj


def encode_array(a: np.ndarray) -> dict:
    arr = a if a.dtype == _F8 and a.flags.c_contiguous else np.ascontiguousarray(a, dtype=_F8)
    return {"shape": list(arr.shape), "data": arr.tobytes()}


# --- checkers -------------------------------------------------------------------------------


def t_bool(v: Any, path: str) -> bool:
    if not isinstance(v, bool):
        raise bad(path, "a boolean", v)
    return v


def t_int(v: Any, path: str) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        raise bad(path, "an integer", v)
    return v


def t_str(v: Any, path: str) -> str:
    if not isinstance(v, str):
        raise bad(path, "a string", v)
    return v


def t_float(v: Any, path: str) -> float:
    """A finite number (integers accepted)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise bad(path, "a number", v)
    try:
        f = float(v)
    except OverflowError:
        raise ProtocolError("bad_value", f"{path}: number out of float range") from None
    if not math.isfinite(f):
        raise ProtocolError("bad_value", f"{path}: must be finite, got {f!r}")
    return f


def t_opt(inner: Checker) -> Checker:
    def check(v: Any, path: str) -> Any:
        return None if v is None else inner(v, path)

    return check


def t_array(v: Any, path: str) -> np.ndarray:
    """An encoded float64 array (finite values are the runtime's business, not the codec's).

    The array is a read-only view of the received bytes (no copy)."""
    if type(v) is dict and len(v) == 2:  # the fast path of a well-formed array; anything else is diagnosed below
        shape, data = v.get("shape"), v.get("data")
        if type(shape) is list and type(data) is bytes and 1 <= len(shape) <= MAX_NDIM:
            count = 1
            for d in shape:
                if type(d) is not int or d < 0:
                    break
                count *= d
            else:
                if count * 8 == len(data) and count < 2**62:
                    try:  # a read-only view of ``data`` in one call (frombuffer + reshape take twice as long)
                        return np.ndarray(shape, _F8, data)
                    except ValueError:  # e.g. [0, 2**62]: no data, but numpy cannot index such a shape
                        pass
    return _t_array_checked(v, path)


def _t_array_checked(v: Any, path: str) -> np.ndarray:
    if not isinstance(v, dict) or set(v) != {"shape", "data"}:
        raise bad(path, 'an array map {"shape": [...], "data": <bin>}', v)
    shape, data = v["shape"], v["data"]
    if not isinstance(shape, list) or not 1 <= len(shape) <= MAX_NDIM:
        raise bad(f"{path}.shape", f"a list of 1..{MAX_NDIM} non-negative integers", shape)
    for d in shape:
        if isinstance(d, bool) or not isinstance(d, int) or d < 0:
            raise bad(f"{path}.shape", "non-negative integers", d)
    if not isinstance(data, bytes):
        raise bad(f"{path}.data", "binary data", data)
    count = math.prod(shape)
    if count * 8 != len(data):
        raise ProtocolError(
            "bad_request", f"{path}: shape {shape} needs {count * 8} bytes of float64, data has {len(data)}"
        )
    try:
        return np.frombuffer(data, dtype=_F8).reshape(shape)
    except ValueError:  # e.g. [0, 2**63]: no data, but numpy cannot index such a shape
        raise ProtocolError("bad_request", f"{path}: shape {shape} is too large to address") from None


def t_array_map(v: Any, path: str) -> dict[str, np.ndarray]:
    if not isinstance(v, dict):
        raise bad(path, "a map of name -> array", v)
    return {t_str(k, f"{path} key"): t_array(a, f"{path}.{k}") for k, a in v.items()}


def t_port_map(v: Any, path: str) -> dict[str, dict]:
    if not isinstance(v, dict):
        raise bad(path, "a map of port name -> {size, unit, doc}", v)
    out = {}
    for k, p in v.items():
        name = t_str(k, f"{path} key")
        out[name] = check_fields(p, PORT_FIELDS, f"{path}.{name}", strict=False)
        if out[name]["size"] < 1:
            raise ProtocolError("bad_request", f"{path}.{name}.size: must be >= 1")
    return out


def t_value(v: Any, path: str, depth: int = 0) -> Any:
    """A parameter value: nil, bool, int, float, str, list or string-keyed map, nested <= 32 deep."""
    if depth > MAX_NESTING:
        raise ProtocolError("bad_request", f"{path}: nested deeper than {MAX_NESTING}")
    if v is None or isinstance(v, (bool, int, float, str)):
        return v
    if isinstance(v, list):
        return [t_value(x, f"{path}[{i}]", depth + 1) for i, x in enumerate(v)]
    if isinstance(v, dict):
        return {t_str(k, f"{path} key"): t_value(x, f"{path}.{k}", depth + 1) for k, x in v.items()}
    raise bad(path, "nil, bool, number, string, list or map", v)


def t_params(v: Any, path: str) -> dict:
    if not isinstance(v, dict):
        raise bad(path, "a map of parameters", v)
    return t_value(v, path)


def t_param_decls(v: Any, path: str) -> dict[str, dict]:
    """A description's declared parameters: name -> {"default": value, "unit": str, "doc": str}."""
    if not isinstance(v, dict):
        raise bad(path, "a map of parameter name -> {default, unit, doc}", v)
    return {t_str(k, f"{path} key"): check_fields(d, PARAM_FIELDS, f"{path}.{k}", strict=False) for k, d in v.items()}


def t_str_map(v: Any, path: str) -> dict[str, str]:
    m = t_any_map(v, path)
    for k, x in m.items():
        t_str(k, f"{path} key")  # (msgpack lets bytes keys through)
        t_str(x, f"{path}.{k}")
    return m


def t_any_map(v: Any, path: str) -> dict:
    if not isinstance(v, dict):
        raise bad(path, "a map", v)
    return v


Fields = dict[str, tuple[Checker, bool]]  # name -> (checker, required)

PORT_FIELDS: Fields = {"size": (t_int, True), "unit": (t_str, False), "doc": (t_str, False)}
PARAM_FIELDS: Fields = {"default": (t_value, False), "unit": (t_str, False), "doc": (t_str, False)}


def check_fields(obj: Any, fields: Fields, path: str, strict: bool = True) -> dict:
    """Check a map against ``fields``; unknown keys are errors when ``strict``, else dropped."""
    if not isinstance(obj, dict):
        raise bad(path, "a map", obj)
    if strict and not obj.keys() <= fields.keys():  # a set comparison in C; the list only for the message
        unknown = [k for k in obj if k not in fields]
        if unknown:
            known = f"known: {', '.join(fields)}" if fields else "it takes none"
            raise ProtocolError("bad_request", f"{path}: unknown field(s) {', '.join(map(repr, unknown))}; {known}")
    out = {}
    for name, (check, required) in fields.items():
        if name in obj:
            out[name] = check(obj[name], f"{path}.{name}")
        elif required:
            raise ProtocolError("bad_request", f"{path}: missing required field {name!r}")
    return out
