"""A hostile Zenoh client for tests/test_security.py: ``python tests/attacker.py ENDPOINT RUN [USER:PASSWORD]``.

Hammers ``cosim/**`` and the run's exact rpc keys with ``shutdown`` and ``run_interval`` requests (bare,
and sealed with a key that is not the run's), scans for the run's keys, and offers a queryable on
``cosim/**`` to intercept the coordinator's requests. Prints ``ready`` after its first round, then,
on SIGTERM, one JSON line of counts: ``sent``, ``replies`` (answers it got), ``found`` (keys its scans
found), ``intercepted`` (queries that reached its queryable), ``connected`` (False: the router
refused it, which is the end of the attack).
"""

from __future__ import annotations

import json
import signal
import sys

import numpy as np
import zenoh

from cosim.protocol.messages import encode_request, seal_request
from cosim.protocol.security import ClientSecurity, parse_login
from cosim.protocol.transport.session import client_config

counts = {"sent": 0, "replies": 0, "found": 0, "intercepted": 0, "connected": False, "rounds": 0}
stop = False


def _stop(*_: object) -> None:
    global stop
    stop = True


def payloads() -> list[bytes]:
    t = np.array([0.0, 0.05, 0.1, 0.15, 0.2])
    trial = encode_request("run_interval", {"t": t, "inputs": {"F": np.full((5, 1), 1e3)}, "interp": "linear"})
    commit = encode_request("run_interval", {"t": t, "inputs": {"F": np.ones((5, 1))}, "commit": True})
    bare = [encode_request("shutdown"), trial, commit, encode_request("commit"), encode_request("rollback")]
    wrong_key = bytes(32)
    return bare + [seal_request(wrong_key, 2**62 + i, p) for i, p in enumerate(bare)]


def main() -> int:
    endpoint, run = sys.argv[1], sys.argv[2]
    login = parse_login(sys.argv[3], "login") if len(sys.argv) > 3 else None
    signal.signal(signal.SIGTERM, _stop)
    security = ClientSecurity(bytes(32), login)
    try:
        session = zenoh.open(client_config(endpoint, 2.0, security=security))
    except zenoh.ZError:
        print("ready", flush=True)
        signal.sigwait([signal.SIGTERM])
        print(json.dumps(counts), flush=True)
        return 0
    counts["connected"] = True

    def intercept(query: zenoh.Query) -> None:
        counts["intercepted"] += 1

    spy = zenoh.open(client_config(endpoint, 2.0, security=security))  # apart: our own gets do not reach it
    trap = spy.declare_queryable("cosim/**", intercept)
    keys = ["cosim/**", f"cosim/{run}/**", f"cosim/{run}/mass1/rpc", f"cosim/{run}/mass2/rpc", f"cosim/{run}/*/rpc"]
    bodies = payloads()
    try:
        while not stop:
            for key in keys:
                for body in bodies:
                    for reply in session.get(key, payload=body, timeout=0.2):
                        counts["replies"] += reply.ok is not None
                    counts["sent"] += 1
                counts["found"] += sum(r.ok is not None for r in session.liveliness().get(key, timeout=0.2))
            own = f"@/{session.zid()}/"  # a session always answers for itself under @/<its zid>
            counts["found"] += sum(r.ok is not None and not str(r.ok.key_expr).startswith(own)
                                   for r in session.get("@/**", timeout=0.2))
            counts["rounds"] += 1
            if counts["rounds"] == 1:
                print("ready", flush=True)
    finally:
        trap.undeclare()
        spy.close()
        session.close()
    print(json.dumps(counts), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
