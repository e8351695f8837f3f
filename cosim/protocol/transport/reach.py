"""Why a subsim cannot reach its coordinator, in one line it can act on: found at once where it can be (a name that
does not resolve, a refused connection, a private bus that is gone), and after Zenoh's refusal by a TLS handshake of
our own (a certificate, a client certificate, TLS on one side only) or else the login."""

from __future__ import annotations

import socket

from cosim.protocol.security import NAME_MISMATCH, ZENOH_AUTH_ENV, ClientSecurity, rustls_refuses, verifying_context
from cosim.protocol.transport.session import UNIX_SOCKET, split_endpoint

_LOGIN_REFUSED = (f"it refused our login: ${ZENOH_AUTH_ENV} (or --auth-file) must be the one the coordinator printed "
                  "for this run and name, or it is not a cosim router")


def unreachable(endpoint: str, timeout: float) -> tuple[str | None, bool]:
    """(why nothing can be reached at a ``tcp/`` or ``tls/`` endpoint, found at once: a name that does not resolve,
    a refused or unroutable connection; whether a TCP connection opened). No reason when a connection opens,
    times out (a slow link: Zenoh goes on trying) or the endpoint is of another kind."""
    if endpoint.startswith(UNIX_SOCKET):  # a private bus of this machine
        path = endpoint[len(UNIX_SOCKET):].partition("#")[0]
        try:
            with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
                s.settimeout(timeout)
                s.connect(path)
            return None, True
        except (FileNotFoundError, ConnectionRefusedError):
            return f"nothing listens on {path} (its coordinator has ended?)", False
        except OSError:
            return None, True
    try:
        host, port = split_endpoint(endpoint.partition("#")[0])
    except ValueError:  # Zenoh says what is wrong with it
        return None, True
    host = host.strip("[]")
    if endpoint.partition("/")[0] not in ("tcp", "tls"):
        return None, True
    try:
        with socket.create_connection((host, port), timeout=timeout):
            return None, True
    except socket.gaierror as exc:
        return f"cannot resolve {host!r} ({exc.strerror})", False
    except ConnectionRefusedError:
        return (f"nothing listens on port {port} of {host} (connection refused): is the coordinator running, and "
                "is this the address and port it printed?"), False
    except TimeoutError:
        return None, False
    except OSError as exc:
        return f"{host}:{port} cannot be reached ({exc.strerror or exc})", False


def tls_cause(endpoint: str, security: ClientSecurity, timeout: float = 3.0) -> str:
    """Why a router that is there refused this subsim's link, found by a TLS handshake of our own (Python's ssl, as
    near as it comes to Zenoh's): the router's certificate against --tls-ca, a client certificate it asks for or
    refuses, TLS where tcp/ was given; else its login."""
    import ssl

    proto = endpoint.partition("/")[0]
    try:
        host, port = split_endpoint(endpoint.partition("#")[0])
    except ValueError:
        return _LOGIN_REFUSED
    host = host.strip("[]")
    if proto not in ("tcp", "tls"):
        return _LOGIN_REFUSED
    try:
        if proto == "tls" and security.tls_ca is not None:
            context = verifying_context(security.tls_ca)
        else:
            context = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
            if proto == "tcp":  # does it speak TLS there? (then tcp/ cannot work)
                context.check_hostname, context.verify_mode = False, ssl.CERT_NONE
            else:
                context.load_default_certs()
        if security.tls_cert is not None and security.tls_key is not None:  # (never ask for a pass phrase)
            context.load_cert_chain(security.tls_cert, security.tls_key, password=lambda: b"")
    except (ssl.SSLError, OSError) as exc:  # Zenoh took the files; say what Python's ssl makes of them
        return f"its login or TLS refused ours; --tls-ca, --tls-cert or --tls-key cannot be read as PEM ({exc})"
    try:
        raw = socket.create_connection((host, port), timeout=timeout)
    except OSError:  # gone meanwhile: the caller says so
        return _LOGIN_REFUSED
    try:
        with raw, context.wrap_socket(raw, server_hostname=host) as tls:
            if proto == "tcp":
                return f"it speaks TLS there: connect with tls/{host}:{port} and --tls-ca (the coordinator's CA)"
            refused = rustls_refuses(tls.getpeercert(), tls.getpeercert(binary_form=True) or b"")
            if refused is not None:  # Python's ssl took it, Zenoh's did not: the coordinator's side to fix
                return f"its certificate {refused}; the coordinator's operator must change it"
            tls.settimeout(0.5)  # TLS 1.3: a client certificate it asks for and does not take is refused after
            try:
                tls.recv(1)
            except (TimeoutError, ssl.SSLWantReadError):
                pass
    except ssl.SSLCertVerificationError as exc:
        why = exc.verify_message or str(exc)
        if exc.verify_code in NAME_MISMATCH:
            return f"its certificate is not for {host}, the address this subsim was given ({why}): use the name or " \
                   "address the coordinator printed"
        if security.tls_ca is None:
            return f"its certificate is not signed by a CA this machine trusts ({why}): give --tls-ca, the CA " \
                   "certificate of the coordinator's machine"
        return f"its certificate is not signed by --tls-ca {security.tls_ca} ({why}): get the CA certificate from " \
               "the coordinator's machine"
    except ssl.SSLError as exc:
        reason = (exc.reason or str(exc)).lower().replace("_", " ")
        if "wrong version" in reason or "record" in reason or "eof" in reason:  # no TLS there
            return _LOGIN_REFUSED if proto == "tcp" else f"it does not speak TLS there: connect with tcp/{host}:{port}"
        if security.tls_cert is None and ("certificate required" in reason or "handshake failure" in reason):
            return "it asks for a client certificate (mutual TLS): give --tls-cert and --tls-key, this machine's " \
                   "certificate signed by the coordinator's CA"
        if security.tls_cert is not None and "alert" in reason:  # (rustls: decrypt error, bad or unknown ca)
            return f"it refused this subsim's certificate, --tls-cert {security.tls_cert} ({exc.reason}): it must " \
                   "be signed by the CA the coordinator was given (its --tls-ca)"
        return f"the TLS handshake failed ({exc.reason or exc}): check tls/ against tcp/ and --tls-ca"
    except OSError:  # the connection closed or reset at our TLS hello
        return _LOGIN_REFUSED if proto == "tcp" else f"it does not speak TLS there: connect with tcp/{host}:{port}"
    return _LOGIN_REFUSED

