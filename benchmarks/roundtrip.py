"""Round trip of one ``run_interval``: the framework against bare Zenoh.

    python benchmarks/roundtrip.py [--samples 1000] [--warmup 200] [--rounds 10]

The request: an integrator subsim of size 6 (configured with y0 = zeros), interval [0, 0.4] with 5
samples, a 5x6 input segment, linear interpolation. ``run_interval`` commits nothing, so the same
request is repeated. Eight ways, interleaved in rounds so that load drifts hit all of them alike:

  (a) remote   RemoteHandle -> Zenoh -> a spawned ``python -m subsims.integrator`` (cosim.launch.Bus)
  (b) inproc   InProcessHandle: the same Runtime called directly
  (c) bare     session.get of the same request bytes -> Zenoh -> a spawned bare queryable that
               answers with a fixed payload of the real reply's size (same session settings; a
               FifoChannel read on the main thread: answering on zenoh's callback thread instead, as
               cosim's CommandServer does, measured the same, 51.4 vs 52.1 us and 163.7 vs 162.6 us)
  (d) status   RemoteHandle.status() to the same process: the framework's fixed cost per request
               (envelope, codec, dispatch) without the model's work
  (e) bare+work  as (c), but the responder first runs the subsim's own ``answer()`` on the request (decode,
               run the integrator, encode; nothing sealed) on a Runtime of its own, then sends the fixed
               reply: what that work costs on the wire, where it runs after a wait, with cold caches
  (f) bare+loop  as (e), but the work is a pure-Python loop of additions that takes, repeated in one
               process, as long as that ``answer()``: the same CPU with a small code footprint
  (g) lean     the least a sealed run_interval can cost in Python, both sides: the client seals the request and
               opens and unpacks the reply into array views; the responder checks the tag, unpacks with msgpack
               into array views, runs the same Runtime's interpolant and model.advance, packs, seals (no schema
               checks, runtime checks, handles, serving thread or replay window)
  (h) lean, no model  as (g), but the responder echoes its input as the output: seals, msgpack and zenoh only

Then the framework overhead ratio (a)/(c), split at (e): (e)/(c) is the subsim's own work in its place,
(a)/(e) the rest (client side, seals, the serving thread's bookkeeping); (f)/(c) beside (e)/(c) tells
whether that work costs by its CPU or by the code it touches (cold after every wait); (g)/(c) and (h)/(c)
are what a lean Python path with these seals, this codec and this model costs (the floor under the framework), and
(a)/(g) what the framework's plumbing costs above it; (a) once more against an
integrator process that times its own ``answer()`` (server work vs transport) and each phase of its serving path
around it (tag check, answer, seal, reply), beside the bare responder (e)'s reply after the same work; and where the
framework's time goes: the CPU time of each stage of the request path, in this process. Prints
figures; asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import msgpack
import numpy as np
import zenoh

from cosim.contract import PROTOCOL_VERSION
from cosim.handles import InProcessHandle
from cosim.launch import Bus, terminate
from cosim.protocol.keys import coordinator_alive_key
from cosim.protocol.messages import (
    ErrorInfo,
    Sealer,
    decode_reply,
    decode_request,
    encode_request,
    encode_result,
    next_seq,
    sealer,
)
from cosim.protocol.security import SECRET_ENV, ClientSecurity, parse_key
from cosim.protocol.service import answer
from cosim.protocol.transport.session import client_config
from cosim.protocol.wire import encode_array, pack
from cosim.runtime import Runtime
from cosim.signals import check_time_grid
from subsims.integrator.model import gauss_nodes
from subsims.integrator.subsim import Integrator

SIZE, N = 6, 5
F8 = np.dtype("<f8")
PARAMS = {"size": SIZE, "y0": [0.0] * SIZE}
TIMES = np.linspace(0.0, 0.4, N)
INPUTS = {"u": np.random.default_rng(2024).normal(size=(N, SIZE))}
STOP = b"stop"


# --- the bare Zenoh responder (runs in its own process) ----------------------------------------------


def bare_key(run: str, name: str = "bare") -> str:
    return f"cosim/{run}/{name}/rpc"


def integrator_runtime() -> Runtime:
    """The benchmark's subsim, in this process: an integrator Runtime configured with ``PARAMS``."""
    rt = Runtime(Integrator(), "integ")
    rt.configure(PARAMS)
    return rt


def benchmark_request() -> bytes:
    return encode_request("run_interval", {"t": TIMES, "inputs": INPUTS, "interp": "linear"})


def lean_request() -> bytes:
    """What (g) sends each call: the same msgpack body as :func:`benchmark_request`, packed straight from the arrays."""
    args = {"t": encode_array(TIMES), "inputs": {k: encode_array(v) for k, v in INPUTS.items()}, "interp": "linear"}
    return pack({"v": PROTOCOL_VERSION, "cmd": "run_interval", "args": args})


def lean_answer(runtime: Runtime, opener: Sealer, frame: bytes, model: bool) -> bytes:
    """(g)'s responder: tag check, msgpack, array views, the model (or an echo of the input), msgpack, seal."""
    seq, body = opener.open_request(frame)
    args = msgpack.unpackb(body)["args"]
    t = args["t"]
    times = np.ndarray(t["shape"], F8, t["data"])
    inputs = {k: np.ndarray(v["shape"], F8, v["data"]) for k, v in args["inputs"].items()}
    if model:
        outputs, _ = runtime.model.advance(runtime.state, times, runtime._input_function(times, inputs, "linear"))
    else:
        outputs = {"y": inputs["u"]}
    result = {"t": t, "outputs": {k: encode_array(v) for k, v in outputs.items()}, "end_time": float(times[-1])}
    return opener.seal_reply(seq, pack({"v": PROTOCOL_VERSION, "ok": True, "result": result}))


def busy_loop(n: int) -> int:
    """Pure-Python additions: CPU time with a small code footprint."""
    x = 0
    for i in range(n):
        x += i
    return x


def loop_like_answer() -> int:
    """Iterations of :func:`busy_loop` that take, repeated in one process, as long as the benchmark's ``answer()``."""
    return max(1, round(1000 * answer_cpu(benchmark_request()) / per_call(lambda: busy_loop(1000))))


def serve_bare(endpoint: str, run: str, reply_size: int, name: str = "bare", mode: str = "fixed") -> int:
    """Answer every query on the bare key with ``reply_size`` fixed bytes until told to stop. First, with mode
    ``work``, run the integrator subsim's ``answer()`` on the query's payload (an unsealed run_interval); with
    ``loop``, :func:`busy_loop` for as long as that takes warm. With ``lean`` and ``lean-no-model`` the reply is
    :func:`lean_answer`'s instead (a sealed request in, a sealed reply out)."""

    def stop(signum: int, frame: object) -> None:
        raise SystemExit(0)

    signal.signal(signal.SIGTERM, stop)
    reply = bytes(range(256)) * (reply_size // 256) + bytes(reply_size % 256)
    lean = mode in ("lean", "lean-no-model")
    runtime = integrator_runtime() if mode == "work" or lean else None
    opener = sealer(parse_key(os.environ[SECRET_ENV])) if lean else None
    checked = None
    loop = loop_like_answer() if mode == "loop" else 0
    security = ClientSecurity.from_env()  # the run's login (only the lean modes seal)
    replying: list[tuple[int, int]] = []  # per request: ns in query.reply, ns dropping the query (its final message)
    with zenoh.open(client_config(endpoint, 10.0, security=security)) as session:
        queryable = session.declare_queryable(bare_key(run, name), zenoh.handlers.FifoChannel(64))
        # exit with the coordinator, as real subsims do
        watch = session.liveliness().declare_subscriber(
            coordinator_alive_key(run),
            lambda s: os.kill(os.getpid(), signal.SIGTERM) if s.kind == zenoh.SampleKind.DELETE else None,
        )
        token = session.liveliness().declare_token(f"cosim/{run}/{name}/alive")
        try:
            while True:
                query = queryable.recv()
                with query:
                    payload = query.payload.to_bytes() if query.payload is not None else b""
                    if payload == STOP:  # answered with the medians of the replying times, in us
                        medians = [statistics.median(x) / 1e3 for x in zip(*replying)] if replying else []
                        query.reply(query.key_expr, json.dumps(medians).encode())
                        return 0
                    sent = reply  # the fixed bytes, unless a lean mode answers this request itself
                    if payload != b"ping" and lean:
                        sent = lean_answer(runtime, opener, payload, model=mode == "lean")
                    elif payload != b"ping" and runtime is not None:
                        result = answer(runtime, payload)
                        if checked is None:  # once: the work done must be the model's run, not an error reply
                            checked = decode_reply("run_interval", result)
                            if isinstance(checked, ErrorInfo):
                                raise SystemExit(f"bare responder: answer() refused the request: {checked.message}")
                    elif payload != b"ping" and loop:
                        busy_loop(loop)
                    t0 = time.perf_counter_ns()
                    query.reply(query.key_expr, sent)
                    t1 = time.perf_counter_ns()
                t2 = time.perf_counter_ns()
                if payload != b"ping":
                    replying.append((t1 - t0, t2 - t1))
        finally:
            token.undeclare()
            watch.undeclare()
            queryable.undeclare()


def serve_timed(endpoint: str, run: str, name: str) -> int:
    """The integrator subsim process, with ``answer()`` timed (wall and CPU) in the process itself, and the phases
    of its serving path around it (wall): the real code, its methods wrapped with clocks.

    Prints, per run_interval request, those times as one JSON line on stdout when it exits.
    """
    import cosim.protocol.service as service
    from cosim.process import main as serve_model
    from cosim.protocol.transport.server import CommandServer

    untimed = service.answer
    wall: list[float] = []
    cpu: list[float] = []
    phases: dict[str, list[float]] = {k: [] for k in ("callback", "admit", "serve", "gate_answer")}
    current: dict[str, float] = {}

    def timed(runtime: Runtime, payload: bytes) -> bytes:
        w0, c0 = time.perf_counter_ns(), time.thread_time_ns()
        reply = untimed(runtime, payload)
        if bytes(payload[:40]).find(b"run_interval") >= 0:
            wall.append((time.perf_counter_ns() - w0) / 1e3)
            cpu.append((time.thread_time_ns() - c0) / 1e3)
        return reply

    def clocked(phase: str, method: Callable) -> Callable:
        def wrapper(*args: object) -> object:
            t0 = time.perf_counter_ns()
            try:
                return method(*args)
            finally:
                current[phase] = (time.perf_counter_ns() - t0) / 1e3
                if phase == "callback":  # the request's end; one queued for the serving thread has no phases here
                    if current.get("cmd") == "run_interval" and phases.keys() <= current.keys():
                        for k in phases:
                            phases[k].append(current[k])
                    current.clear()

        return wrapper

    serve_one = CommandServer._answer

    def serving(self: CommandServer, query: object, key_expr: object, request: object, cmd: str | None) -> None:
        current["cmd"] = cmd or ""
        serve_one(self, query, key_expr, request, cmd)

    service.answer = timed  # Gate.answer looks the name up at each request
    service.Gate.admit = clocked("admit", service.Gate.admit)
    service.Gate.answer = clocked("gate_answer", service.Gate.answer)
    CommandServer._answer = clocked("serve", serving)
    CommandServer._on_query = clocked("callback", CommandServer._on_query)
    rc = serve_model(Integrator, ["--connect", endpoint, "--run", run, "--name", name])
    print(json.dumps({"n": len(wall), "wall": wall, "cpu": cpu, "phases": phases}), flush=True)
    return rc


def in_situ(bus: Bus, warmup: int, count: int) -> tuple[list[float], list[float], list[float], dict[str, list[float]]]:
    """(client round trips, answer() wall times, answer() CPU times, the serving phases' wall times) of run_interval,
    in microseconds."""
    name = "integ-timed"
    popen = subprocess.Popen(
        [sys.executable, str(Path(__file__).resolve()), "--timed-subsim", bus.endpoint, bus.run, name],
        env={**os.environ, **bus.subsim_env(name)},
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        handle = bus.attach(name, wait=20.0)
        handle.configure(PARAMS)
        call = lambda: handle.run_interval(TIMES, INPUTS)  # noqa: E731
        sample(call, warmup)
        rtt = sample(call, count)
        handle.shutdown()
        handle.close()
        out, _ = popen.communicate(timeout=10.0)
    finally:
        if popen.poll() is None:
            popen.kill()
            popen.wait()
    stats = json.loads(out.strip().splitlines()[-1])
    return rtt, stats["wall"][warmup:], stats["cpu"][warmup:], {k: v[warmup:] for k, v in stats["phases"].items()}


class BareClient:
    """The coordinator half of (c): exactly what RemoteHandle does, minus encoding and decoding."""

    def __init__(self, bus: Bus, reply_size: int, mode: str = "fixed") -> None:
        name = "bare" if mode == "fixed" else f"bare-{mode}"
        self.session, self.key = bus.session, bare_key(bus.run, name)
        self.popen = subprocess.Popen(
            [sys.executable, str(Path(__file__).resolve()), "--bare-server", bus.endpoint, bus.run, str(reply_size),
             name, mode],
            env={**os.environ, **bus.subsim_env(name)},
        )
        deadline = time.monotonic() + 20.0
        while not self._answers(b"ping"):  # declarations propagate asynchronously
            if self.popen.poll() is not None or time.monotonic() > deadline:
                self.close()
                raise RuntimeError("the bare responder did not come up")
            time.sleep(0.02)

    def _answers(self, payload: bytes) -> bool:
        replies = self.session.get(self.key, payload=payload, timeout=1.0)
        return any(r.ok is not None for r in replies)

    def call_lean(self, key: bytes) -> dict[str, np.ndarray]:
        """(g)'s client: seal a freshly packed request, open the reply, unpack its outputs into array views."""
        seq, opener = next_seq(), sealer(key)
        for reply in self.session.get(self.key, payload=opener.seal_request(seq, lean_request()), timeout=10.0,
                                      consolidation=zenoh.ConsolidationMode.NONE):
            result = msgpack.unpackb(opener.open_reply(seq, reply.ok.payload.to_bytes()))["result"]
            return {k: np.ndarray(v["shape"], F8, v["data"]) for k, v in result["outputs"].items()}
        raise RuntimeError("no reply from the lean responder")

    def call(self, payload: bytes) -> bytes:
        for reply in self.session.get(
            self.key, payload=payload, timeout=10.0, consolidation=zenoh.ConsolidationMode.NONE
        ):
            return reply.ok.payload.to_bytes()
        raise RuntimeError("no reply from the bare responder")

    def close(self) -> list[float]:
        """Stop the responder; its medians (us) of the time in ``query.reply`` and in dropping the query."""
        medians: list[float] = []
        try:
            if self.popen.poll() is None:
                for r in self.session.get(self.key, payload=STOP, timeout=1.0):
                    if r.ok is not None:
                        medians = json.loads(r.ok.payload.to_bytes())
            self.popen.wait(3.0)
        except Exception:
            terminate(self.popen)
        return medians


# --- measurement ---------------------------------------------------------------------------------------


def sample(fn: Callable[[], object], count: int) -> list[float]:
    """Wall time of each of ``count`` calls, in microseconds."""
    out = []
    for _ in range(count):
        t0 = time.perf_counter_ns()
        fn()
        out.append((time.perf_counter_ns() - t0) / 1e3)
    return out


def per_call(fn: Callable[[], object], batch: int = 200, batches: int = 15) -> float:
    """Median over batches of the mean CPU time per call, in microseconds.

    CPU time of this thread, not wall time: other processes competing for the cores do not
    inflate it, so the stages add up even on a loaded machine.
    """
    times = []
    for _ in range(batches):
        t0 = time.thread_time_ns()
        for _ in range(batch):
            fn()
        times.append((time.thread_time_ns() - t0) / batch / 1e3)
    return statistics.median(times)


def answer_cpu(request: bytes) -> float:
    """CPU time of the subsim's ``answer()`` on ``request``, repeated in this process (warm caches), in us."""
    rt = integrator_runtime()
    return per_call(lambda: answer(rt, request))


def pct(xs: list[float], q: float) -> float:
    return float(np.percentile(xs, q))


def breakdown(request: bytes, reply: bytes) -> list[tuple[str, float]]:
    """Each stage of the framework's request path, timed in this process (microseconds per call)."""
    rt = integrator_runtime()
    args = decode_request(request).args
    times, inputs = args["t"], args["inputs"]
    u = rt._input_function(times, inputs, "linear")
    calls = [0]

    def counting(t: float) -> dict:
        calls[0] += 1
        return u(t)

    outputs, end_state = rt.model.advance(rt.state, times, counting)
    result = rt.run_interval(times, inputs)
    return [
        (
            "client  encode_request",
            per_call(lambda: encode_request("run_interval", {"t": TIMES, "inputs": INPUTS, "interp": "linear"})),
        ),
        ("subsim  decode_request (msgpack + schema check)", per_call(lambda: decode_request(request))),
        ("subsim  check_time_grid(t)", per_call(lambda: check_time_grid(times, "t"))),
        (
            "subsim  Runtime._input_function (checks, Segment, interpolant)",
            per_call(lambda: rt._input_function(times, inputs, "linear")),
        ),
        ("subsim  model.advance total (integrate_once)", per_call(lambda: rt.model.advance(rt.state, times, u))),
        ("          of which gauss_nodes(5): numpy leggauss, per call", per_call(lambda: gauss_nodes(times.size))),
        (f"          of which {calls[0]} input evaluations u(t)", calls[0] * per_call(lambda: u(0.13))),
        (
            "subsim  Runtime._check_outputs + _check_state",
            per_call(lambda: (rt._check_outputs(outputs, times), rt._check_state(end_state, SIZE, "returned"))),
        ),
        ("subsim  Runtime.run_interval total", per_call(lambda: rt.run_interval(times, inputs))),
        ("subsim  encode_result", per_call(lambda: encode_result(result))),
        ("subsim  answer() total (decode + run + encode)", per_call(lambda: answer(rt, request))),
        ("client  decode_reply", per_call(lambda: decode_reply("run_interval", reply))),
    ]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--samples", type=int, default=1000, help="timed calls per way (>= 500)")
    p.add_argument("--warmup", type=int, default=200, help="untimed calls per way first")
    p.add_argument("--rounds", type=int, default=10, help="interleaved rounds the samples are split into")
    p.add_argument("--bare-server", nargs=5, metavar=("ENDPOINT", "RUN", "REPLY_SIZE", "NAME", "MODE"),
                   help=argparse.SUPPRESS)
    p.add_argument("--timed-subsim", nargs=3, metavar=("ENDPOINT", "RUN", "NAME"), help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.bare_server:
        endpoint, run, size, name, mode = a.bare_server
        return serve_bare(endpoint, run, int(size), name, mode)
    if a.timed_subsim:
        return serve_timed(*a.timed_subsim)

    request = benchmark_request()
    reply = answer(integrator_runtime(), request)

    with Bus.open() as bus:
        remote = bus.spawn("subsims.integrator", "integ", quiet=True).handle
        remote.configure(PARAMS)
        inproc = InProcessHandle(Integrator(), "integ")
        inproc.configure(PARAMS)
        bare = BareClient(bus, len(reply))
        bare_work = bare_loop = lean = lean_echo = None
        bare_replying: list[float] = []
        try:
            bare_work = BareClient(bus, len(reply), mode="work")
            bare_loop = BareClient(bus, len(reply), mode="loop")
            lean = BareClient(bus, len(reply), mode="lean")
            lean_echo = BareClient(bus, len(reply), mode="lean-no-model")
            lean_key, echo_key = bus.key("bare-lean"), bus.key("bare-lean-no-model")
            # the ways must agree before their times mean anything
            r_remote, r_inproc = remote.run_interval(TIMES, INPUTS), inproc.run_interval(TIMES, INPUTS)
            assert r_remote.outputs["y"].tobytes() == r_inproc.outputs["y"].tobytes()
            assert len(bare.call(request)) == len(bare_work.call(request)) == len(bare_loop.call(request)) == len(reply)
            assert lean.call_lean(lean_key)["y"].tobytes() == r_remote.outputs["y"].tobytes()
            assert lean_echo.call_lean(echo_key)["y"].tobytes() == INPUTS["u"].tobytes()
            ways: dict[str, Callable[[], object]] = {
                "(a) remote handle, spawned process": lambda: remote.run_interval(TIMES, INPUTS),
                "(b) in-process handle": lambda: inproc.run_interval(TIMES, INPUTS),
                "(c) bare zenoh get/reply, same bytes": lambda: bare.call(request),
                "(d) remote handle, status (no model work)": remote.status,
                "(e) bare, responder runs answer() first": lambda: bare_work.call(request),
                "(f) bare, responder loops as long first": lambda: bare_loop.call(request),
                "(g) lean: seals, msgpack, the same model": lambda: lean.call_lean(lean_key),
                "(h) lean, no model (echo)": lambda: lean_echo.call_lean(echo_key),
            }
            for fn in ways.values():
                sample(fn, a.warmup)
            samples: dict[str, list[float]] = {name: [] for name in ways}
            for r in range(a.rounds):  # --samples split over the rounds, the first ones taking the remainder
                count = a.samples // a.rounds + (r < a.samples % a.rounds)
                for name, fn in ways.items():
                    samples[name] += sample(fn, count)
        finally:
            bare.close()
            if bare_work is not None:
                bare_replying = bare_work.close()
            for client in (bare_loop, lean, lean_echo):
                if client is not None:
                    client.close()
        rtt, srv_wall, srv_cpu, phases = in_situ(bus, a.warmup, a.samples)

    load = os.getloadavg()
    print(f"run_interval round trip: integrator size {SIZE}, {N} samples over [0, 0.4], input segment {N}x{SIZE}")
    print(
        f"request {len(request)} B, reply {len(reply)} B; {a.warmup} warm-up + {a.samples} timed calls "
        f"per way in {a.rounds} interleaved rounds; load average {load[0]:.2f} on {os.cpu_count()} CPUs"
    )
    print()
    print(f"| {'way':<42} | median (us) | p90 (us) | samples |")
    print(f"|{'-' * 44}|-------------|----------|---------|")
    for name, xs in samples.items():
        print(f"| {name:<42} | {pct(xs, 50):11.1f} | {pct(xs, 90):8.1f} | {len(xs):7d} |")
    ra, _, rc, _, re, rf, rg, rh = samples.values()
    med = pct(ra, 50) / pct(rc, 50)
    print()
    print(
        f"framework overhead (a)/(c): median {med:.2f}x, p90 {pct(ra, 90) / pct(rc, 90):.2f}x "
        f"(target <= 1.50x: {'met' if med <= 1.5 else 'NOT met'})"
    )
    print(f"framework time per call, median (a) - (c): {pct(ra, 50) - pct(rc, 50):.1f} us")
    stages = breakdown(request, reply)
    us = [x for _, x in stages]
    print(
        f"  of which the subsim's answer() where it runs, (e)/(c): {pct(re, 50) / pct(rc, 50):.2f}x "
        f"(+{pct(re, 50) - pct(rc, 50):.1f} us, for {us[10]:.1f} us of CPU when repeated in one process); "
        f"the rest, (a)/(e): {pct(ra, 50) / pct(re, 50):.2f}x"
    )
    print(
        f"  the same warm CPU in a pure-Python loop (small code footprint), (f)/(c): {pct(rf, 50) / pct(rc, 50):.2f}x "
        f"(+{pct(rf, 50) - pct(rc, 50):.1f} us, against +{pct(re, 50) - pct(rc, 50):.1f} us for answer())"
    )
    print(
        f"  a lean Python path with these seals, msgpack and this model (g)/(c): "
        f"{pct(rg, 50) / pct(rc, 50):.2f}x (+{pct(rg, 50) - pct(rc, 50):.1f} us); without the model, (h)/(c): "
        f"{pct(rh, 50) / pct(rc, 50):.2f}x (+{pct(rh, 50) - pct(rc, 50):.1f} us); the framework's plumbing above "
        f"that path (schema and runtime checks, handles, serving thread, replay window), (a)/(g): "
        f"{pct(ra, 50) / pct(rg, 50):.2f}x (+{pct(ra, 50) - pct(rg, 50):.1f} us)"
    )
    print()
    print("(a) again, against an integrator process that times answer() itself (medians, us):")
    print(
        f"  round trip at the client {pct(rtt, 50):.1f}; inside the subsim: answer() wall {pct(srv_wall, 50):.1f}, "
        f"CPU {pct(srv_cpu, 50):.1f}; so transport + client side {pct(rtt, 50) - pct(srv_wall, 50):.1f} "
        f"(bare zenoh (c): {pct(rc, 50):.1f})"
    )
    med = {k: pct(v, 50) for k, v in phases.items()}
    print(
        f"  the subsim's serving path, wall, medians: the whole callback {med['callback']:.1f} = entry, key check, "
        f"command peek and lock {med['callback'] - med['admit'] - med['serve']:.1f} + tag and replay checks (admit) "
        f"{med['admit']:.1f} + answer() {pct(srv_wall, 50):.1f} + reply seal "
        f"{med['gate_answer'] - pct(srv_wall, 50):.1f} + query.reply and dropping the query "
        f"{med['serve'] - med['gate_answer']:.1f}"
    )
    if bare_replying:
        print(
            f"  the bare responder (e), after the same answer(): query.reply {bare_replying[0]:.1f}, dropping the "
            f"query {bare_replying[1]:.1f} (the reply is on its way during both; the drop sends the final message)"
        )
    print()
    print("where the framework's time goes (CPU time per call in this process, median of batch means):")
    print(f"| {'stage':<64} | us/call |")
    print(f"|{'-' * 66}|---------|")
    for name, x in stages:
        print(f"| {name:<64} | {x:7.1f} |")
    codec = us[0] + us[1] + us[9] + us[11]
    runtime = us[8] - us[4]  # run_interval minus the model's advance: validation, interpolant set-up, checks
    evaluations = us[6]
    model = us[4] - evaluations
    framework = codec + runtime + evaluations
    print()
    share = 100 * framework / pct(rc, 50)
    print(
        f"framework work per request: codec {codec:.1f} + runtime checks and set-up {runtime:.1f} + input "
        f"evaluations {evaluations:.1f} = {framework:.1f} us = {share:.0f}% of bare zenoh (c)"
    )
    print(f"the integrator's own arithmetic: {model:.1f} us, of which recomputing its Gauss nodes {us[5]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
