"""The paper's runs over a slow link: every subsim reaches the coordinator through a relay that delays each way.

    python benchmarks/slow_link.py                        # case 1, RF-D and RF-C, 200 s, 0.5 ms each way
    python benchmarks/slow_link.py --delay-ms 2 --stop 100
    python benchmarks/slow_link.py --delay-ms 0.5 1 2     # several delays
    python benchmarks/slow_link.py --repeat 3             # median of 3 interleaved runs per link
    python benchmarks/slow_link.py relay --target tcp/127.0.0.1:7447 --delay-ms 0.5   # only the relay

The relay (:class:`DelayRelay`) is a TCP forwarder on 127.0.0.1: each connection a subsim opens to it is
forwarded to the coordinator's router, and every chunk of bytes, in either direction, is passed on
``delay`` seconds after it arrived (in order; the delay is a latency, not a bandwidth limit), so one
request/reply round trip gains at least two delays. It runs in a process of its own, so its threads do not
compete with the coordinator for the GIL. The coordinator's own connection to its router stays direct.

For each run (without the relay, through the relay with no delay, then with each delay) it prints the
wall time of the coupling (from the end of the first interval to the end of the last: start-up excluded),
the requests (each one a round trip) per simulated second, the stages per interval, and the wall time the
delay added per request (also in delays) and per simulated second, relative to the relay with no delay
(which isolates the delay from the relay's own cost, an extra Python hop).
RF-D waits for its round trips one after another, so it pays about two delays per request; RF-C sends the
requests of a stage together, so a stage pays about two delays whatever the number of subsims.
``scenarios/satellite/case1-auto.toml`` (automatic interval control), when present, is run too, with each
method, to ``--auto-stop``.
"""

from __future__ import annotations

import argparse
import contextlib
import queue
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

LOOPBACK = ("127.0.0.1", "localhost", "::1", "[::1]")


# --- the relay -------------------------------------------------------------------------------------------


class DelayRelay:
    """Forwards TCP connections from ``127.0.0.1:<port>`` to ``target``, delaying every chunk ``delay`` s each way.

    Per direction a reader thread stamps each chunk with its due time and a writer thread sends it then, so
    chunks keep their order and overlap (a fixed latency, not a bandwidth limit). ``close`` stops everything.
    """

    def __init__(self, target: tuple[str, int], delay: float, host: str = "127.0.0.1") -> None:
        if target[0] not in LOOPBACK or host not in LOOPBACK:
            raise ValueError(f"the relay only joins loopback addresses, not {host} -> {target[0]}")
        if delay < 0:
            raise ValueError(f"delay must be >= 0, got {delay}")
        self.target, self.delay = target, delay
        self._listener = socket.create_server((host, 0))
        self.port: int = self._listener.getsockname()[1]
        self._sockets: list[socket.socket] = []
        self._lock = threading.Lock()
        self._closed = False
        self._acceptor = threading.Thread(target=self._accept, name="relay-accept", daemon=True)

    @property
    def endpoint(self) -> str:
        """The Zenoh endpoint of the relay, to give the subsims instead of the router's."""
        return f"tcp/127.0.0.1:{self.port}"

    def start(self) -> DelayRelay:
        self._acceptor.start()
        return self

    def _accept(self) -> None:
        while not self._closed:
            try:
                downstream, _ = self._listener.accept()
            except OSError:
                return  # closed
            try:
                upstream = socket.create_connection(self.target, timeout=5.0)
            except OSError:
                downstream.close()
                continue
            upstream.settimeout(None)
            for s in (downstream, upstream):
                s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                self._sockets += [downstream, upstream]
            self._pipe(downstream, upstream, "up")
            self._pipe(upstream, downstream, "down")

    def _pipe(self, src: socket.socket, dst: socket.socket, name: str) -> None:
        chunks: queue.SimpleQueue[tuple[float, bytes]] = queue.SimpleQueue()

        def read() -> None:
            while True:
                try:
                    data = src.recv(1 << 16)
                except OSError:
                    data = b""
                chunks.put((time.monotonic() + self.delay, data))
                if not data:
                    return

        def write() -> None:
            while True:
                due, data = chunks.get()
                wait = due - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
                try:
                    if not data:
                        dst.shutdown(socket.SHUT_WR)
                        return
                    dst.sendall(data)
                except OSError:
                    return

        threading.Thread(target=read, name=f"relay-{name}-read", daemon=True).start()
        threading.Thread(target=write, name=f"relay-{name}-write", daemon=True).start()

    def close(self) -> None:
        self._closed = True
        with contextlib.suppress(OSError):
            self._listener.shutdown(socket.SHUT_RDWR)  # wakes the blocked accept() (close alone does not)
        self._listener.close()
        with self._lock:
            sockets, self._sockets = self._sockets, []
        for s in sockets:
            with contextlib.suppress(OSError):
                s.shutdown(socket.SHUT_RDWR)
            s.close()
        self._acceptor.join(2.0)

    def __enter__(self) -> DelayRelay:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()


def parse_tcp_endpoint(endpoint: str) -> tuple[str, int]:
    """``tcp/127.0.0.1:7447`` -> ("127.0.0.1", 7447)."""
    proto, _, address = endpoint.partition("/")
    host, _, port = address.rpartition(":")
    if proto != "tcp" or not host or not port.isdigit():
        raise ValueError(f"not a tcp endpoint: {endpoint!r}")
    return host.strip("[]"), int(port)


class RelayProcess:
    """A :class:`DelayRelay` in a child process (``slow_link.py relay``); ``stop`` always reaps it."""

    def __init__(self, target: str, delay: float) -> None:
        self.popen = subprocess.Popen(
            [sys.executable, str(Path(__file__).resolve()), "relay", "--target", target, "--delay-ms",
             repr(delay * 1e3)],
            stdout=subprocess.PIPE, text=True,
        )
        try:
            line = self.popen.stdout.readline()  # type: ignore[union-attr]
            if not line.startswith("RELAY "):
                raise RuntimeError(f"the relay did not start (said {line!r})")
            self.endpoint = line.split()[1]
        except BaseException:
            self.stop()
            raise

    def stop(self) -> None:
        from cosim.launch import terminate  # the relay process itself imports nothing of cosim

        terminate(self.popen)
        if self.popen.stdout is not None:
            self.popen.stdout.close()


def serve_relay(target: str, delay: float) -> int:
    """``slow_link.py relay``: run a relay until SIGTERM; its endpoint is the first line on stdout."""
    import signal

    def stop(signum: int, frame: object) -> None:
        raise SystemExit(0)

    signal.signal(signal.SIGTERM, stop)
    with DelayRelay(parse_tcp_endpoint(target), delay) as relay:
        print(f"RELAY {relay.endpoint}", flush=True)
        threading.Event().wait()
    return 0


# --- the benchmark ---------------------------------------------------------------------------------------


@contextlib.contextmanager
def subsims_through_relay(delay: float) -> Iterator[dict[str, RelayProcess]]:
    """While active, subsims launched by ``cosim.launch`` connect to a relay (started on first use, one per
    router endpoint) instead of the router; the coordinator's own sessions still connect directly."""
    import cosim.launch as launch

    relays: dict[str, RelayProcess] = {}
    original = launch.subsim_command

    def redirected(module: str, endpoint: str, run: str, name: str, model: str | None = None,
                   **options: Any) -> list[str]:
        if endpoint not in relays:
            relays[endpoint] = RelayProcess(endpoint, delay)
        return original(module, relays[endpoint].endpoint, run, name, model, **options)

    launch.subsim_command = redirected  # Bus.spawn looks the name up at each call
    try:
        yield relays
    finally:
        launch.subsim_command = original
        for relay in relays.values():
            relay.stop()


def run_once(scenario_path: Path, method: str | None, stop: float, delay: float | None) -> dict:
    """One run over Zenoh, directly (``delay`` None) or through the relay. Timed from the end of the first
    interval to the end of the last (start-up excluded): wall seconds, requests and simulated seconds."""
    from cosim.coupler.relaxation import Interval
    from cosim.protocol.transport.client import RemoteHandle
    from cosim.runner import run_scenario
    from cosim.scenario import load

    scenario = load(scenario_path)
    count = [0]
    marks: list[tuple[float, int, float]] = []  # (wall, requests, t) at the end of the first and last interval
    original = RemoteHandle._begin

    def counted(handle: RemoteHandle, cmd: str, args: dict) -> object:
        count[0] += 1
        return original(handle, cmd, args)

    def on_interval(interval: Interval) -> None:
        mark = (time.perf_counter(), count[0], float(interval.t[-1]))
        marks[1:] = [mark] if marks else []
        if not marks:
            marks.append(mark)

    relay = subsims_through_relay(delay) if delay is not None else contextlib.nullcontext()
    RemoteHandle._begin = counted  # type: ignore[method-assign]
    try:
        with relay, tempfile.TemporaryDirectory() as tmp:
            report = run_scenario(scenario, method=method, stop=stop, output=Path(tmp) / "run.csv",
                                  listen="tcp/127.0.0.1:0",  # what a link between machines is, and what the relay takes
                                  progress=False, log=lambda m: None, on_interval=on_interval)
    finally:
        RemoteHandle._begin = original  # type: ignore[method-assign]
    (w0, n0, t0), (w1, n1, t1) = marks[0], marks[-1]
    s = report.summary
    return {"method": report.method, "wall_s": w1 - w0, "requests": n1 - n0, "span": t1 - t0,
            "intervals": s.intervals, "stages": sum(k * v for k, v in s.stages.items()) / max(s.intervals, 1)}


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["relay"]:
        r = argparse.ArgumentParser(prog="slow_link.py relay")
        r.add_argument("--target", required=True, help="the router's endpoint, tcp/127.0.0.1:<port>")
        r.add_argument("--delay-ms", type=float, default=0.5)
        a = r.parse_args(argv[1:])
        return serve_relay(a.target, a.delay_ms / 1e3)
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--delay-ms", type=float, nargs="+", default=[0.5], help="delay each way, ms")
    p.add_argument("--stop", type=float, default=200.0, help="problem time of each run, s")
    p.add_argument("--auto-stop", type=float, default=2000.0,
                   help="problem time of the case1-auto.toml runs, s (its intervals grow to about 11 s)")
    p.add_argument("--methods", nargs="+", default=["distributed", "centralized"])
    p.add_argument("--repeat", type=int, default=1, help="runs per link, interleaved; the median wall time counts")
    args = p.parse_args(argv)
    runs = [(ROOT / "scenarios" / "satellite" / "case1.toml", m, args.stop) for m in args.methods]
    auto = ROOT / "scenarios" / "satellite" / "case1-auto.toml"
    if auto.exists():
        runs += [(auto, m, args.auto_stop) for m in args.methods]
    else:
        print(f"({auto.relative_to(ROOT)} does not exist: not run)")
    print(f"problem time {args.stop:g} s per run ({args.auto_stop:g} s with automatic intervals); links: direct, "
          "relay with delays each way of " + ", ".join(f"{d:g} ms" for d in [0.0, *args.delay_ms]))
    print(f"{'scenario':14s} {'method':12s} {'link':>9s} {'wall s':>8s} {'requests':>9s} {'req/sim s':>10s} "
          f"{'stages':>7s} {'added wall per request':>23s} {'added wall per sim s':>21s}")
    links = [None, 0.0, *[d / 1e3 for d in args.delay_ms if d > 0]]
    for path, method, stop in runs:
        results: dict[float | None, list[dict]] = {link: [] for link in links}
        for _ in range(args.repeat):  # interleaved, so that load drifts hit every link alike
            for link in links:
                results[link].append(run_once(path, method, stop, link))
        reference = None
        for delay in links:
            r = sorted(results[delay], key=lambda x: x["wall_s"])[len(results[delay]) // 2]  # the median run
            link = "direct" if delay is None else f"{delay * 1e3:g} ms"
            line = (f"{path.stem:14s} {r['method']:12s} {link:>9s} {r['wall_s']:8.1f} {r['requests']:9d} "
                    f"{r['requests'] / r['span']:10.1f} {r['stages']:7.2f}")
            if delay == 0.0:
                reference = r  # the relay's own cost, without delay: the figures below are relative to it
            elif delay is not None and reference is not None:
                added = r["wall_s"] - reference["wall_s"]
                line += (f" {added / r['requests'] * 1e3:11.2f} ms ({added / r['requests'] / delay:4.1f} delays)"
                         f" {added / r['span'] * 1e3:13.1f} ms/sim s")
            print(line, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
