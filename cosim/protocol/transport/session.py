"""Zenoh sessions: configuration, the coordinator's router, a subsim's client.

Topology: the coordinator's session is a ``router`` listening on an endpoint; every subsim is a
``client`` connected to it. Multicast scouting is always off (runs and tests never find each
other); shared memory is off (small payloads, and SHM-promoted queries can be dropped under
load, eclipse-zenoh/zenoh#2628). The admin space is closed unless asked for; a run's router admits
only logins it knows and applies access control to the run's keys (docs/reliability.md).
"""

from __future__ import annotations

import json
import os
import re
import resource
import socket
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import zenoh

from cosim.protocol.keys import alive_key, coordinator_alive_key, rpc_key
from cosim.protocol.security import ClientSecurity, Security, tls_problem

# The transport's own failure (a session that cannot open, a link refused), for the layers above that report it
# without importing zenoh themselves.
BusError = zenoh.ZError

# All of zenoh's internal thread pools (app, rx, tx, acc, net) handed over to one thread. On a 2-core
# machine this cut a small request/reply from 225 to 150 us and the CPU per request by about 40 %, since
# fewer thread hand-offs and wake-ups sit on the path. Read once per process, at the first session open;
# set ZENOH_RUNTIME yourself to override.
SINGLE_THREAD_RUNTIME = (
    "(app: (worker_threads: 1), rx: (handover: app), tx: (handover: app), acc: (handover: app), net: (handover: app))"
)


ZENOH_NEEDED = (1, 10)  # the eclipse-zenoh this transport is written for (pyproject.toml: >=1.10,<2)


def installed_zenoh() -> str | None:
    """The installed eclipse-zenoh's version, from the ``.dist-info`` directory pip put beside the package; None when
    there is none (a build from source). Read there, not through importlib.metadata, whose import costs every
    subsim process about 30 ms at its start."""
    for info in Path(zenoh.__file__).resolve().parent.parent.glob("eclipse_zenoh-*.dist-info"):
        return info.name.removeprefix("eclipse_zenoh-").removesuffix(".dist-info")
    return None


def zenoh_mismatch() -> str | None:
    """One line when the installed eclipse-zenoh is not one this transport works with (an older one fails with a
    TypeError on every request it serves), else None."""
    have = installed_zenoh()
    if have is None:
        return None  # (nothing to compare)
    numbers = tuple(int(x) for x in re.findall(r"\d+", have)[:2])
    if ZENOH_NEEDED <= numbers < (ZENOH_NEEDED[0] + 1,):
        return None
    needed = ".".join(map(str, ZENOH_NEEDED))
    return (f"cosim needs eclipse-zenoh >= {needed}, < {ZENOH_NEEDED[0] + 1} and this Python has {have}: "
            f"pip install 'eclipse-zenoh>={needed},<{ZENOH_NEEDED[0] + 1}'")


# Incoming links: a flood of TCP connections that never log in (no login needed to open one) kept subsims out with
# Zenoh's defaults, which admit 100 handshakes at a time and give each 10 s: 150 idle connections stopped a run from
# starting. Many more may be pending, within the descriptors this process may open, and each gets 3 s: enough for a
# handshake's 3-4 round trips (TLS included) over a link of up to about 0.7 s round trip; a subsim whose try runs out
# tries again. (Measured with the larger bound: 150 idle connections still delayed a run by 7 s with 10 s each, not
# measurably with 3 s.)
UNIX_SOCKET = "unixsock-stream/"  # an endpoint on a Unix socket: this prefix, then the socket's path
ACCEPT_TIMEOUT_MS = 3000
ACCEPT_PENDING_MAX = 10000


def accept_pending() -> int:
    """How many handshakes the router may have pending: half of the file descriptors this process may open (its
    soft limit raised towards the hard one first), so that a flood leaves descriptors for the run's own files and
    processes; at least Zenoh's default of 100. (Processes started afterwards inherit the raised soft limit.)"""
    want = 2 * ACCEPT_PENDING_MAX
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft != resource.RLIM_INFINITY and soft < want:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (want if hard == resource.RLIM_INFINITY else min(want, hard),
                                                        hard))
        except (ValueError, OSError):  # not allowed here: keep the soft limit
            pass
        soft = resource.getrlimit(resource.RLIMIT_NOFILE)[0]
    return ACCEPT_PENDING_MAX if soft == resource.RLIM_INFINITY else max(100, min(ACCEPT_PENDING_MAX, soft // 2))


def make_config(
    mode: str,
    listen: list[str] | tuple[str, ...] = (),
    connect: list[str] | tuple[str, ...] = (),
    extra: dict[str, Any] | None = None,
) -> zenoh.Config:
    os.environ.setdefault("ZENOH_RUNTIME", SINGLE_THREAD_RUNTIME)
    conf = zenoh.Config()
    settings: dict[str, Any] = {
        "mode": mode,
        "scouting/multicast/enabled": False,
        "scouting/delay": 0,
        "listen/endpoints": list(listen),
        "connect/endpoints": list(connect),
        "transport/shared_memory/enabled": False,
    }
    settings.update(extra or {})
    for key, value in settings.items():
        conf.insert_json5(key, json.dumps(value))
    return conf


def client_config(
    endpoint: str, connect_timeout_s: float, lease_ms: int = 10000, security: ClientSecurity | None = None
) -> zenoh.Config:
    """A subsim's session. ``lease_ms`` only bounds how long a *hung* process goes unnoticed (a killed one
    is seen at once: its socket closes); 3 s proved too short on a loaded 2-core machine, where a busy
    router missed keepalives and dropped healthy subsims. ``security``: the router's login, and the CA
    (and client certificate) of a ``tls/`` endpoint."""
    extra: dict[str, Any] = {"connect/timeout_ms": int(connect_timeout_s * 1000), "transport/link/tx/lease": lease_ms}
    if security is not None and security.login is not None:
        extra["transport/auth/usrpwd/user"], extra["transport/auth/usrpwd/password"] = security.login
    if security is not None and security.tls_ca is not None:
        extra["transport/link/tls/root_ca_certificate"] = str(security.tls_ca)
    if security is not None and security.tls_cert is not None:
        extra["transport/link/tls/enable_mtls"] = True
        extra["transport/link/tls/connect_certificate"] = str(security.tls_cert)
        extra["transport/link/tls/connect_private_key"] = str(security.tls_key)
    return make_config("client", connect=[endpoint], extra=extra)


ANY_SUBSIM = "*"  # in access_control's ``servers``: the logins that may serve any subsim of the run


def access_control(run: str, servers: Mapping[str, Sequence[str]]) -> dict[str, Any]:
    """Zenoh access control of a run's router. ``servers``: subsim name -> the logins that may serve it (the
    name :data:`ANY_SUBSIM` for logins that may serve any). A login may serve ``cosim/<run>/<name>/rpc``, hold
    ``cosim/<run>/<name>/alive`` and watch ``cosim/<run>/@coordinator/alive``, and gets only the queries on
    its subsims' keys; nothing else passes, in either direction (no wildcard queries or scans, no other subsim's
    requests or liveliness, even to a wildcard queryable, no admin space, no other run's keys).
    The coordinator's own session is the router, which access control does not filter."""
    coordinator = coordinator_alive_key(run)

    def rule(rule_id: str, flow: str, messages: list[str], key: str) -> dict[str, Any]:
        return {"id": rule_id, "permission": "allow", "flows": [flow], "messages": messages, "key_exprs": [key]}

    common = [
        rule("watch", "ingress", ["declare_liveliness_subscriber", "liveliness_query"], coordinator),
        rule("coordinator", "egress", ["liveliness_token", "reply"], coordinator),
    ]
    rules, subjects, policies = list(common), [], []
    for index, (name, users) in enumerate(servers.items()):
        rpc, alive = rpc_key(run, name), alive_key(run, name)
        own = [
            rule(f"serve-{index}", "ingress", ["declare_queryable", "reply"], rpc),
            rule(f"announce-{index}", "ingress", ["liveliness_token"], alive),
            rule(f"requests-{index}", "egress", ["query"], rpc),
        ]
        rules += own
        subjects.append({"id": f"serves-{index}", "usernames": sorted(users)})
        policies.append({"id": f"subsim-{index}", "rules": [r["id"] for r in own + common],
                         "subjects": [f"serves-{index}"]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects,
            "policies": policies}


FORKED = ("this process was forked (multiprocessing's default start method on Linux) from one that had used Zenoh; "
          "Zenoh's threads do not survive a fork, and a bus opened here would hang: start the worker processes with "
          "multiprocessing.get_context('spawn'), or run them in-process (inprocess=True)")


class _Fork:
    used = False  # this process opened a Zenoh session
    inherited = False  # this process is a fork of one that had


def _forked() -> None:
    _Fork.inherited = _Fork.used


os.register_at_fork(after_in_child=_forked)


def open_router(
    listen: str = "tcp/127.0.0.1:0",
    run: str | None = None,
    logins: dict[str, str] | None = None,
    security: Security | None = None,
    servers: Mapping[str, Sequence[str]] | None = None,
) -> tuple[zenoh.Session, str]:
    """Open the coordinator's router session; return it with the endpoint clients should connect to.

    With ``run`` and ``logins`` (user -> password) the router admits only those logins and applies
    :func:`access_control` for ``run`` with ``servers`` (default: every login may serve any subsim).
    ``security`` adds TLS (``tls/`` endpoints) and opens the admin space when asked. Port 0 is replaced by a
    free port picked here (the admin space stays closed)."""
    security = security or Security()
    proto = listen.partition("/")[0]
    host, port = split_endpoint(listen) if proto in ("tcp", "tls") else ("", -1)  # e.g. unixsock-stream/...
    if security.tls and proto != "tls":
        raise ValueError(f"--listen {listen}: with a TLS certificate the endpoint must be tls/<host>:<port>")
    if proto == "tls" and not security.tls:
        raise ValueError(f"--listen {listen}: a tls/ endpoint needs --tls-cert and --tls-key (docs/reliability.md)")
    if security.tls and security.tls_cert is not None and security.tls_key is not None:
        named = None if host.strip("[]") in ("0.0.0.0", "::", "") else host.strip("[]")  # (every address: unknown)
        problem = tls_problem(security.tls_cert, security.tls_key, security.tls_ca, named)
        if problem is not None:  # said now, not by every subsim after 10 s as a refusal of any kind
            raise ValueError(problem)
    extra: dict[str, Any] = {
        "adminspace/enabled": security.admin_space,
        "transport/unicast/accept_timeout": ACCEPT_TIMEOUT_MS,
        "transport/unicast/accept_pending": accept_pending(),
    }
    if security.tls:
        extra["transport/link/tls/listen_certificate"] = str(security.tls_cert)
        extra["transport/link/tls/listen_private_key"] = str(security.tls_key)
        if security.mutual:
            extra["transport/link/tls/enable_mtls"] = True
            extra["transport/link/tls/root_ca_certificate"] = str(security.tls_ca)
    with tempfile.TemporaryDirectory(prefix="cosim-auth-") as tmp:
        if logins:
            dictionary = Path(tmp) / "users"
            fd = os.open(dictionary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
            with os.fdopen(fd, "w") as f:
                f.write("".join(f"{u}:{p}\n" for u, p in logins.items()))
            extra["transport/auth/usrpwd/dictionary_file"] = str(dictionary)
            if run is not None:
                extra["access_control"] = access_control(run, servers or {ANY_SUBSIM: list(logins)})
        tries = 5 if port == 0 else 1
        if _Fork.inherited:
            raise RuntimeError(FORKED)
        _Fork.used = True
        for attempt in range(tries):
            chosen = _free_port(host) if port == 0 else port
            endpoint = f"{proto}/{host}:{chosen}" if port >= 0 else listen
            try:  # the dictionary is read here; the directory goes when the router is open
                session = zenoh.open(make_config("router", listen=[endpoint], extra=extra))
                break
            except zenoh.ZError as exc:
                if attempt == tries - 1:
                    raise RuntimeError(f"cannot listen on {endpoint}: {error_text(exc)[:300]}") from None
    return session, _connectable(proto, host, chosen) if port >= 0 else listen


def error_text(exc: BaseException) -> str:
    """Zenoh's error as one line a user can read: its message, without Rust source paths and debug wrappers."""
    text = " ".join(str(exc).split())
    inner = re.search(r'msg: "(.*?)(?: at /\S+\.rs:\d+\.?)?"', text)  # Json5Err(Message { msg: "...", ...})
    if inner:
        text = inner.group(1)
    return re.sub(r"\s*at /\S+\.rs:\d+\.?", "", text)


def split_endpoint(endpoint: str) -> tuple[str, int]:
    host, colon, port = endpoint.partition("/")[2].rpartition(":")
    if not colon or not host or not port.isdigit():
        raise ValueError(f"endpoint {endpoint!r}: expected tcp/<host>:<port> or tls/<host>:<port>")
    return host, int(port)


def _free_port(host: str) -> int:
    """A port that is free on ``host`` now (the router binds it right after; a lost race is retried)."""
    bare = host.strip("[]")
    family = socket.AF_INET6 if ":" in bare else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as s:
        s.bind((socket.gethostbyname(bare) if family == socket.AF_INET else bare, 0))
        return s.getsockname()[1]


def _connectable(proto: str, host: str, port: int) -> str:
    """Where local clients connect: a wildcard listen address becomes loopback."""
    host = {"0.0.0.0": "127.0.0.1", "[::]": "[::1]"}.get(host, host)
    return f"{proto}/{host}:{port}"
