"""Subsim side of the bus: serve one runtime's commands on ``cosim/<run>/<name>/rpc``.

Commands are handled one at a time on the thread that calls :meth:`CommandServer.serve`, so the
model and its state are only ever touched by that thread.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import zenoh

from cosim.contract import CosimError
from cosim.protocol.bus import alive_key, coordinator_alive_key, rpc_key
from cosim.protocol.messages import decode_request, encode_error, encode_result, request_command
from cosim.runtime import Runtime

log = logging.getLogger(__name__)


def answer(runtime: Runtime, payload: bytes) -> bytes:
    """Turn one request payload into one reply payload. Never raises."""
    cmd = "?"
    try:
        request = decode_request(payload)
        cmd = request.cmd
        return encode_result(runtime.handle(request.cmd, request.args))
    except CosimError as exc:
        if cmd == "?":
            cmd = request_command(payload)
        return encode_error(exc.code, exc.message, runtime.name, cmd)
    except Exception as exc:  # last line of defence: the process must survive any request
        log.exception("unexpected failure serving %s", cmd)
        return encode_error("internal", f"{type(exc).__name__}: {exc}", runtime.name, cmd)


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
