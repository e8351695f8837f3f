"""Subsim side of the Zenoh transport: serve one runtime's commands on ``cosim/<run>/<name>/rpc``.

Commands are handled one at a time on the thread that calls :meth:`CommandServer.serve`, so the
model and its state are only ever touched by that thread.
"""

from __future__ import annotations

from collections.abc import Callable

import zenoh

from cosim.protocol.keys import alive_key, coordinator_alive_key, rpc_key
from cosim.protocol.service import answer
from cosim.runtime import Runtime


class CommandServer:
    """Declares the rpc queryable, the liveliness token, and a watch on the coordinator's token."""

    def __init__(
        self,
        session: zenoh.Session,
        run: str,
        runtime: Runtime,
        on_coordinator_lost: Callable[[], None] | None = None,
    ) -> None:
        self.runtime = runtime
        self._on_lost = on_coordinator_lost
        self._queryable = session.declare_queryable(rpc_key(run, runtime.name), zenoh.handlers.FifoChannel(64))
        self._watch = session.liveliness().declare_subscriber(coordinator_alive_key(run), self._on_coordinator)
        # the token goes last: once it is seen, the queryable has been declared
        self._token = session.liveliness().declare_token(alive_key(run, runtime.name))

    def _on_coordinator(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.DELETE and self._on_lost is not None:
            self._on_lost()

    def serve(self) -> None:
        """Serve until ``shutdown`` is requested. ``recv`` wakes every 100 ms to deliver signals."""
        while not self.runtime.shutdown_requested:
            query = self._queryable.recv()
            with query:
                payload = query.payload.to_bytes() if query.payload is not None else b""
                query.reply(query.key_expr, answer(self.runtime, payload))

    def close(self) -> None:
        for entity in (self._token, self._watch, self._queryable):
            try:
                entity.undeclare()
            except Exception:  # already gone with the session
                pass
