"""The slow-link relay of benchmarks/slow_link.py forwards bytes both ways, in order, and delays each way."""

from __future__ import annotations

import importlib.util
import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import pytest

pytestmark = [pytest.mark.slow]  # the inner loop: pytest -m "not slow"

DELAY = 0.05  # s each way: large against loopback and scheduling noise, so the property is clear-cut


def load_slow_link() -> ModuleType:
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "slow_link.py"
    spec = importlib.util.spec_from_file_location("slow_link", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


slow_link = load_slow_link()


@pytest.fixture
def echo_server() -> Iterator[tuple[str, int]]:
    """A loopback TCP server that sends back whatever it receives (one connection)."""
    server = socket.create_server(("127.0.0.1", 0))
    conns: list[socket.socket] = []

    def serve() -> None:
        try:
            conn, _ = server.accept()
        except OSError:
            return
        conns.append(conn)
        while data := conn.recv(1 << 16):
            conn.sendall(data)
        conn.close()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield server.getsockname()[:2]
    finally:
        server.close()
        for conn in conns:
            conn.close()
        thread.join(2.0)


def exchange(sock: socket.socket, payload: bytes) -> bytes:
    sock.sendall(payload)
    got = b""
    while len(got) < len(payload):
        chunk = sock.recv(1 << 16)
        if not chunk:
            break
        got += chunk
    return got


def test_the_relay_forwards_in_order_and_a_round_trip_takes_at_least_two_delays(echo_server: tuple) -> None:
    with slow_link.DelayRelay(echo_server, DELAY) as relay, socket.create_connection(("127.0.0.1", relay.port)) as s:
        payload = bytes(range(256)) * 400  # 100 KiB: several chunks each way
        start = time.monotonic()
        assert exchange(s, payload) == payload
        assert time.monotonic() - start >= 2 * DELAY
        for i in range(3):  # every round trip is delayed, not just the first
            start = time.monotonic()
            assert exchange(s, b"ping %d" % i) == b"ping %d" % i
            assert time.monotonic() - start >= 2 * DELAY


def test_the_relay_passes_the_end_of_the_stream_on(echo_server: tuple) -> None:
    with slow_link.DelayRelay(echo_server, DELAY) as relay, socket.create_connection(("127.0.0.1", relay.port)) as s:
        assert exchange(s, b"last words") == b"last words"
        s.shutdown(socket.SHUT_WR)  # the echo server sees EOF through the relay and closes: EOF comes back
        s.settimeout(5.0)
        assert s.recv(10) == b""


def test_the_relay_joins_only_loopback_addresses() -> None:
    with pytest.raises(ValueError, match="loopback"):
        slow_link.DelayRelay(("192.0.2.1", 7447), DELAY)


def test_the_router_endpoint_is_parsed() -> None:
    assert slow_link.parse_tcp_endpoint("tcp/127.0.0.1:7447") == ("127.0.0.1", 7447)
    assert slow_link.parse_tcp_endpoint("tcp/[::1]:7447") == ("::1", 7447)
    with pytest.raises(ValueError):
        slow_link.parse_tcp_endpoint("udp/127.0.0.1:7447")


def test_a_whole_run_goes_through_the_relay_and_pays_its_delay() -> None:
    """run_once as the benchmark calls it: the subsims connect through a relay process, the run completes like
    a direct one (same intervals and stages), and each round trip timed, one after another (the oscillator's two
    masses read each other), pays both delays (caught: the launch command's options changing under the relay's
    redirection). The requests counted between the first and the last interval's end are not compared: where
    an interval is recorded, and so where the count starts, depends on timing."""
    scenario = Path(__file__).resolve().parents[1] / "scenarios" / "oscillator.toml"
    direct = slow_link.run_once(scenario, "distributed", 0.5, None)
    delayed = slow_link.run_once(scenario, "distributed", 0.5, DELAY)
    assert (delayed["intervals"], delayed["stages"]) == (direct["intervals"], direct["stages"]) == (10, 4.0)
    assert delayed["requests"] > 0 and delayed["span"] > 0
    assert delayed["wall_s"] >= 2 * DELAY * delayed["requests"]
