"""Who may talk to a run: the run's secret, per-subsim keys, and the transport security settings.

No transport and no I/O beyond reading the files it is given. The request/reply tags themselves are
part of the codec (:mod:`cosim.protocol.messages`); see docs/reliability.md, "Security model".

* Every run has a 256-bit **master secret**. Each subsim gets only its own **key**, derived from the
  master secret, the run id and its name, so a subsim cannot sign for another one.
* Launched subsims receive their key (and the run's Zenoh login) through the **environment**
  (``COSIM_SECRET``, ``COSIM_ZENOH_AUTH``), never on the command line, which ``ps`` shows.
* :class:`Security` names the certificate and credential files that switch on TLS and
  user/password authentication for runs across machines.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import secrets
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import ssl

SECRET_ENV = "COSIM_SECRET"  # hex key of one subsim (64 hex digits)
ZENOH_AUTH_ENV = "COSIM_ZENOH_AUTH"  # "user:password" of the router's login
KEY_BYTES = 32


def new_master_secret() -> bytes:
    return secrets.token_bytes(KEY_BYTES)


def subsim_key(master: bytes, run: str, name: str, generation: int = 0) -> bytes:
    """The key subsim ``name`` of run ``run`` signs with: HMAC-SHA256(master, "cosim-subsim-key" 0 run 0 name), and
    for the ``generation``-th replacement the coordinator started, ... 0 name 0 generation: a replaced process
    that comes back to life can neither read its successor's requests nor answer them."""
    label = b"cosim-subsim-key\0" + run.encode() + b"\0" + name.encode()
    if generation:
        label += b"\0" + str(generation).encode()
    return hmac.new(master, label, hashlib.sha256).digest()


def zenoh_login(master: bytes, run: str, name: str | None = None) -> tuple[str, str]:
    """A Zenoh user and password of the run, derived from the master secret (nothing else to store): subsim
    ``name``'s own login, or with no name the run's shared one (a bus that did not know its subsims' names)."""
    if name is None:
        password = hmac.new(master, b"cosim-zenoh-password\0" + run.encode(), hashlib.sha256).hexdigest()
        return "cosim-" + run, password
    label = b"cosim-zenoh-subsim-password\0" + run.encode() + b"\0" + name.encode()
    return f"cosim-{run}.{name}", hmac.new(master, label, hashlib.sha256).hexdigest()


def parse_key(text: str, where: str = SECRET_ENV) -> bytes:
    try:
        key = bytes.fromhex(text.strip())
    except ValueError:
        raise ValueError(f"{where}: not hex; use the value cosim printed for this subsim") from None
    if len(key) != KEY_BYTES:
        raise ValueError(f"{where}: must be {2 * KEY_BYTES} hex digits, got {2 * len(key)}")
    return key


def parse_login(text: str, where: str) -> tuple[str, str]:
    user, sep, password = text.strip().partition(":")
    if not sep or not user or not password:
        raise ValueError(f"{where}: expected 'user:password'")
    return user, password


def read_login(path: Path) -> tuple[str, str]:
    """First ``user:password`` line of a credential file (a subsim's ``--auth-file``)."""
    for line in _lines(path):
        return parse_login(line, str(path))
    raise ValueError(f"{path}: no 'user:password' line")


def read_dictionary(path: Path) -> dict[str, str]:
    """Every ``user:password`` line of the router's dictionary (``cosim run --auth-file``)."""
    users = dict(parse_login(line, f"{path} line {i}") for i, line in enumerate(_lines(path), 1))
    if not users:
        raise ValueError(f"{path}: no 'user:password' line")
    return users


def _lines(path: Path) -> list[str]:
    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise ValueError(f"cannot read credential file {path}: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise ValueError(f"credential file {path} is not text: expected 'user:password' lines") from None
    return [ln.strip() for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]


@dataclass(frozen=True)
class Security:
    """Transport security of a run (coordinator side). All ``None``: loopback defaults (see below).

    ``tls_cert``/``tls_key``: the router's certificate and private key (PEM); with them the router
    listens on ``tls/`` endpoints. ``tls_ca``: the CA that signed it, handed to launched subsims, and
    with ``mutual`` also the CA that client certificates must chain to. ``auth_file``: ``user:password``
    lines that may log in besides the run's own generated login. ``admin_space``: open Zenoh's admin
    space (closed by default) to the coordinator's own session; access control still keeps clients
    out. Whatever is set, the router always requires a login and applies access control to the run's
    keys, and every request carries its subsim's tag.
    """

    tls_cert: Path | None = None
    tls_key: Path | None = None
    tls_ca: Path | None = None
    mutual: bool = False
    auth_file: Path | None = None
    admin_space: bool = False

    @property
    def tls(self) -> bool:
        return self.tls_cert is not None

    def check(self) -> Security:
        """Files exist and come in the pairs TLS needs; raises ``ValueError`` with one actionable line."""
        if (self.tls_cert is None) != (self.tls_key is None):
            raise ValueError("TLS needs both a certificate and its private key (--tls-cert and --tls-key)")
        if self.mutual and (self.tls_ca is None or not self.tls):
            raise ValueError("mutual TLS needs --tls-cert, --tls-key and --tls-ca (their CA)")
        for what, path in (("tls_cert", self.tls_cert), ("tls_key", self.tls_key), ("tls_ca", self.tls_ca),
                           ("auth_file", self.auth_file)):
            option = "--" + what.replace("_", "-")
            if path is not None and not Path(path).is_file():
                raise ValueError(f"{option} ({what} in [security]): "
                                 f"{'a directory, not a file' if Path(path).is_dir() else 'no such file'}: {path}")
        if self.auth_file is not None:
            read_dictionary(self.auth_file)
        return self


@dataclass(frozen=True)
class ClientSecurity:
    """What a subsim process needs to reach its coordinator: its key, a login, optionally TLS files."""

    key: bytes
    login: tuple[str, str] | None = None
    tls_ca: Path | None = None
    tls_cert: Path | None = None  # client certificate, for mutual TLS
    tls_key: Path | None = None

    @classmethod
    def from_env(
        cls,
        environ: dict[str, str] | None = None,
        auth_file: Path | None = None,
        tls_ca: Path | None = None,
        tls_cert: Path | None = None,
        tls_key: Path | None = None,
    ) -> ClientSecurity:
        env = os.environ if environ is None else environ
        text = env.get(SECRET_ENV)
        if not text:
            raise ValueError(f"{SECRET_ENV} is not set: start the subsim with the key cosim printed for it "
                             f"({SECRET_ENV}=<hex> python -m ...)")
        login = read_login(auth_file) if auth_file else None
        if login is None and env.get(ZENOH_AUTH_ENV):
            login = parse_login(env[ZENOH_AUTH_ENV], ZENOH_AUTH_ENV)
        if login is None:  # every run's router asks for one: without it the link was refused after 10 s, unnamed
            raise ValueError(f"{ZENOH_AUTH_ENV} is not set: start the subsim with the two variables cosim printed for "
                             f"it ({SECRET_ENV}=<hex> {ZENOH_AUTH_ENV}=<login> python -m ...), or a login of "
                             "--auth-file")
        if (tls_cert is None) != (tls_key is None):
            raise ValueError("a client certificate needs its private key (--tls-cert and --tls-key)")
        return cls(parse_key(text), login, tls_ca, tls_cert, tls_key)


# OpenSSL verify codes that Zenoh's rustls refuses as surely: no certificate of --tls-ca in the chain; another name
NO_ISSUER = (2, 20)  # X509_V_ERR_UNABLE_TO_GET_ISSUER_CERT(_LOCALLY)
NAME_MISMATCH = (62, 64)  # X509_V_ERR_HOSTNAME_MISMATCH, X509_V_ERR_IP_ADDRESS_MISMATCH


def verifying_context(ca: Path) -> ssl.SSLContext:
    """A client's TLS context that trusts ``ca`` as Zenoh's rustls does: any certificate of it is an anchor (an
    intermediate too). Raises ``ssl.SSLError`` for a file that holds no PEM certificate."""
    import ssl

    context = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    context.load_verify_locations(ca)
    context.verify_flags |= ssl.VERIFY_X509_PARTIAL_CHAIN
    return context


BASIC_CONSTRAINTS = bytes.fromhex("0603551d13")  # the OID 2.5.29.19 as DER puts it before the extension's value


def is_ca_certificate(der: bytes) -> bool:
    """Whether the DER certificate ``der`` says basicConstraints cA = TRUE. (Python's ssl shows no extension but the
    subjectAltName; the extension is read where its OID stands: [critical BOOLEAN], OCTET STRING { SEQUENCE { cA
    BOOLEAN, ... } }, with short lengths, as a basicConstraints always has.)"""
    at = der.find(BASIC_CONSTRAINTS)
    if at < 0:
        return False
    value = der[at + len(BASIC_CONSTRAINTS):]
    if value[:2] == b"\x01\x01":  # critical
        value = value[3:]
    return value[:1] == b"\x04" and value[2:3] == b"\x30" and value[4:6] == b"\x01\x01" and value[6:7] == b"\xff"


def rustls_refuses(peer: dict, der: bytes) -> str | None:
    """What Zenoh's rustls refuses in a router certificate that Python's ssl verified (``peer``: its
    ``getpeercert()``, ``der``: the same in DER), said after "the certificate": a CA's certificate as a server's own,
    and no DNS name or IP address in its subjectAltName (only in the subject's CN, or a URI). Else None."""
    if is_ca_certificate(der):
        return ("is a CA certificate (basicConstraints CA:TRUE, what 'openssl req -x509' makes unless told otherwise), "
                "which Zenoh's TLS refuses as a router's own: sign a router certificate with a CA "
                "(docs/reliability.md, Switching it on)")
    if not any(kind in ("DNS", "IP Address") for kind, _ in peer.get("subjectAltName", ())):
        return ("names no DNS name or IP address in a subjectAltName (a name in its subject's CN only, which Zenoh's "
                "TLS does not read): make it with -addext 'subjectAltName=DNS:<name>,IP:<address>'")
    return None


def tls_problem(cert: Path, key: Path, ca: Path | None, host: str | None) -> str | None:
    """Why a subsim given ``ca`` would refuse the router that shows ``cert`` (with ``key``) at ``host``, found by a TLS
    handshake between two contexts in memory (nothing sent); None when it would not. ``host`` None: no name checked
    (a router listening on every address is reached at one not known here). Without ``ca``, only the pair is
    checked. (A wrong CA or a certificate for another address was found only by the subsims, after 10 s, as a
    login or TLS refusal of any kind.)"""
    import ssl

    server = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    try:  # (an empty pass phrase: OpenSSL would ask for one on the terminal, and Zenoh reads none)
        server.load_cert_chain(cert, key, password=lambda: b"")
    except (ssl.SSLError, OSError) as exc:
        return (f"--tls-key {key} is not the unencrypted private key of --tls-cert {cert}, or one of them is no PEM "
                f"({getattr(exc, 'reason', None) or exc})")
    if ca is None:
        return None
    try:
        client = verifying_context(ca)
    except ssl.SSLError as exc:
        return f"--tls-ca {ca}: not a PEM certificate ({exc.reason})"
    client.check_hostname = host is not None
    to_server, to_client = ssl.MemoryBIO(), ssl.MemoryBIO()
    ends = (client.wrap_bio(to_client, to_server, server_hostname=host),
            server.wrap_bio(to_server, to_client, server_side=True))
    done = [False, False]
    for _ in range(8):  # a TLS 1.3 handshake takes 2-3 flights
        for i, end in enumerate(ends):
            try:
                end.do_handshake()
                done[i] = True
            except ssl.SSLWantReadError:
                pass
            except ssl.SSLCertVerificationError as exc:
                why = exc.verify_message or str(exc)
                if exc.verify_code in NAME_MISMATCH:
                    return f"--tls-cert {cert} is not for {host}, the address subsims are given: {why}"
                if exc.verify_code in NO_ISSUER:
                    return f"--tls-ca {ca} does not vouch for --tls-cert {cert}: {why}"
                return None  # where OpenSSL is stricter than Zenoh's rustls (an expired or plain root): Zenoh decides
            except ssl.SSLError:
                return None
        if all(done):
            why = rustls_refuses(ends[0].getpeercert(), ends[0].getpeercert(binary_form=True))
            return None if why is None else f"--tls-cert {cert} {why}"
    return None
