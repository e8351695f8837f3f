"""Key expressions of a run and the names that go into them (no transport here).

Every key of a run lives under ``cosim/<run>/``: ``<subsim>/rpc`` (the subsim's queryable),
``<subsim>/alive`` (its liveliness token) and ``@coordinator/alive`` (the coordinator's token).
"""

from __future__ import annotations

import re
import secrets

KEY_ROOT = "cosim"
_NAME = re.compile(r"^[A-Za-z0-9_.\-]{1,64}$")


def check_name(value: str, what: str) -> str:
    """Run ids and subsim names become key-expression chunks: no '/', '*', '$', '?', '#', spaces."""
    if not isinstance(value, str) or not _NAME.match(value):
        raise ValueError(f"{what} {value!r} must be 1-64 characters of letters, digits, '_', '-' or '.'")
    return value


def new_run_id() -> str:
    """``run-`` and 128 random bits from :mod:`secrets` (32 hex digits): not guessable, not enumerable."""
    return "run-" + secrets.token_hex(16)


def rpc_key(run: str, subsim: str) -> str:
    return f"{KEY_ROOT}/{run}/{subsim}/rpc"


def alive_key(run: str, subsim: str) -> str:
    return f"{KEY_ROOT}/{run}/{subsim}/alive"


def coordinator_alive_key(run: str) -> str:
    return f"{KEY_ROOT}/{run}/@coordinator/alive"
