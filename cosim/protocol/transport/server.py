"""Subsim side of the Zenoh transport: serve one runtime's commands on ``cosim/<run>/<name>/rpc``.

Commands are handled one at a time on the thread that calls :meth:`CommandServer.serve`, so the
model and its state are only ever touched by that thread. Queries arrive on zenoh-python's callback
thread, which never blocks: it answers queries that are not exactly this subsim's key (wildcards)
with nothing, drops frames without this subsim's tag, refuses oversized ones (``too_large``) and,
when ``queue_size`` requests are already waiting, answers ``busy``. A flood therefore never stalls
Zenoh's receive path (which would cost the subsim its link) and never reaches the model.
"""

from __future__ import annotations

import logging
import queue
from collections.abc import Callable

import zenoh

from cosim.protocol.keys import alive_key, coordinator_alive_key, rpc_key
from cosim.protocol.service import Admitted, Gate
from cosim.runtime import Runtime

log = logging.getLogger(__name__)

DEFAULT_QUEUE = 64


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
    ) -> None:
        self.runtime = runtime
        self.gate = Gate(runtime, key, max_request)
        self._on_lost = on_coordinator_lost
        self._rpc = rpc_key(run, runtime.name)
        # a SimpleQueue (C) costs a tenth of a queue.Queue per hand-off. Zenoh runs this queryable's callbacks
        # one at a time, so the bound checked against qsize() in _on_query holds (serving only makes room)
        self._pending: queue.SimpleQueue[tuple[zenoh.Query, zenoh.KeyExpr, Admitted]] = queue.SimpleQueue()
        self._queue_size = queue_size
        self._queryable = session.declare_queryable(self._rpc, self._on_query)
        self._watch = session.liveliness().declare_subscriber(coordinator_alive_key(run), self._on_coordinator)
        # the token goes last: once it is seen, the queryable has been declared
        self._token = session.liveliness().declare_token(alive_key(run, runtime.name))

    def _on_coordinator(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.DELETE and self._on_lost is not None:
            self._on_lost()

    def _on_query(self, query: zenoh.Query) -> None:
        """zenoh-python's thread for this queryable: checks, then queues; must never block."""
        try:
            key_expr = query.key_expr
            if str(key_expr) != self._rpc:  # a wildcard or another key: not addressed to us
                self.gate.counts["dropped"] += 1
                query.__exit__()
                return
            payload = query.payload
            admitted, reply = self.gate.admit(payload.to_bytes() if payload is not None else b"")
            if admitted is not None:
                queued = self._pending.qsize()
                if queued < self._queue_size:
                    self._pending.put((query, key_expr, admitted))
                    return
                reply = self.gate.busy(admitted, queued)
            with query:
                if reply is not None:
                    query.reply(key_expr, reply)
        except Exception:  # the receive path must survive anything
            log.exception("dropping a query that could not be checked")

    def serve(self) -> None:
        """Serve until ``shutdown`` is requested. The wait wakes every 100 ms, so signals are delivered."""
        while not self.runtime.shutdown_requested:
            try:
                query, key_expr, request = self._pending.get(timeout=0.1)
            except queue.Empty:
                continue
            with query:
                reply = self.gate.answer(request)
                if reply is not None:
                    query.reply(key_expr, reply)

    def close(self) -> None:
        for entity in (self._token, self._watch, self._queryable):
            try:
                entity.undeclare()
            except Exception:  # already gone with the session
                pass
        while True:  # requests queued behind shutdown are not answered; finalize them
            try:
                query, _, _ = self._pending.get_nowait()
            except queue.Empty:
                return
            query.__exit__()
