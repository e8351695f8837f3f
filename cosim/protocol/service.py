"""One request payload in, one reply payload out, for one runtime: the subsim side without a transport.

Any transport (Zenoh here; a test, a pipe, another bus) serves a subsim by calling :func:`answer`,
or, for sealed frames from a bus, through a :class:`Gate`: tag, replay and size checks where the transport
receives (cheap, nothing decoded), :func:`answer` on the serving thread.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Mapping
from typing import NamedTuple

from cosim.contract import PROTOCOL_VERSION, CosimError
from cosim.protocol.messages import (
    SEAL_BYTES,
    VersionMismatch,
    decode_request,
    encode_error,
    encode_result,
    request_command,
    sealer,
)
from cosim.runtime import Runtime
from cosim.subsim import Port

log = logging.getLogger(__name__)

# The default request cap: CAP_FACTOR times a run_interval of MAX_SAMPLES samples over every input
# port (t and the inputs, 8 bytes a value, plus envelope), never below CAP_FLOOR (configure's params).
MAX_SAMPLES = 10_000
CAP_FACTOR = 4
CAP_FLOOR = 1 << 20
# Sequence numbers accepted out of order, below the highest accepted (several coordinator threads may
# send to one subsim); each number is still accepted only once.
REPLAY_WINDOW = 1024


_told_versions: set[int] = set()  # the other protocol versions this process has said it does not speak


def answer(runtime: Runtime, payload: bytes | memoryview) -> bytes:
    """Turn one request payload into one reply payload. Never raises."""
    cmd = "?"
    try:
        request = decode_request(payload)
        cmd = request.cmd
        return encode_result(runtime.handle(request.cmd, request.args))
    except CosimError as exc:
        if cmd == "?":
            cmd = request_command(payload)
        if isinstance(exc, VersionMismatch) and exc.version not in _told_versions:  # said here too, once: this
            _told_versions.add(exc.version)  # side's operator sees only "the coordinator left" otherwise
            log.warning("%s: refused a request in protocol %s, this subsim speaks %s: if your coordinator sent it, "
                        "run the same cosim version on both machines (cosim --version); python -m cosim.conformance "
                        "sends one on purpose", runtime.name, exc.version, PROTOCOL_VERSION)
        return encode_error(exc.code, exc.message, runtime.name, cmd, exc.traceback)
    except Exception as exc:  # last line of defence: the process must survive any request
        log.exception("unexpected failure serving %s", cmd)
        return encode_error("internal", f"{type(exc).__name__}: {exc}", runtime.name, cmd)


def default_request_cap(inputs: Mapping[str, Port]) -> int:
    """Bytes a request may have: a few times the largest legitimate ``run_interval`` for these ports."""
    values = MAX_SAMPLES * (1 + sum(p.size for p in inputs.values()))
    return max(CAP_FLOOR, CAP_FACTOR * (8 * values + 256 * (1 + len(inputs))))


class Admitted(NamedTuple):  # a tuple: a fraction of a frozen dataclass's cost, one per request
    """A request whose size and tag passed; ``seq`` is -1 when the gate has no key."""

    seq: int
    body: bytes | memoryview


class Gate:
    """The subsim's door for sealed frames (docs/protocol.md 4.1).

    :meth:`admit` runs where the transport receives, one frame at a time in arrival order, must never block
    and decodes nothing: a frame without this subsim's tag is dropped without a word, and so is a replay (a
    sequence number accepted before, or ``REPLAY_WINDOW`` or more below the highest accepted), before its
    size is looked at or a queue could answer it ``busy``; a frame over the cap gets a ``too_large`` reply.
    :meth:`answer` decodes and answers an admitted request on the serving thread. ``key=None`` turns
    sealing off (frames are bare request bodies), for transports that authenticate otherwise.
    ``counts`` tallies what happened (admitted, dropped, replayed, too_large, busy).
    """

    def __init__(self, runtime: Runtime, key: bytes | None, max_request: int | None = None) -> None:
        self.runtime, self.key, self.max_request = runtime, key, max_request
        self._sealer = None if key is None else sealer(key)
        self._cap_inputs: Mapping[str, Port] | None = None  # the ports the cached default cap is for
        self._default_cap = 0
        self.last_seq = -1  # the highest sequence number accepted
        self._recent: set[int] = set()  # those accepted within the window below it
        self.counts: Counter[str] = Counter()

    @property
    def cap(self) -> int:
        if self.max_request is not None:
            return self.max_request
        inputs = self.runtime.inputs  # replaced, never changed in place, when a configure changes the ports
        if inputs is not self._cap_inputs:
            self._cap_inputs, self._default_cap = inputs, default_request_cap(inputs)
        return self._default_cap

    def admit(self, frame: bytes) -> tuple[Admitted | None, bytes | None]:
        """``(request, None)`` to queue; ``(None, reply)`` to send at once; ``(None, None)`` to drop."""
        if self._sealer is None:
            seq, body = -1, frame
        else:
            opened = self._sealer.open_request(frame)
            if opened is None:
                self.counts["dropped"] += 1
                return None, None
            seq, body = opened
            if not self._fresh(seq):
                self.counts["replayed"] += 1
                return None, None
        cap = self.cap
        if len(body) > cap:
            self.counts["too_large"] += 1
            msg = f"request of {len(body)} bytes is over this subsim's cap of {cap} bytes; raise it with --max-request"
            return None, self._error(seq, "too_large", msg)
        self.counts["admitted"] += 1
        return Admitted(seq, body), None

    def answer(self, request: Admitted) -> bytes:
        """The (sealed) reply to an admitted request."""
        seq, body = request
        if self._sealer is None:
            return answer(self.runtime, body)
        return self._sealer.seal_reply(seq, answer(self.runtime, body))

    def _fresh(self, seq: int) -> bool:
        """Accept ``seq`` once, and only within the window below the highest accepted."""
        if seq > self.last_seq:
            self.last_seq = seq
            self._recent.add(seq)
            if len(self._recent) > 2 * REPLAY_WINDOW:
                self._recent = {s for s in self._recent if s > seq - REPLAY_WINDOW}
            return True
        if seq <= self.last_seq - REPLAY_WINDOW or seq in self._recent:
            return False
        self._recent.add(seq)
        return True

    def busy(self, request: Admitted, queued: int) -> bytes:
        self.counts["busy"] += 1
        return self._error(request.seq, "busy", f"{queued} requests already queued; refused, nothing changed")

    def _error(self, seq: int, code: str, message: str) -> bytes:
        return self._seal(seq, encode_error(code, message, self.runtime.name, "?"))

    def _seal(self, seq: int, body: bytes) -> bytes:
        return body if self._sealer is None else self._sealer.seal_reply(seq, body)


__all__ = ["SEAL_BYTES", "Admitted", "Gate", "answer", "default_request_cap"]
