"""Malformed and hostile requests against every shipped subsim, over Zenoh: none may crash it or change it.

    python benchmarks/flood.py [--count 100000] [--window 256] [--only integrator oscillator] [--json]

Each shipped subsim is launched as its own process (cosim.launch.Bus), configured with the parameters
of the first scenario that uses it, and run one interval and committed. Then ``--count`` requests are
sent with up to ``--window`` in flight at once (so the queue overflows and ``busy`` is exercised too),
drawn from: random bytes; well-formed requests sealed with a wrong key; replays of an answered request;
sealed random bytes; sealed msgpack junk; sealed requests with wrong versions, unknown commands and
fields, hostile arrays (lying shapes, huge claimed sizes, NaN, wrong widths), wrong start times,
impossible rollbacks and bad states; an occasional request over the size cap; sealed requests on
wildcard keys. None of them is a legitimate state change (a well-formed
trial may slip through the random input mix; a trial changes nothing committed).

After the flood: the process must still run and hold its liveliness token (else a *crash*), and its
committed time and state must be bit-identical to before (else a *state change*). Prints, per subsim,
the requests sent, what came back (by error code; ``dropped`` = no reply, as designed for unauthenticated,
replayed and wildcard requests) and the two counts; ``--json`` prints one JSON line per subsim instead.
Exit code 1 if any subsim crashed or changed.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import re
import sys
import tempfile
import time
import tomllib
from collections import Counter, deque
from pathlib import Path

import msgpack
import numpy as np

from cosim.launch import Bus
from cosim.protocol.keys import rpc_key
from cosim.protocol.messages import decode_reply, encode_request, next_seq, open_reply, seal_request
from cosim.protocol.service import default_request_cap
from cosim.scenario import load

ROOT = Path(__file__).resolve().parents[1]
EXTRA = {"subsims.integrator.subsim:Integrator": {}, "subsims.double_integrator.subsim:DoubleIntegrator": {}}


def shipped() -> dict[str, dict]:
    """model -> params of the first scenario that uses it (plus the two test subsims)."""
    found: dict[str, dict] = {}
    for path in sorted(ROOT.glob("scenarios/**/*.toml")):
        try:
            scenario = load(path)
        except Exception:  # e.g. an FMU scenario whose FMU is not built yet (with_fmu_built builds it)
            found.update({m: p for m, p in _fmu_shorthands(path).items() if m not in found})
            continue
        for spec in scenario.subsims.values():
            if spec.model and spec.model not in found:
                found[spec.model] = dict(spec.params)
    return {**found, **{m: p for m, p in EXTRA.items() if m not in found}}


def _fmu_shorthands(path: Path) -> dict[str, dict]:
    """The FMU subsim's params of the first ``fmu = "..."`` subsim in a scenario file, read as plain TOML."""
    try:
        tables = tomllib.loads(path.read_text()).get("subsims", {})
    except (OSError, tomllib.TOMLDecodeError):
        return {}
    for table in tables.values():
        if isinstance(table, dict) and isinstance(table.get("fmu"), str):
            fmu = str((path.parent / table["fmu"]).resolve())
            return {"subsims.fmu:FmuSubsim": {**table.get("params", {}), "fmu": fmu}}
    return {}


def with_fmu_built(params: dict, build_dir: Path) -> dict:
    """``params``, with a mass FMU they name that is not built yet (``scenarios/fmu/mass2.fmu``: built, not shipped)
    built into ``build_dir``, as the tests build theirs (gcc and fmpy)."""
    return {k: _built(v, build_dir) for k, v in params.items()}


def _built(value: object, build_dir: Path) -> object:
    match = re.fullmatch(r".*mass([23])\.fmu", value) if isinstance(value, str) else None
    if match is None or Path(value).is_file():
        return value
    spec = importlib.util.spec_from_file_location("build_mass", ROOT / "scenarios" / "fmu" / "build_mass.py")
    assert spec is not None and spec.loader is not None
    build_mass = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(build_mass)
    return str(build_mass.build_mass_fmu(build_dir, int(match.group(1))))


def array(shape: list, data: bytes) -> dict:
    return {"shape": shape, "data": data}


class Hostile:
    """Draws one hostile frame at a time for one subsim (its key, ports and committed time)."""

    def __init__(self, rng: np.random.Generator, key: bytes, inputs: dict, t0: float, cap: int, replay: bytes):
        self.rng, self.key, self.inputs, self.t0, self.cap, self.replay = rng, key, inputs, t0, cap, replay

    def seal(self, body: bytes) -> bytes:
        return seal_request(self.key, next_seq(), body)

    def junk(self, depth: int = 0) -> object:
        r = self.rng.integers(0, 9)
        if depth > 2 or r < 4:
            return [None, True, -1, 2**63, 1e308, float("nan"), "x" * int(self.rng.integers(0, 20)),
                    self.rng.bytes(int(self.rng.integers(0, 30)))][r % 8]
        if r < 6:
            return [self.junk(depth + 1) for _ in range(int(self.rng.integers(0, 4)))]
        return {str(self.rng.integers(0, 99)): self.junk(depth + 1) for _ in range(int(self.rng.integers(0, 4)))}

    def bad_inputs(self, n: int) -> dict:
        out = {}
        for name, size in self.inputs.items():
            kind = self.rng.integers(0, 6)
            if kind == 0:
                out[name] = array([n, size], b"\0" * 7)  # data shorter than the shape
            elif kind == 1:
                out[name] = array([2**40, 2**40], b"")  # a huge claimed size
            elif kind == 2:
                out[name] = array([n, size + 1], np.zeros((n, size + 1)).tobytes())  # wrong width
            elif kind == 3:
                out[name] = array([n, size], np.full((n, size), np.nan).tobytes())
            elif kind == 4:
                out[name] = {"shape": "x", "data": 3}
            else:
                out[name] = array([n, size], np.zeros((n, size)).tobytes())
        if self.rng.integers(0, 3) == 0:
            out["no_such_port"] = array([n, 1], np.zeros(n).tobytes())
        return out

    def envelope(self) -> bytes:
        n = int(self.rng.integers(2, 6))
        t_ok = self.t0 + np.linspace(0.0, 0.1, n)
        kind = int(self.rng.integers(0, 10))
        if kind == 0:
            msg = {"v": int(self.rng.choice([0, 2, 99])), "cmd": "status", "args": {}}
        elif kind == 1:
            msg = {"v": 1, "cmd": "self_destruct", "args": {}}
        elif kind == 2:
            msg = {"v": 1, "cmd": "run_interval", "args": {"t": array([n], t_ok.tobytes()),
                                                           "inputs": self.bad_inputs(n)}}
        elif kind == 3:  # a good segment at the wrong start time
            t = t_ok + 1.0
            inputs = {k: array([n, s], np.zeros((n, s)).tobytes()) for k, s in self.inputs.items()}
            msg = {"v": 1, "cmd": "run_interval", "args": {"t": array([n], t.tobytes()), "inputs": inputs}}
        elif kind == 4:
            msg = {"v": 1, "cmd": "rollback", "args": {"to_time": -12345.678}}
        elif kind == 5:
            msg = {"v": 1, "cmd": "set_state", "args": {"time": 0.0, "state": array([1, 1, 1, 1, 1], b"\0" * 8)}}
        elif kind == 6:
            msg = {"v": 1, "cmd": "configure", "args": {"params": "not a map", "t0": 0.0}}
        elif kind == 7:
            msg = {"v": 1, "cmd": "commit", "args": {"extra": 1}}
        elif kind == 8:
            msg = {"v": 1, "cmd": "run_interval", "args": {"t": array([n], t_ok[::-1].copy().tobytes()),
                                                           "inputs": {}, "commit": "yes"}}
        else:
            msg = {"v": 1, "cmd": self.junk(), "args": self.junk(), "extra": self.junk()}
        return msgpack.packb(msg, use_bin_type=True)

    def draw(self, run: str, name: str) -> tuple[str, str, bytes]:
        """(category, key expression, frame)."""
        where = rpc_key(run, name)
        r = self.rng.random()
        if r < 0.10:
            return "random bytes", where, self.rng.bytes(int(self.rng.integers(0, 200)))
        if r < 0.20:
            return "wrong key", where, seal_request(bytes(32), next_seq(), encode_request("shutdown"))
        if r < 0.25:
            return "replay", where, self.replay
        if r < 0.30:
            return "wildcard", f"cosim/{run}/**", self.seal(encode_request("shutdown"))
        if r < 0.40:
            return "sealed random bytes", where, self.seal(self.rng.bytes(int(self.rng.integers(0, 200))))
        if r < 0.50:
            return "sealed junk", where, self.seal(msgpack.packb(self.junk(), use_bin_type=True))
        if r < 0.501:
            return "over the cap", where, self.seal(b"\x80" + b"\0" * (self.cap + 1))
        return "sealed hostile envelope", where, self.seal(self.envelope())


def first_interval(bus: Bus, name: str, handle) -> None:
    """One committed interval of zeros, so the committed state is not just the initial one."""
    d = handle.describe()
    t0 = d.time or 0.0
    times = np.array([t0, t0 + 1e-3])
    inputs = {k: np.zeros((2, p.size)) for k, p in d.inputs.items()}
    try:
        handle.run_interval(times, inputs)
        handle.commit()
    except Exception as exc:  # some models refuse zero inputs; their initial state is then the committed one
        print(f"  ({name}: no committed interval: {exc})", file=sys.stderr)


def flood(model: str, params: dict, count: int, window: int, seed: int) -> dict:
    name = model.rsplit(":", 1)[-1].lower()
    with Bus.open() as bus:
        proc = bus.spawn("", name, model=model, quiet=True, timeout=600.0)
        handle = proc.handle
        d = handle.configure(params)
        first_interval(bus, name, handle)
        before = handle.get_state()
        status = handle.status()
        key = bus.key(name)
        replay_seq = next_seq()
        replay = seal_request(key, replay_seq, encode_request("status"))
        list(bus.session.get(rpc_key(bus.run, name), payload=replay, timeout=10.0))  # answered once
        hostile = Hostile(np.random.default_rng(seed), key, {k: p.size for k, p in d.inputs.items()},
                          before.time, default_request_cap(d.inputs), replay)
        replies: Counter[str] = Counter()
        kinds: Counter[str] = Counter()
        pending: deque = deque()
        t_start = time.perf_counter()

        def collect() -> None:
            seq_frame, got = pending.popleft()
            oks = [r.ok.payload.to_bytes() for r in got if r.ok is not None]
            if not oks:
                replies["dropped"] += 1
                return
            body = open_reply(key, int.from_bytes(seq_frame[-40:-32], "big"), oks[0])
            if body is None:
                replies["unsealed reply"] += 1
                return
            try:
                reply = decode_reply("status", body)
                replies[getattr(reply, "code", "ok")] += 1
            except Exception:
                replies["ok"] += 1  # a result of another command than status: not an error

        for _ in range(count):
            kind, where, frame = hostile.draw(bus.run, name)
            kinds[kind] += 1
            pending.append((frame, bus.session.get(where, payload=frame, timeout=600.0)))
            while len(pending) >= window:
                collect()
        while pending:
            collect()
        wall = time.perf_counter() - t_start
        crashed = proc.popen.poll() is not None or not handle.alive
        changed = 0
        if not crashed:
            after = handle.get_state()
            changed = int(after.time != before.time or after.state.tobytes() != before.state.tobytes())
            served = handle.status()["requests"] - status["requests"]
        else:
            served = -1
        return {"subsim": model, "sent": count, "seconds": round(wall, 1), "kinds": dict(kinds),
                "replies": dict(replies), "served_by_runtime": served, "crashes": int(crashed),
                "state_changes": changed}


def peak_rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def oversized(megabytes: int = 32) -> str:
    """One run_interval of ``megabytes`` MB to an integrator: how fast it is refused, and the peak memory."""
    with Bus.open() as bus:
        proc = bus.spawn("subsims.integrator", "big", quiet=True, timeout=600.0)
        proc.handle.configure({})
        before = peak_rss_mb(proc.popen.pid)
        n = megabytes * 2**20 // 16
        times, inputs = np.linspace(0.0, 1.0, n), {"u": np.zeros((n, 1))}
        t0 = time.perf_counter()
        try:
            proc.handle.run_interval(times, inputs)
            outcome = "ANSWERED (no cap)"
        except Exception as exc:
            outcome = f"refused ({getattr(exc, 'code', type(exc).__name__)})"
        wall = time.perf_counter() - t0
        return (f"a {megabytes} MB run_interval to the integrator: {outcome} after {wall:.2f} s; subsim peak RSS "
                f"{before:.0f} MB before, {peak_rss_mb(proc.popen.pid):.0f} MB after")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--count", type=int, default=100_000, help="requests per subsim")
    p.add_argument("--window", type=int, default=256, help="requests in flight at once")
    p.add_argument("--only", nargs="*", help="subsims whose model contains one of these strings")
    p.add_argument("--seed", type=int, default=2026)
    p.add_argument("--json", action="store_true", help="one JSON line per subsim")
    p.add_argument("--oversized", type=int, default=32, metavar="MB",
                   help="first send one request this large and report (0: skip)")
    args = p.parse_args()
    if args.oversized:  # with --json as one JSON line too: --oversized is never skipped silently
        line = oversized(args.oversized)
        print(json.dumps({"oversized_mb": args.oversized, "result": line}) if args.json else line, flush=True)
    with tempfile.TemporaryDirectory(prefix="cosim-flood-") as tmp:
        build_dir = Path(tmp)
        models = {m: prm for m, prm in shipped().items() if not args.only or any(s in m for s in args.only)}
        bad = 0
        for model, params in models.items():
            try:
                params = with_fmu_built(params, build_dir)
            except Exception as exc:  # no compiler or no fmpy here: say so, go on with the others
                print(f"{model}: skipped, its FMU could not be built ({type(exc).__name__}: {exc})", flush=True)
                continue
            row = flood(model, params, args.count, args.window, args.seed)
            bad += row["crashes"] + row["state_changes"]
            for k in ("bad_request", "decode"):
                row["replies"].setdefault(k, 0)
            if args.json:
                print(json.dumps(row), flush=True)
            else:
                codes = ", ".join(f"{k} {v}" for k, v in sorted(row["replies"].items()))
                print(f"{model}: {row['sent']} sent in {row['seconds']} s; crashes {row['crashes']}, committed-state "
                      f"changes {row['state_changes']}; replies: {codes}; reached the runtime: "
                      f"{row['served_by_runtime']}", flush=True)
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
