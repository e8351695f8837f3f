"""Coordinator side of tests/test_two_hosts.py's cut measurement: ``python tests/netns_coordinator.py EP CERT KEY CA``.

Opens a TLS router on EP, prints one JSON line (environment and argv of the remote subsim ``far``),
attaches it and prints ``attached``; on ``cut`` from stdin prints ``cutting``, then waits for the
subsim's liveliness to go and prints one JSON line: ``noticed``, ``seconds`` since ``cutting``, ``how``.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from cosim.launch import Bus
from cosim.protocol.security import Security


def main() -> int:
    endpoint, cert, key, ca = sys.argv[1:5]
    with Bus.open(endpoint, security=Security(Path(cert), Path(key), Path(ca))) as bus:
        argv = [sys.executable, *bus.command("subsims.integrator", "far")[1:]]
        print(json.dumps({"env": bus.subsim_env("far"), "argv": argv}), flush=True)
        handle = bus.attach("far", wait=60.0)
        handle.configure({})
        print("attached", flush=True)
        if sys.stdin.readline().strip() != "cut":
            return 2
        print("cutting", flush=True)
        t0 = time.monotonic()
        noticed = handle._died.wait(120.0)
        seconds = time.monotonic() - t0
        print(json.dumps({"noticed": noticed, "seconds": seconds, "how": "the subsim's liveliness token went"}),
              flush=True)
        handle.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
