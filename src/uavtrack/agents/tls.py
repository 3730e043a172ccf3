"""The TLS files of a swarm, checked before Zenoh starts, by the program that holds them.

Zenoh reads its TLS files when it opens a link, and a certificate the other side refuses
(expired, not valid yet, signed by another CA) shows only as connections that time out,
on the side that did not cause them. So the world and every program check their own
files first and name the one at fault, in one line:

* ``--tls-ca``: PEM certificates, each valid now (not before <= now <= not after);
* ``--tls-cert``: this host's certificate (first in the file, possibly followed by
  intermediates), valid now, and issued by a certificate of the CA file through those
  intermediates: its issuer's name is the CA's subject and the CA's key verifies its
  signature (`cryptography`'s ``verify_directly_issued_by``);
* ``--tls-key``: an unencrypted PEM private key, the key of that certificate (the same
  public key), and private to its owner (`security.check_private`, as ssh asks of a key).

Only uavtrack's own TLS options are checked; TLS files named in a ``--zenoh-config`` are
Zenoh's to read.
"""

from __future__ import annotations

import datetime
import os
from pathlib import Path

from .security import check_private

TLS_SCHEMES = ("tls", "quic")
"""Zenoh endpoints secured by the TLS files (quic/ runs TLS 1.3 inside)."""


def clear_endpoint(endpoints: list[str]) -> str | None:
    """The first endpoint that TLS files would not secure (tcp/, udp/, ...), or None."""
    for endpoint in endpoints:
        scheme = endpoint.strip().split("/", 1)[0]
        if endpoint.strip() and scheme not in TLS_SCHEMES:
            return endpoint.strip()
    return None


def refuse_clear(endpoints: list[str]) -> None:
    """ValueError when TLS files come with an endpoint they do not secure: it would run in
    clear text, and say nothing."""
    clear = clear_endpoint(endpoints)
    if clear is not None:
        secured = "tls/" + clear.split("/", 1)[-1]
        raise ValueError(
            f"--tls-ca, --tls-cert and --tls-key secure tls/ endpoints, and {clear} would run "
            f"in clear text: use {secured}"
        )


def _certificates(option: str, path: str) -> list:
    from cryptography import x509

    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise ValueError(f"{option}: cannot read {path}: {exc.strerror}") from None
    try:
        found = x509.load_pem_x509_certificates(data)
    except ValueError:
        found = []
    if not found:
        raise ValueError(f"{option}: {path} holds no PEM certificate")
    return found


def _in_date(option: str, path: str, certificate, now: datetime.datetime) -> None:
    name = certificate.subject.rfc4514_string() or "a certificate"
    after, before = certificate.not_valid_after_utc, certificate.not_valid_before_utc
    if now > after:
        raise ValueError(f"{option}: {path} ({name}) expired on {after:%Y-%m-%d %H:%M} UTC")
    if now < before:
        raise ValueError(
            f"{option}: {path} ({name}) is not valid before {before:%Y-%m-%d %H:%M} UTC "
            "(or this machine's clock is wrong)"
        )


def _issued_by(certificate, issuer) -> bool:
    from cryptography.exceptions import InvalidSignature

    try:
        certificate.verify_directly_issued_by(issuer)
    except (ValueError, TypeError, InvalidSignature):
        return False
    return True


def _chains(leaf, intermediates: list, roots: list) -> bool:
    """Whether `leaf` is issued by a root, directly or through the intermediates."""
    current, left = leaf, list(intermediates)
    for _ in range(len(intermediates) + 1):
        if any(_issued_by(current, root) for root in roots):
            return True
        step = next((c for c in left if _issued_by(current, c)), None)
        if step is None:
            return False
        left.remove(step)
        current = step
    return False


def check(ca: str, cert: str, key: str, now: datetime.datetime | None = None) -> None:
    """ValueError naming the option, the file and what is wrong with this host's TLS
    files (see the module docstring); `now` defaults to this machine's UTC time."""
    from cryptography.hazmat.primitives import serialization

    now = now or datetime.datetime.now(datetime.UTC)
    roots = _certificates("--tls-ca", ca)
    for root in roots:
        _in_date("--tls-ca", ca, root, now)
    chain = _certificates("--tls-cert", cert)
    for member in chain:
        _in_date("--tls-cert", cert, member, now)
    if not _chains(chain[0], chain[1:], roots):
        raise ValueError(f"--tls-cert: {cert} is not signed by the CA of --tls-ca {ca}")
    try:
        fd = os.open(key, os.O_RDONLY)
    except OSError as exc:
        raise ValueError(f"--tls-key: cannot read {key}: {exc.strerror}") from None
    with os.fdopen(fd, "rb") as handle:
        try:
            check_private(key, os.fstat(handle.fileno()).st_mode)
        except ValueError as exc:
            raise ValueError(f"--tls-key: {exc}") from None
        data = handle.read()
    try:
        private = serialization.load_pem_private_key(data, password=None)
    except (ValueError, TypeError):
        raise ValueError(f"--tls-key: {key} is not an unencrypted PEM private key") from None
    spki = serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo
    if private.public_key().public_bytes(*spki) != chain[0].public_key().public_bytes(*spki):
        raise ValueError(f"--tls-key: {key} is not the key of --tls-cert {cert}")
