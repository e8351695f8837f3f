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
from cosim.protocol.messages import ErrorInfo, decode_reply, encode_request

NONE = zenoh.ConsolidationMode.NONE

# Every query leaves a task in the session that sent it: the task sleeps for the query's whole timeout
# and ends early only when that session closes, not when the query is answered (zenoh 1.x,
# zenoh/src/api/session.rs, Session::query; eclipse-zenoh/zenoh#877 was the same bug in 0.11). Measured
# with eclipse-zenoh 1.10.2: 1.1 KB of resident memory per request until its timeout, so a coordinator
# sending 2,000 requests a second with a 120 s timeout would hold about 260 MB for answered requests.
# A handle therefore sends from a client session of its own (opened by ``requests``) and replaces it
# every RENEW_EVERY requests, between requests: memory stays within RENEW_EVERY such tasks (about 5 MB
# per subsim), at the cost of one more hop (this process's router) per request and a new session (about
# 10 ms) every RENEW_EVERY requests.
RENEW_EVERY = 5000


class RemoteHandle(SubsimHandle):
    """Zenoh request/reply to ``cosim/<run>/<name>/rpc``; liveliness reports a dead process at once."""

    def __init__(
        self,
        session: zenoh.Session,
        run: str,
        name: str,
        timeout: float = 60.0,
        requests: Callable[[], zenoh.Session] | None = None,
        renew_every: int = RENEW_EVERY,
    ) -> None:
        """``session`` watches the subsim's liveliness. ``requests`` opens a client session of the router
        from which the handle sends its requests, replaced every ``renew_every`` requests (see
        :data:`RENEW_EVERY`); without it, requests go from ``session`` and their memory outlives them."""
        self.session, self.run, self.name = session, run, check_name(name, "subsim name")
        self._key = rpc_key(run, name)
        self.timeout = timeout
        self._open_requests, self._renew_every = requests, renew_every
        self._requests: zenoh.Session | None = None  # the session of our own, once opened
        self._sent = self._in_flight = 0
        # A declared querier costs about 35 us less per request than session.get. Its timeout is fixed
        # at declaration, and a querier declared late may not see the subsim yet, so a request made
        # after ``timeout`` changed goes through session.get instead.
        self._querier: zenoh.Querier | None = None
        self._querier_timeout: float | None = None
        if requests is None:
            self._querier = session.declare_querier(self._key, timeout=timeout, consolidation=NONE)
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
            replies = list(self.session.get(self._key, payload=encode_request("status"), timeout=1.0))
            if replies and replies[0].ok is not None:
                return
            if time.monotonic() > deadline:
                raise SubsimError("no_responder", f"not answering after {timeout:g} s", self.name, "connect")
            time.sleep(0.01)

    def _begin(self, cmd: str, args: dict[str, Any]) -> Callable[[], dict]:
        if self._died.is_set():
            raise SubsimDied("no_responder", "the subsim process is gone (liveliness lost)", self.name, cmd)
        payload = encode_request(cmd, args)
        if self._open_requests is not None and self._in_flight == 0 and (
            self._requests is None or self._sent >= self._renew_every
        ):
            self._renew()
        source = self._requests if self._requests is not None else self.session
        if self.timeout == self._querier_timeout and self._querier is not None:
            replies = self._querier.get(payload=payload)
        else:
            replies = source.get(self._key, payload=payload, timeout=self.timeout, consolidation=NONE)
        self._sent += 1
        self._in_flight += 1
        return lambda: self._finish(cmd, replies)

    def _renew(self) -> None:
        """Send from now on from a fresh client session; close the old one, which frees its queries' tasks."""
        fresh = self._open_requests()  # type: ignore[misc]
        try:
            querier = fresh.declare_querier(self._key, timeout=self.timeout, consolidation=NONE)
            # declarations reach a new session a moment after it opens (zenoh-notes P2)
            deadline = time.monotonic() + min(self.timeout, 10.0)
            while not querier.matching_status.matching and not self._died.is_set() and time.monotonic() < deadline:
                time.sleep(0.001)
        except BaseException:
            fresh.close()
            raise
        old, self._requests = self._requests, fresh
        self._querier, self._querier_timeout, self._sent = querier, self.timeout, 0
        if old is not None:
            old.close()

    def _finish(self, cmd: str, replies: Any) -> dict:
        try:
            return self._wait(cmd, replies)
        finally:
            self._in_flight -= 1

    def _wait(self, cmd: str, replies: Any) -> dict:
        # blocks until the reply or the end of the request: a waiting coordinator leaves the cores to the
        # subsims (a polling wait was 40-60 us faster per round trip but burned a core the subsims need)
        reply = next(iter(replies), None)
        if reply is not None:
            if reply.ok is None:
                text = reply.err.payload.to_bytes().decode(errors="replace")
                if self._died.is_set():
                    raise SubsimDied("no_responder", f"the process died during the request ({text})", self.name, cmd)
                raise SubsimError("timeout", f"no reply within {self.timeout:g} s ({text})", self.name, cmd)
            try:
                result = decode_reply(cmd, reply.ok.payload.to_bytes())
            except ProtocolError as exc:
                raise SubsimError(exc.code, f"malformed reply: {exc.message}", self.name, cmd) from None
            if isinstance(result, ErrorInfo):
                raise SubsimError(result.code, result.message, result.subsim, result.command)
            return result
        # zero replies: nobody serves the key (not started, or died mid-request)
        self._died.wait(0.5 if self._alive.is_set() else 0.0)
        reason = "the process died during the request" if self._died.is_set() else "no process serves this subsim"
        raise SubsimDied("no_responder", reason, self.name, cmd)

    def close(self) -> None:
        """Undeclare and close what the handle opened; later requests (a last ``shutdown``) use ``session``."""
        entities = (self._querier, self._liveliness, self._requests)
        self._open_requests, self._requests, self._querier, self._querier_timeout = None, None, None, None
        for entity in entities:
            try:
                if isinstance(entity, zenoh.Session):
                    entity.close()
                elif entity is not None:
                    entity.undeclare()
            except Exception:
                pass
