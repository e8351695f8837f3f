"""Coordinator side of the Zenoh transport: a subsim handle that sends requests to ``cosim/<run>/<name>/rpc``."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import zenoh

from cosim.contract import ProtocolError, SubsimDied, SubsimError
from cosim.handles import SubsimHandle
from cosim.protocol.keys import alive_key, check_name, rpc_key
from cosim.protocol.messages import ErrorInfo, decode_reply, encode_request, next_seq, open_reply, seal_request


class RemoteHandle(SubsimHandle):
    """Zenoh request/reply to ``cosim/<run>/<name>/rpc``; liveliness reports a dead process at once.

    With ``key`` (the subsim's key, :func:`cosim.protocol.security.subsim_key`) every request is sealed
    and only a reply carrying the subsim's tag for that request is believed (docs/protocol.md 4.1)."""

    def __init__(
        self, session: zenoh.Session, run: str, name: str, timeout: float = 60.0, key: bytes | None = None
    ) -> None:
        self.session, self.run, self.name = session, run, check_name(name, "subsim name")
        self._secret = key
        self._key = rpc_key(run, name)
        self.timeout = timeout
        # A declared querier costs about 35 us less per request than session.get. Its timeout is fixed
        # at declaration, and a querier declared late may not see the subsim yet, so a request made
        # after ``timeout`` changed goes through session.get instead.
        self._querier = session.declare_querier(self._key, timeout=timeout, consolidation=zenoh.ConsolidationMode.NONE)
        self._querier_timeout = timeout
        self._alive = threading.Event()
        self._died = threading.Event()
        self._liveliness = session.liveliness().declare_subscriber(
            alive_key(run, name), self._on_liveliness, history=True
        )

    def _on_liveliness(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            self._died.clear()
            self._alive.set()
        else:
            self._alive.clear()
            self._died.set()

    @property
    def alive(self) -> bool:
        return self._alive.is_set()

    def wait_alive(self, timeout: float) -> bool:
        """True once the process's liveliness token has been seen (within ``timeout`` seconds)."""
        return self._alive.wait(timeout)

    def wait_ready(self, timeout: float = 10.0) -> None:
        """Wait for the liveliness token and a first answered ``status`` (declarations propagate late)."""
        deadline = time.monotonic() + timeout
        if not self.wait_alive(timeout):
            raise SubsimError("no_responder", f"no process appeared within {timeout:g} s", self.name, "connect")
        while True:
            seq, frame = self._seal(encode_request("status"))
            replies = self.session.get(
                self._key, payload=frame, timeout=1.0, consolidation=zenoh.ConsolidationMode.NONE
            )
            if any(r.ok is not None and self._open(seq, r.ok.payload.to_bytes()) is not None for r in replies):
                return
            if time.monotonic() > deadline:
                raise SubsimError("no_responder", f"not answering after {timeout:g} s", self.name, "connect")
            time.sleep(0.01)

    def _begin(self, cmd: str, args: dict[str, Any]) -> Callable[[], dict]:
        if self._died.is_set():
            raise SubsimDied("no_responder", "the subsim process is gone (liveliness lost)", self.name, cmd)
        seq, payload = self._seal(encode_request(cmd, args))
        if self.timeout == self._querier_timeout:
            replies = self._querier.get(payload=payload)
        else:
            replies = self.session.get(
                self._key, payload=payload, timeout=self.timeout, consolidation=zenoh.ConsolidationMode.NONE
            )
        return lambda: self._finish(cmd, seq, replies)

    def _seal(self, body: bytes) -> tuple[int, bytes]:
        if self._secret is None:
            return -1, body
        seq = next_seq()
        return seq, seal_request(self._secret, seq, body)

    def _open(self, seq: int, frame: bytes) -> bytes | memoryview | None:
        return frame if self._secret is None else open_reply(self._secret, seq, frame)

    def _finish(self, cmd: str, seq: int, replies: Any) -> dict:
        # blocks until the reply or the end of the request: a waiting coordinator leaves the cores to the
        # subsims (a polling wait was 40-60 us faster per round trip but burned a core the subsims need)
        forged = 0
        for reply in replies:
            if reply.ok is None:
                text = reply.err.payload.to_bytes().decode(errors="replace")
                if self._died.is_set():
                    raise SubsimDied("no_responder", f"the process died during the request ({text})", self.name, cmd)
                raise SubsimError("timeout", f"no reply within {self.timeout:g} s ({text})", self.name, cmd)
            body = self._open(seq, reply.ok.payload.to_bytes())
            if body is None:  # not sealed with this subsim's key for this request: not from our subsim
                forged += 1
                continue
            try:
                result = decode_reply(cmd, body)
            except ProtocolError as exc:
                raise SubsimError(exc.code, f"malformed reply: {exc.message}", self.name, cmd) from None
            if isinstance(result, ErrorInfo):
                raise SubsimError(result.code, result.message, result.subsim,
                                  cmd if result.command == "?" else result.command)
            return result
        if forged:
            raise SubsimError("unauthenticated", f"{forged} reply(ies) without this subsim's tag: is it running with "
                              "the key cosim gave it (COSIM_SECRET)?", self.name, cmd)
        # zero replies: nobody serves the key (not started, or died mid-request)
        self._died.wait(0.5 if self._alive.is_set() else 0.0)
        reason = "the process died during the request" if self._died.is_set() else "no process serves this subsim"
        raise SubsimDied("no_responder", reason, self.name, cmd)

    def close(self) -> None:
        for entity in (self._querier, self._liveliness):
            try:
                entity.undeclare()
            except Exception:
                pass
