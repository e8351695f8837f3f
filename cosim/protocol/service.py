"""One request payload in, one reply payload out, for one runtime: the subsim side without a transport.

Any transport (Zenoh here; a test, a pipe, another bus) serves a subsim by calling :func:`answer`.
"""

from __future__ import annotations

import logging

from cosim.contract import CosimError
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
