"""What one RF-D stage of three subsims costs on the bus alone: three round trips, or one chain of puts.

    python benchmarks/stage_chain.py [--calls 300] [--rounds 10] [--payload 400]

Bare Zenoh, no cosim codec or model, with cosim's session settings (the coordinator's session is the
router; three client processes). Two ways, interleaved in rounds:

  (a) round trips   the coordinator queries A, then B, then C (what the distributed coupler does today:
                    each subsim's inputs are computed by the coordinator from the previous one's outputs)
  (b) chain         the coordinator puts to A, A puts to B, B puts to C, C puts back to the coordinator
                    (what subsim-to-subsim segments would do: every hop between subsims passes the
                    router inside the coordinator's process, but no Python there)

Prints the median per stage of each and their ratio: the most a stage could gain from sending segments
from subsim to subsim, before any of the work that design needs (each subsim evaluating the couplings
into the next one, carrying the stage's outputs along, sealing every hop). Asserts nothing.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from pathlib import Path

import zenoh

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cosim.protocol.transport.session import client_config, open_router  # noqa: E402

CHAIN = (("A", "B"), ("B", "C"), ("C", "coordinator"))


def serve(endpoint: str, name: str, successor: str, payload_size: int) -> None:
    """A subsim stand-in: answers queries with ``payload_size`` bytes and forwards every put to ``successor``."""
    reply = b"x" * payload_size
    with zenoh.open(client_config(endpoint, 10.0)) as session:
        session.declare_queryable(f"stage/{name}/rpc", lambda q: q.reply(q.key_expr, reply))
        inbox = session.declare_subscriber(f"stage/{name}/in", zenoh.handlers.FifoChannel(64))
        onward = session.declare_publisher(f"stage/{successor}/in")
        while True:
            onward.put(inbox.recv().payload.to_bytes())


def _wait_until_up(queriers: list, first: zenoh.Publisher, inbox: zenoh.Subscriber, payload: bytes) -> None:
    """Declarations propagate asynchronously: wait until every stand-in answers and a put comes round."""
    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline:
        answered = sum(1 for q in queriers for r in q.get(payload=payload) if r.ok is not None)
        if answered == len(queriers):
            first.put(payload)
            until = time.monotonic() + 0.5
            while time.monotonic() < until:
                if inbox.try_recv() is not None:
                    time.sleep(0.2)  # earlier puts still on their way come round too; drop them
                    while inbox.try_recv() is not None:
                        pass
                    return
                time.sleep(0.005)
        time.sleep(0.05)
    raise RuntimeError("the stand-in subsims did not come up within 20 s")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--calls", type=int, default=300, help="stages per round and way")
    p.add_argument("--rounds", type=int, default=10)
    p.add_argument("--payload", type=int, default=400, help="bytes per message (a satellite request: ~400)")
    p.add_argument("--serve", nargs=3, metavar=("ENDPOINT", "NAME", "SUCCESSOR"), help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.serve:
        serve(*a.serve, a.payload)
        return 0
    session, endpoint = open_router()
    procs = [subprocess.Popen([sys.executable, __file__, "--serve", endpoint, name, successor,
                               "--payload", str(a.payload)]) for name, successor in CHAIN]
    try:
        payload = b"x" * a.payload
        inbox = session.declare_subscriber("stage/coordinator/in", zenoh.handlers.FifoChannel(64))
        first = session.declare_publisher("stage/A/in")
        queriers = [session.declare_querier(f"stage/{name}/rpc", timeout=4.0) for name, _ in CHAIN]

        def round_trips() -> None:
            for querier in queriers:
                for reply in querier.get(payload=payload):
                    reply.ok.payload.to_bytes()

        def chain() -> None:
            first.put(payload)
            inbox.recv()

        ways = {"(a) 3 round trips": round_trips, "(b) chain of puts": chain}
        _wait_until_up(queriers, first, inbox, payload)
        for way in ways.values():  # warm-up
            for _ in range(100):
                way()
        times: dict[str, list[float]] = {name: [] for name in ways}
        for _ in range(a.rounds):
            for name, way in ways.items():
                start = time.perf_counter()
                for _ in range(a.calls):
                    way()
                times[name].append((time.perf_counter() - start) / a.calls * 1e6)
        print(f"one stage of 3 subsims on the bus alone, {a.payload} B messages, {a.rounds} rounds x {a.calls}:")
        for name, values in times.items():
            print(f"  {name}: median {statistics.median(values):6.0f} us per stage "
                  f"(round means {min(values):.0f}-{max(values):.0f})")
        ratio = statistics.median(times["(b) chain of puts"]) / statistics.median(times["(a) 3 round trips"])
        print(f"  chain / round trips: {ratio:.2f}")
    finally:
        for proc in procs:
            proc.kill()
            proc.wait()
        session.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
