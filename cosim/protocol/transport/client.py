"""Coordinator side of the Zenoh transport: a subsim handle that sends requests to ``cosim/<run>/<name>/rpc``."""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from functools import partial
from typing import Any

import zenoh

from cosim.contract import (
    PROTOCOL_VERSION,
    MalformedReply,
    ProtocolError,
    SubsimDied,
    SubsimError,
    SubsimHung,
    SubsimLeft,
)
from cosim.handles import SubsimHandle
from cosim.protocol.keys import alive_key, check_name, rpc_key
from cosim.protocol.messages import ErrorInfo, VersionMismatch, decode_reply, encode_request, next_seq, sealer

FAST_QUERY_TIMEOUT = 4.0  # seconds: zenoh's own timeout of requests whose deadline is at most half of it
GONE_GRACE = 0.3  # seconds a request may still be answered after its subsim's liveliness token went
DEFAULT_LEASE = 10.0  # s a subsim waits for a silent coordinator by default (cosim.process --lease)
LEFT_AFTER = 0.8  # a death after a pause of this part of the subsim's lease or more is taken as caused by it
PAUSE_REMEMBERED = 30.0  # s: a pause that ended longer before a death was found explains none
DIED_MID_REQUEST = "the process died during the request"
GONE = "the subsim process is gone"
NOT_APPEARED = "no process appeared within"  # (a wait for a subsim's token ran out)
SILENT_LIMIT = 15.0  # seconds a serving process (its token there, past a cut link's 10 s lease) may leave us unanswered
# Every queryable on a subsim's key gets its requests (not only the best match): another login holder's queryable
# declared there as complete would otherwise take them all and black-hole the subsim (its replies are forged anyway).
EVERY_QUERYABLE = zenoh.QueryTarget.ALL


class NotAppeared(SubsimError):
    """No process served the subsim's name within the wait: it was never started, or under another --run/--name."""


class _Pending:
    """One request in flight: its reply channel, the token that can cancel it, and its deadline."""

    __slots__ = ("replies", "token", "expires", "hung", "gone", "sent", "timeout_at", "early", "ended")

    def __init__(self, replies: Any, token: zenoh.CancellationToken, expires: float | None, sent: float,
                 timeout_at: float) -> None:
        self.replies, self.token, self.expires = replies, token, expires
        self.sent = sent
        self.timeout_at = timeout_at  # when zenoh's own timeout of the query ends it
        self.hung = False
        self.gone = False  # the subsim's liveliness token went while this was in flight
        self.early: list[zenoh.Reply] = []  # replies taken by ready(), read first by the waiter
        self.ended = False  # ready() found the channel closed

    def ready(self) -> bool:
        """True once waiting would not block: a reply came, or the query ended. Never blocks."""
        if self.early or self.ended:
            return True
        try:
            reply = self.replies.try_recv()
        except zenoh.ZError:  # closed and empty: the query ended without (another) reply
            self.ended = True
            return True
        if reply is None:
            return False
        self.early.append(reply)
        return True

    def all_replies(self) -> Iterable[zenoh.Reply]:
        """Every reply, blocking until the query ends: those ready() took first."""
        yield from self.early
        if not self.ended:
            yield from self.replies

    def cancel(self) -> None:
        self.hung = not self.gone
        self.token.cancel()  # closes the reply channel: the waiting caller wakes with no reply


class _Watchdog:
    """One thread per process that cancels requests past their deadline.

    The caller blocks on zenoh's reply channel (no GIL hand-off on the reply path: a callback handler
    measured twice as slow under load); this thread wakes every ``TICK`` seconds, so a deadline fires
    at most that late. Registering a request is a dict insert: nothing is woken per request.

    A tick more than ``PAUSE`` seconds late means this process did not run meanwhile (stopped with Ctrl-Z or
    SIGSTOP, a debugger, a paused VM): the time it lost is not the subsims' fault, so every deadline moves on
    by it, and the pauses are kept for the errors to name (:meth:`paused_since`).
    """

    TICK = 0.05
    PAUSE = 0.5

    def __init__(self) -> None:
        self._watched: dict[int, _Pending] = {}
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self._tick = time.monotonic()  # the last tick
        self._pauses: deque[tuple[float, float]] = deque(maxlen=16)  # (start, end) of the latest pauses

    def long_pause(self, since: float, minimum: float) -> tuple[float, float] | None:
        """The latest pause of at least ``minimum`` seconds that ended after ``since`` (the one going on, not yet
        ticked over, included), as (start, end)."""
        late = time.monotonic() - self._tick - self.TICK
        if self._thread is not None and late >= minimum:
            return self._tick, self._tick + late
        return next(((start, end) for start, end in reversed(list(self._pauses))
                     if end > since and end - start >= minimum), None)

    def paused_since(self, since: float) -> float:
        """Seconds this process was found not running after ``since``, a pause not yet ticked over included."""
        lost = sum(end - max(start, since) for start, end in list(self._pauses) if end > since)
        late = time.monotonic() - self._tick - self.TICK
        return lost + (late if self._thread is not None and late > self.PAUSE else 0.0)

    def watch(self, pending: _Pending) -> None:
        self._watched[id(pending)] = pending
        if self._thread is None:
            with self._lock:
                if self._thread is None:
                    self._thread = threading.Thread(target=self._run, name="cosim-deadlines", daemon=True)
                    self._thread.start()

    def forget(self, pending: _Pending) -> None:
        self._watched.pop(id(pending), None)

    def _run(self) -> None:
        self._tick = time.monotonic()
        while True:
            time.sleep(self.TICK)
            now = time.monotonic()
            late, self._tick = now - self._tick - self.TICK, now
            if late > self.PAUSE:
                self._pauses.append((now - late, now))
                for pending in list(self._watched.values()):
                    if pending.expires is not None:
                        pending.expires += late
            for key, pending in list(self._watched.items()):
                if pending.expires is not None and now >= pending.expires:
                    self._watched.pop(key, None)
                    pending.cancel()


_WATCHDOG = _Watchdog()


class RemoteHandle(SubsimHandle):
    """Zenoh request/reply to ``cosim/<run>/<name>/rpc``; liveliness reports a dead process at once.

    ``timeout``: zenoh's own limit on a query. ``deadline`` (seconds, or None): how long a caller waits for
    a reply before it calls the subsim hung (``SubsimHung``); the driver sets it from measured request
    times, so a stopped or stuck process is found long before ``timeout``.

    With ``key`` (the subsim's key, :func:`cosim.protocol.security.subsim_key`) every request is sealed
    and only a reply carrying the subsim's tag for that request is believed (docs/protocol.md 4.1).

    ``served``: the Zenoh ids of the processes that served ``name`` earlier in the run (shared by its handles, this
    one adds the process it adopts). One of them answering beside this handle's process is an old process woken up
    after it was replaced (a subsim stopped longer than its lease): its replies are ignored, not taken for a second
    copy started by hand."""

    checks_replies = True  # the process may be anyone's implementation of the protocol

    def __init__(
        self, session: zenoh.Session, run: str, name: str, timeout: float = 60.0, key: bytes | None = None,
        served: set | None = None,
    ) -> None:
        self.session, self.run, self.name = session, run, check_name(name, "subsim name")
        self._sealer = None if key is None else sealer(key)
        self._key = rpc_key(run, name)
        self.timeout = timeout
        self.deadline: float | None = None
        self.hung = False  # a request missed its deadline: the process is stuck or stopped (its stop need not ask)
        # how its process ended ("killed by SIGSEGV"), for the error that says it died; set by whoever started it
        self.exit_status: Callable[[], str | None] | None = None
        self.lease = DEFAULT_LEASE  # s the subsim waits for a silent coordinator before it leaves (its --lease)
        self._born = time.monotonic()  # a pause before its process was asked for made no process of it leave
        self._server: Any = None  # the Zenoh id of the process that answers (its first valid reply's)
        self._server_lost = False  # a token of this name went since ``_server`` answered: it may be another's now
        self._served = set() if served is None else served
        self._in_flight: set[_Pending] = set()
        # A declared querier costs about 35 us less per request than session.get; its timeout is fixed at
        # declaration. Zenoh keeps a task of about 1.1 KB per query for the query's whole timeout, however soon
        # the reply comes (measured: +11 MiB per 10^4 requests with a 120 s timeout), so requests with a short
        # deadline go through a querier with a short timeout (memory stays at rate x FAST_QUERY_TIMEOUT), and the
        # rest (no deadline, or a slow model) through session.get with the timeout they need.
        self._querier = session.declare_querier(self._key, timeout=FAST_QUERY_TIMEOUT, target=EVERY_QUERYABLE,
                                                consolidation=zenoh.ConsolidationMode.NONE)
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
            self._server_lost = self._server is not None
            # no reply will come, unless one is already on its way (a subsim replies to shutdown, then leaves):
            # give that one a moment, then wake the waiter
            soon = time.monotonic() + GONE_GRACE
            for pending in list(self._in_flight):
                pending.gone = True
                pending.expires = soon if pending.expires is None else min(pending.expires, soon)
                _WATCHDOG.watch(pending)

    def _still_served(self) -> bool:
        """After a DELETE of the subsim's token: whether a token is on its key all the same. A process killed to
        be replaced has its token removed when the router notices, which may be after its successor's token came
        (seen in CI): that late DELETE is not the successor's death."""
        try:
            replies = list(self.session.liveliness().get(alive_key(self.run, self.name), timeout=1.0))
        except zenoh.ZError:  # the session is closing
            return False
        if not any(r.ok is not None for r in replies):
            return False
        self._died.clear()
        self._alive.set()
        return True

    @property
    def alive(self) -> bool:
        return self._alive.is_set()

    def wait_alive(self, timeout: float) -> bool:
        """True once the process's liveliness token has been seen (within ``timeout`` seconds)."""
        return self._alive.wait(timeout)

    def wait_ready(self, timeout: float = 10.0) -> None:
        """Wait for the liveliness token and a first answered ``status`` (declarations propagate late). A process
        whose token has been there for :data:`SILENT_LIMIT` seconds without one valid reply is given up on then,
        not at the end of a long ``timeout``: it runs, but drops our requests (another run's key)."""
        deadline = time.monotonic() + timeout
        untagged, silent_since = 0, None  # replies without a valid tag; since when the token is there, unanswered
        while True:
            if not self._alive.is_set():  # not yet there, or gone again (a cut link outlived its lease)
                if not self.wait_alive(max(deadline - time.monotonic(), 0.0)):
                    raise NotAppeared("no_responder", f"{NOT_APPEARED} {timeout:g} s (none serves run "
                                                      f"{self.run!r} as {self.name!r}: check its --run and --name)",
                                      self.name, "connect")
                silent_since = time.monotonic()
            seq, frame = self._seal(encode_request("status"))
            replies = [r for r in self.session.get(self._key, payload=frame, timeout=1.0, target=EVERY_QUERYABLE,
                                                   consolidation=zenoh.ConsolidationMode.NONE) if r.ok is not None]
            genuine = [r.replier_id.zid for r in replies if self._open(seq, r.ok.payload.to_bytes()) is not None]
            if genuine:  # a process new to this run's name rather than an earlier one still (or again) up
                self._adopt(next((z for z in genuine if z not in self._served), genuine[0]))
                return
            untagged += len(replies)
            now = time.monotonic()
            silent = now - (silent_since or now)
            if (now > deadline or silent > SILENT_LIMIT) and untagged:
                raise SubsimError("unauthenticated", f"it answers, but none of its {untagged} replies in "
                                  f"{silent:.0f} s carried a valid tag for its request (docs/protocol.md 4.1: the "
                                  "reply tag covers the request's seq, with this subsim's key)", self.name, "connect")
            if now > deadline or silent > SILENT_LIMIT:  # its token is there, so it runs: it drops what it cannot open
                raise SubsimError("no_responder", f"its process is up but has not answered in {silent:.0f} s: is it "
                                  "running with this run's COSIM_SECRET? (a subsim silently drops requests sealed "
                                  "with another key)", self.name, "connect")
            time.sleep(0.01)

    def _adopt(self, server: Any) -> None:
        self._server = self._server or server
        self._served.add(self._server)

    def _begin(self, cmd: str, args: dict[str, Any]) -> Callable[[], dict]:
        if self._died.is_set() and not self._still_served():
            if self.session.is_closed():  # (it said the process had exited with code 0: the bus stopped it)
                raise SubsimError("no_responder", "its bus is closed (the coordinator's session, and the processes "
                                  "it started): open another and spawn or attach the subsim again", self.name, cmd)
            raise self._died_error(GONE, cmd, self._token_went(during=False))
        seq, payload = self._seal(encode_request(cmd, args))
        token = zenoh.CancellationToken()
        deadline = self.deadline
        now = time.monotonic()
        if deadline is not None and 2 * deadline <= FAST_QUERY_TIMEOUT <= self.timeout:
            replies = self._querier.get(payload=payload, cancellation_token=token)
            limit = FAST_QUERY_TIMEOUT
        else:
            limit = self.timeout if deadline is None else min(self.timeout, max(2 * deadline, FAST_QUERY_TIMEOUT))
            replies = self.session.get(self._key, payload=payload, timeout=limit, cancellation_token=token,
                                       target=EVERY_QUERYABLE, consolidation=zenoh.ConsolidationMode.NONE)
        pending = _Pending(replies, token, None if deadline is None else now + deadline, now, now + limit)
        self._in_flight.add(pending)
        if deadline is not None:
            _WATCHDOG.watch(pending)
        return partial(self._finish, cmd, seq, pending, deadline)  # one frame less per request than a lambda

    def replied(self) -> bool:
        """Whether every request of this handle has its reply (or has ended): collecting would not block."""
        return all(pending.ready() for pending in list(self._in_flight))

    def _seal(self, body: bytes) -> tuple[int, bytes]:
        if self._sealer is None:
            return -1, body
        seq = next_seq()
        return seq, self._sealer.seal_request(seq, body)

    def _open(self, seq: int, frame: bytes) -> bytes | memoryview | None:
        return frame if self._sealer is None else self._sealer.open_reply(seq, frame)

    def _finish(self, cmd: str, seq: int, pending: _Pending, deadline: float | None) -> dict:
        # blocks on the reply channel until the reply or the end of the query (zenoh's timeout, a death, or the
        # watchdog's cancel at the deadline); a waiting coordinator leaves the cores to the subsims
        try:
            forged, error = 0, None
            for reply in pending.all_replies():
                ok = reply.ok
                if ok is None:  # zenoh's timeout, or anyone's reply_err: no reason to stop waiting for the subsim's
                    error = reply
                    continue
                body = self._open(seq, ok.payload.to_bytes())
                if body is None:  # not sealed with this subsim's key for this request: not from our subsim
                    forged += 1
                    continue
                server = reply.replier_id.zid
                if self._server is None:
                    self._adopt(server)
                elif server != self._server and server in self._served:  # replaced earlier, woken up since
                    continue
                elif server != self._server and self._server_lost:  # its process died, and one started since
                    raise self._died_error("its process died, and the process now serving its name was started "
                                           "since (it holds none of this run's state)", cmd)
                elif server != self._server:  # sealed with its key: a second copy of this subsim, started by hand
                    raise SubsimError("duplicate", f"a second process answers as {self.name!r}, Zenoh id {server}, "
                                      f"besides the one this run uses, Zenoh id {self._server}: it was started "
                                      "twice; stop the copy (each says its id as it starts: 'serving run ... as "
                                      "Zenoh id ...')", self.name, cmd)
                try:
                    result = decode_reply(cmd, body)
                except VersionMismatch as exc:  # not a malformed reply: another cosim there
                    raise SubsimError("version", f"it speaks protocol {exc.version}, this coordinator "
                                      f"{PROTOCOL_VERSION}: run the same cosim version on its machine and here "
                                      "(cosim --version)", self.name, cmd) from None
                except ProtocolError as exc:
                    raise MalformedReply(exc.code, exc.message, self.name, cmd) from None
                if isinstance(result, ErrorInfo):
                    raise SubsimError(result.code, result.message, result.subsim,
                                      cmd if result.command == "?" else result.command, result.traceback)
                return result
            if error is not None and not pending.hung and not forged:
                raise self._zenoh_error(cmd, error, pending)
            raise self._no_reply(cmd, pending, deadline, forged)
        finally:
            self._in_flight.discard(pending)
            _WATCHDOG.forget(pending)

    def _zenoh_error(self, cmd: str, reply: zenoh.Reply, pending: _Pending) -> SubsimError:
        """What a Zenoh-level error reply means: zenoh's own timeout, or (well before it) a subsim's reply_err."""
        text = reply.err.payload.to_bytes().decode(errors="replace")
        early = pending.timeout_at - time.monotonic() > min(0.5, 0.1 * (pending.timeout_at - pending.sent))
        if early and not self._died.is_set():  # a queryable's reply_err (zenoh's timeout comes from a router too)
            return MalformedReply("bad_value", f"it answered with a Zenoh error reply ({text[:80]!r}) instead of a "
                                  "protocol reply; an error goes in a protocol reply, {\"ok\": false, \"error\": "
                                  "{...}} (docs/protocol.md 7)", self.name, cmd)
        if self._died.is_set():
            return self._died_error(DIED_MID_REQUEST, cmd, self._token_went(during=True))
        return self._lost_in_pause(cmd, pending) or self._timed_out(cmd, pending)

    def _timed_out(self, cmd: str, pending: _Pending) -> SubsimError:
        """Zenoh's own timeout ended the query: the process is stuck or stopped, as at a missed deadline (so its
        stop kills it at once instead of asking it to shut down and waiting out the graces)."""
        self.hung = True
        limit = round(pending.timeout_at - pending.sent, 3)
        return SubsimError("timeout", f"no reply within {limit:g} s (hung or stopped?)", self.name, cmd)

    def _lost_in_pause(self, cmd: str, pending: _Pending) -> SubsimHung | None:
        """The query timed out while this process was not running: the reply is lost, maybe not the subsim. It
        is replaced as a hung one would be (restored, bit-identical), and the error says whose the pause was."""
        paused = _WATCHDOG.paused_since(pending.sent)
        if paused <= 0.0:
            return None
        hung = SubsimHung("timeout", f"its reply was lost: this coordinator did not run for {paused:.1f} s during "
                          "the request (stopped, or starved of CPU) and the query timed out meanwhile", self.name, cmd)
        hung.pause = _WATCHDOG.long_pause(pending.sent, _Watchdog.PAUSE)  # (its losses are one failure, as SubsimLeft)
        return hung

    def _no_reply(self, cmd: str, pending: _Pending, deadline: float | None, forged: int) -> SubsimError:
        """Why the query ended without a genuine reply."""
        if pending.hung:
            self.hung = True
            return SubsimHung("timeout", f"no reply within the {deadline:g} s deadline (hung or stopped?)",
                              self.name, cmd)
        if forged:
            return SubsimError("unauthenticated", f"{forged} reply(ies) without this subsim's tag: is it running "
                               "with the key cosim gave it (COSIM_SECRET), and does it seal its replies as "
                               "docs/protocol.md 4.1 says (the tag covers the request's seq)?", self.name, cmd)
        # zero replies: nobody serves the key (not started, or died mid-request), or zenoh's timeout ended the
        # query without its error reply (seen under load)
        self._died.wait(0.5 if self._alive.is_set() else 0.0)
        if not self._died.is_set() and self._alive.is_set() and time.monotonic() >= pending.timeout_at:
            return self._lost_in_pause(cmd, pending) or self._timed_out(cmd, pending)
        if self._died.is_set():
            return self._died_error(DIED_MID_REQUEST, cmd, self._token_went(during=True))
        if self._alive.is_set():  # its token is up and the query ended: the process dropped it unanswered
            return self._died_error("its process ended the request without a reply (its token is still up): a subsim "
                                    "answers every request it admits with exactly one reply (docs/protocol.md 1)", cmd)
        return self._died_error("no process serves this subsim", cmd)

    def _token_went(self, during: bool) -> str:
        """Why its liveliness token went, for a process not known to have exited: it may not have."""
        when = " during the request" if during else ""
        why = " while its process still runs: its link" if self.exit_status is not None else \
            ": the process ended (Ctrl-C at its terminal, a kill, a crash), or its link"
        return f"its liveliness token went{when}{why} was silent for longer than its {self.lease:g} s lease (cut, or " \
               "the process stopped)"

    def _died_error(self, reason: str, cmd: str, unknown_exit: str | None = None) -> SubsimDied:
        """``reason``, with how the process ended where that is known; ``unknown_exit``: the reason instead where it
        is not (the process may still run)."""
        status = None if self.exit_status is None else self.exit_status()
        if status is None and unknown_exit is not None:
            reason = unknown_exit
        reason = reason if status is None else f"{reason}: {status}"
        pause = _WATCHDOG.long_pause(time.monotonic() - PAUSE_REMEMBERED, LEFT_AFTER * self.lease)
        if pause is not None and pause[0] > self._born and "killed by" not in (status or ""):
            # it did what a subsim does when its coordinator is silent that long: leave (by itself, not by a signal)
            return SubsimLeft("no_responder", f"{reason}; it left while this coordinator did not run for "
                              f"{pause[1] - pause[0]:.1f} s (stopped, or starved of CPU), as a subsim leaves a "
                              f"coordinator silent for {self.lease:g} s", self.name, cmd, pause)
        return SubsimDied("no_responder", reason, self.name, cmd)

    def close(self) -> None:
        for entity in (self._querier, self._liveliness):
            try:
                entity.undeclare()
            except Exception:
                pass
