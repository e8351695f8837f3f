"""The subsim contract both ends share: protocol version, commands, error codes and their exceptions.

The lowest layer (documented in docs/protocol.md): the runtime raises these errors, the wire
carries them, handles re-raise them on the coordinator side. No I/O, no encoding.
"""

from __future__ import annotations

PROTOCOL_VERSION = 1
VERSION = "0.1.0"  # this package's (cosim.__version__): both ends print it with the protocol's, to compare machines

COMMANDS = ("describe", "configure", "run_interval", "commit", "rollback", "get_state", "set_state", "status",
            "shutdown")

# code -> meaning
ERROR_CODES: dict[str, str] = {
    "decode": "payload is not a msgpack map, or not valid msgpack",
    "version": "protocol version missing or not supported",
    "unknown_command": "command name not known",
    "bad_request": "a field is missing, unknown, of the wrong type, or an array is malformed",
    "bad_value": "a field is well formed but out of contract (wrong size, NaN/inf, bad parameter)",
    "not_configured": "the subsim must be configured first",
    "time_mismatch": "the request's start time is not the committed time",
    "no_trial": "commit without a run_interval since the last commit or rollback",
    "stale_trial": "the latest trial did not start from the current committed state",
    "not_in_history": "rollback target time is not in the committed history",
    "model_error": "the model could not advance (e.g. a singularity); nothing committed changed",
    "too_long": "the model asks for a shorter interval (an FMU discarded its step); nothing committed changed",
    "model_exception": "the model raised an unexpected exception (a bug in it); the error carries its traceback; "
                       "nothing committed changed",
    "internal": "unexpected failure inside the subsim; nothing committed changed",
    "too_large": "the request is larger than the subsim's request cap; refused before decoding",
    "busy": "the subsim's request queue is full; the request was refused, nothing changed; retry later",
    "timeout": "no reply within the caller's timeout (raised coordinator-side)",
    "no_responder": "nobody serves this subsim's key, or the process died mid-request (coordinator-side)",
    "unauthenticated": "no reply carried this subsim's tag for the request (coordinator-side)",
    "duplicate": "a second process answers as this subsim: one started twice (coordinator-side)",
}
COORDINATOR_SIDE = frozenset({"timeout", "no_responder", "unauthenticated", "duplicate"})  # no subsim sends these


class CosimError(Exception):
    """An error with a protocol code; the runtime turns it into an error reply."""

    def __init__(self, code: str, message: str, traceback: str | None = None) -> None:
        super().__init__(message)
        self.code = code
        self.message = message
        self.traceback = traceback  # the model's own frames, for a model_exception


class ProtocolError(CosimError):
    """A message could not be decoded or does not match its schema."""


class SubsimError(RuntimeError):
    """Coordinator side: a command failed. Names the subsim, the command and the cause."""

    def __init__(self, code: str, message: str, subsim: str, command: str, traceback: str | None = None) -> None:
        super().__init__(f"{subsim}.{command}: [{code}] {message}")
        self.code = code
        self.message = message
        self.subsim = subsim
        self.command = command
        self.traceback = traceback  # the model's traceback as the subsim formatted it (model_exception)


class MalformedReply(SubsimError):
    """The subsim's reply breaks the protocol: undecodable, a Zenoh error reply, or not what its description and
    the request say (an output missing or misshapen, another t). Its implementation is at fault, not the request."""

    def __init__(self, code: str, message: str, subsim: str, command: str) -> None:
        super().__init__(code, f"malformed reply: {message}", subsim, command)


class SubsimDied(SubsimError):
    """The subsim process went away (liveliness lost or no responder)."""


class SubsimLeft(SubsimDied):
    """The subsim process left while this coordinator did not run (stopped, or starved of CPU) for longer than a
    subsim waits for it. ``pause``: that pause's (start, end), monotonic seconds: every subsim it made leave counts
    as one failure."""

    def __init__(self, code: str, message: str, subsim: str, command: str, pause: tuple[float, float]) -> None:
        super().__init__(code, message, subsim, command)
        self.pause = pause


class SubsimHung(SubsimError):
    """The subsim did not reply within the caller's deadline (stopped, stuck in its model, or cut off)."""
