"""Zenoh sessions: configuration, the coordinator's router, a subsim's client.

Topology: the coordinator's session is a ``router`` listening on an endpoint; every subsim is a
``client`` connected to it. Multicast scouting is always off (runs and tests never find each
other); shared memory is off (small payloads, and SHM-promoted queries can be dropped under
load, eclipse-zenoh/zenoh#2628).
"""

from __future__ import annotations

import json
import os
from typing import Any

import zenoh

# All of zenoh's internal thread pools (app, rx, tx, acc, net) handed over to one thread. On a 2-core
# machine this cut a small request/reply from 225 to 150 us and the CPU per request by about 40 %, since
# fewer thread hand-offs and wake-ups sit on the path. Read once per process, at the first session open;
# set ZENOH_RUNTIME yourself to override.
SINGLE_THREAD_RUNTIME = (
    "(app: (worker_threads: 1), rx: (handover: app), tx: (handover: app), acc: (handover: app), net: (handover: app))"
)


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


def client_config(endpoint: str, connect_timeout_s: float, lease_ms: int = 10000) -> zenoh.Config:
    """A subsim's session. ``lease_ms`` only bounds how long a *hung* process goes unnoticed (a killed one
    is seen at once: its socket closes); 3 s proved too short on a loaded 2-core machine, where a busy
    router missed keepalives and dropped healthy subsims."""
    return make_config(
        "client",
        connect=[endpoint],
        extra={"connect/timeout_ms": int(connect_timeout_s * 1000), "transport/link/tx/lease": lease_ms},
    )


def open_router(listen: str = "tcp/127.0.0.1:0") -> tuple[zenoh.Session, str]:
    """Open the coordinator's router session; return it with the endpoint clients should connect to."""
    session = zenoh.open(make_config("router", listen=[listen], extra={"adminspace/enabled": True}))
    try:
        endpoint = _bound_endpoint(session, listen)
    except Exception:
        session.close()
        raise
    return session, endpoint


def _bound_endpoint(session: zenoh.Session, listen: str) -> str:
    """Read the actual locator (port 0 becomes a real port) from the admin space."""
    for reply in session.get(f"@/{session.zid()}/*", timeout=2.0):
        if reply.ok is not None and str(reply.ok.key_expr).rsplit("/", 1)[-1] in ("router", "peer"):
            locators = json.loads(reply.ok.payload.to_bytes())["locators"]
            proto = listen.split("/", 1)[0]
            for loc in locators:
                if loc.startswith(proto + "/"):
                    return loc
            if locators:
                return locators[0]
    raise RuntimeError(f"could not read the bound locator of the router listening on {listen}")
