"""Subsim side of the Zenoh transport: serve one runtime's commands on ``cosim/<run>/<name>/rpc``.

Commands are handled one at a time, in arrival order, so the model and its state are only ever
touched by one thread at a time. Queries arrive on zenoh-python's callback thread, which checks
them without blocking: it answers queries that are not exactly this subsim's key (wildcards) with
nothing, drops frames without this subsim's tag and replays, refuses oversized ones (``too_large``) and, when
``queue_size`` requests are already waiting, answers ``busy``. A flood therefore never stalls
Zenoh's receive path (which would cost the subsim its link) and never reaches the model.

A request that finds the subsim idle and is known to be quick (every command but ``configure``,
``shutdown`` and a ``run_interval`` slower than ``inline_limit`` last time) is answered right there
on the callback thread: the hand-off to the serving thread and back cost a request about 35 us of
CPU and 20-30 us of wall time (``benchmarks/roundtrip.py``). Anything else is queued for the thread
that calls :meth:`CommandServer.serve`.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from collections.abc import Callable

import zenoh

from cosim.protocol.keys import alive_key, coordinator_alive_key, rpc_key
from cosim.protocol.messages import peek_command
from cosim.protocol.service import Admitted, Gate
from cosim.runtime import Runtime

log = logging.getLogger(__name__)

DEFAULT_QUEUE = 64
NEVER_SEALED = 3  # requests dropped for their seal, none admitted yet: tell the operator once (a wrong key?)


# Answered where they arrive when the subsim is idle: bookkeeping only, no model run. (configure builds a
# model, shutdown ends the serving loop: both go through it.)
QUICK_COMMANDS = frozenset({"describe", "status", "commit", "rollback", "get_state", "set_state"})
INLINE_LIMIT = 0.005  # s: a run_interval is answered where it arrives while the last one took at most this


class CommandServer:
    """Declares the rpc queryable, the liveliness token, and a watch on the coordinator's token."""

    def __init__(
        self,
        session: zenoh.Session,
        run: str,
        runtime: Runtime,
        on_coordinator_lost: Callable[[], None] | None = None,
        key: bytes | None = None,
        max_request: int | None = None,
        queue_size: int = DEFAULT_QUEUE,
        inline_limit: float = INLINE_LIMIT,
        on_never_sealed: Callable[[], None] | None = None,
    ) -> None:
        self.runtime = runtime
        self.gate = Gate(runtime, key, max_request)
        self._on_lost = on_coordinator_lost
        self._on_never_sealed = on_never_sealed  # called once: requests come, none ever sealed with our key
        self._rpc = rpc_key(run, runtime.name)
        # requests waiting for the serving thread; ``_busy``: a request is being answered (on either thread).
        # Both change under ``_ready``'s lock, so a request is answered inline only when none came before it.
        self._queued: collections.deque[tuple[zenoh.Query, zenoh.KeyExpr, Admitted, str | None]] = collections.deque()
        self._busy = False
        self._ready = threading.Condition()
        self._queue_size = queue_size
        self.inline_limit = inline_limit
        self._last_run = float("inf")  # seconds the last run_interval took (unknown: not quick)
        self.inline_count = 0  # requests answered on the callback thread (for tests and benchmarks)
        self._queryable = session.declare_queryable(self._rpc, self._on_query)
        self._watch = session.liveliness().declare_subscriber(coordinator_alive_key(run), self._on_coordinator)
        # the token goes last: once it is seen, the queryable has been declared
        self._token = session.liveliness().declare_token(alive_key(run, runtime.name))

    def _on_coordinator(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.DELETE and self._on_lost is not None:
            self._on_lost()

    def _on_query(self, query: zenoh.Query) -> None:
        """zenoh-python's thread for this queryable: checks, then answers a quick request or queues it."""
        try:
            key_expr = query.key_expr
            if str(key_expr) != self._rpc:  # a wildcard or another key: not addressed to us
                self.gate.counts["dropped"] += 1
                query.__exit__()
                return
            payload = query.payload
            admitted, reply = self.gate.admit(payload.to_bytes() if payload is not None else b"")
            counts = self.gate.counts
            if admitted is None and self._on_never_sealed is not None and counts["dropped"] >= NEVER_SEALED \
                    and not counts["admitted"]:  # e.g. started with another run's COSIM_SECRET
                notice, self._on_never_sealed = self._on_never_sealed, None
                notice()
            if admitted is not None:
                cmd = peek_command(admitted.body)
                quick = cmd in QUICK_COMMANDS or (cmd == "run_interval" and self._last_run <= self.inline_limit)
                with self._ready:
                    inline = quick and not self._busy and not self._queued
                    queued = len(self._queued)
                    if inline:
                        self._busy = True
                    elif queued < self._queue_size:
                        self._queued.append((query, key_expr, admitted, cmd))
                        self._ready.notify()
                        return
                if inline:
                    self.inline_count += 1
                    self._answer(query, key_expr, admitted, cmd)
                    return
                reply = self.gate.busy(admitted, queued)
            with query:
                if reply is not None:
                    query.reply(key_expr, reply)
        except Exception:  # the receive path must survive anything
            log.exception("dropping a query that could not be checked")

    def _answer(self, query: zenoh.Query, key_expr: zenoh.KeyExpr, request: Admitted, cmd: str | None) -> None:
        """Answer one request (``_busy`` is set), then let the next one in. ``cmd``: its command, peeked."""
        try:
            with query:
                started = time.perf_counter()
                reply = self.gate.answer(request)
                if cmd == "run_interval":
                    self._last_run = time.perf_counter() - started
                elif cmd == "configure":  # perhaps another model now: its speed is not known
                    self._last_run = float("inf")
                query.reply(key_expr, reply)
        finally:
            with self._ready:
                self._busy = False
                if self._queued:
                    self._ready.notify()

    def serve(self) -> None:
        """Serve until ``shutdown`` is requested. The wait wakes every 100 ms, so signals are delivered."""
        while not self.runtime.shutdown_requested:
            with self._ready:
                if self._busy or not self._queued:
                    self._ready.wait(0.1)
                    continue
                query, key_expr, request, cmd = self._queued.popleft()
                self._busy = True
            self._answer(query, key_expr, request, cmd)

    def close(self) -> None:
        for entity in (self._token, self._watch, self._queryable):
            try:
                entity.undeclare()
            except Exception:  # already gone with the session
                pass
        with self._ready:  # requests queued behind shutdown are not answered; finalize them
            left, self._queued = list(self._queued), collections.deque()
        for query, *_ in left:
            query.__exit__()
