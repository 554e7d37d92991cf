"""X.509 and Ed25519 key material, made with the ``cryptography`` library (no shell-outs).

One CA per swarm signs one TLS certificate per process identity (CN = identity name, SANs
for loopback and the configured hosts, serverAuth + clientAuth, because in a Zenoh peer
mesh every node both listens and connects). TLS keys are ECDSA P-256: fast to make (a
fresh per-run swarm for ``aeroweaver sim`` costs milliseconds) and accepted by rustls.
Message signing keys are separate Ed25519 keys, so a leaked TLS key does not let anyone
author messages and vice versa. Private keys are written 0600 (atomically, never readable
by others even for an instant).
"""

from __future__ import annotations

import datetime as dt
import hashlib
import ipaddress
import os
import tempfile
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from cryptography import x509
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec, ed25519
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from aeroweaver_edge.security.key_files import PkiError, load_private_key, read_private

DEFAULT_HOSTS: tuple[str, ...] = ("127.0.0.1", "localhost", "::1")


@dataclass(frozen=True)
class CertifiedKey:
    """A certificate and its private key (PEM bytes)."""

    cert_pem: bytes
    key_pem: bytes

    @property
    def cert(self) -> x509.Certificate:
        return x509.load_pem_x509_certificate(self.cert_pem)


def _now() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


def _key_pem(key: ec.EllipticCurvePrivateKey | ed25519.Ed25519PrivateKey) -> bytes:
    return key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )


def _key_usage(*, cert_sign: bool) -> x509.KeyUsage:
    """CA: signs certificates; end entity: signs the TLS handshake (ECDHE key agreement)."""
    return x509.KeyUsage(
        digital_signature=True,
        content_commitment=False,
        key_encipherment=False,
        data_encipherment=False,
        key_agreement=not cert_sign,
        key_cert_sign=cert_sign,
        crl_sign=cert_sign,
        encipher_only=False,
        decipher_only=False,
    )


def make_ca(swarm: str, days: int = 365) -> CertifiedKey:
    """A self-signed CA that may sign end-entity certificates only (path length 0)."""
    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name(
        [
            x509.NameAttribute(NameOID.ORGANIZATION_NAME, "AeroWeaver-edge"),
            x509.NameAttribute(NameOID.COMMON_NAME, f"aeroweaver swarm {swarm} CA"),
        ]
    )
    now = _now()
    cert = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - dt.timedelta(minutes=5))
        .not_valid_after(now + dt.timedelta(days=days))
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(_key_usage(cert_sign=True), critical=True)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .sign(key, hashes.SHA256())
    )
    return CertifiedKey(cert.public_bytes(serialization.Encoding.PEM), _key_pem(key))


def _san(hosts: Iterable[str]) -> x509.SubjectAlternativeName:
    names: list[x509.GeneralName] = []
    seen: set[str] = set()
    for host in hosts:
        if not host or host in seen:
            continue
        seen.add(host)
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(host)))
        except ValueError:
            names.append(x509.DNSName(host))
    return x509.SubjectAlternativeName(names)


def issue(
    ca: CertifiedKey, common_name: str, hosts: Iterable[str] = DEFAULT_HOSTS, days: int = 30
) -> CertifiedKey:
    """A TLS certificate for one identity: CN = its name, usable as server and as client."""
    ca_key = serialization.load_pem_private_key(ca.key_pem, password=None)
    if not isinstance(ca_key, ec.EllipticCurvePrivateKey):
        raise PkiError("the CA key is not an ECDSA key")
    ca_cert = ca.cert
    key = ec.generate_private_key(ec.SECP256R1())
    now = _now()
    cert = (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name)]))
        .issuer_name(ca_cert.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - dt.timedelta(minutes=5))
        .not_valid_after(min(now + dt.timedelta(days=days), ca_cert.not_valid_after_utc))
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(_key_usage(cert_sign=False), critical=True)
        .add_extension(
            x509.ExtendedKeyUsage(
                [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
            ),
            critical=False,
        )
        .add_extension(_san(hosts), critical=False)
        .add_extension(
            x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_cert.public_key()),  # type: ignore[arg-type]
            critical=False,
        )
        .sign(ca_key, hashes.SHA256())
    )
    return CertifiedKey(cert.public_bytes(serialization.Encoding.PEM), _key_pem(key))


def make_signing_key() -> ed25519.Ed25519PrivateKey:
    return ed25519.Ed25519PrivateKey.generate()


def signing_key_pem(key: ed25519.Ed25519PrivateKey) -> bytes:
    return _key_pem(key)


def raw_public(key: ed25519.Ed25519PrivateKey | ed25519.Ed25519PublicKey) -> bytes:
    pub = key.public_key() if isinstance(key, ed25519.Ed25519PrivateKey) else key
    return pub.public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)


def fingerprint(data: bytes) -> str:
    """Short hex fingerprint of a public key or a DER certificate (SHA-256, 16 hex digits)."""
    return hashlib.sha256(data).hexdigest()[:16]


def cert_fingerprint(cert_pem: bytes) -> str:
    cert = x509.load_pem_x509_certificate(cert_pem)
    return fingerprint(cert.public_bytes(serialization.Encoding.DER))


def load_signing_key(path: Path) -> ed25519.Ed25519PrivateKey:
    """The message-signing key, checked like ssh checks a key (``key_files``)."""
    key = load_private_key(path, "signing key")
    if not isinstance(key, ed25519.Ed25519PrivateKey):
        raise PkiError(f"{path}: not an Ed25519 private key (a signing key is Ed25519)")
    return key


def load_tls_key(key_path: Path, cert: x509.Certificate, cert_path: Path) -> None:
    """The TLS private key is private, parses, and belongs to ``cert`` (Zenoh reads the file
    itself, so this is the one place a wrong or leaked key is caught with its name)."""
    key = load_private_key(key_path, "TLS private key")
    if not isinstance(key, ec.EllipticCurvePrivateKey) or raw_pub_der(key) != cert_pub_der(cert):
        raise PkiError(f"{key_path}: not the private key of {cert_path}")


def load_cert(path: Path) -> x509.Certificate:
    try:
        return x509.load_pem_x509_certificate(_read(path))
    except ValueError as exc:
        raise PkiError(f"{path}: not a PEM certificate ({exc})") from None


def load_ca(cert_path: Path, key_path: Path) -> CertifiedKey:
    ca = CertifiedKey(_read(cert_path), read_private(key_path, "CA private key"))
    try:
        key = serialization.load_pem_private_key(ca.key_pem, password=None)
        cert = ca.cert
    except ValueError as exc:
        raise PkiError(f"{key_path}: unreadable CA material ({exc})") from None
    if not isinstance(key, ec.EllipticCurvePrivateKey) or raw_pub_der(key) != cert_pub_der(cert):
        raise PkiError(f"{key_path}: does not match {cert_path}")
    return ca


def raw_pub_der(key: ec.EllipticCurvePrivateKey) -> bytes:
    return key.public_key().public_bytes(
        serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo
    )


def cert_pub_der(cert: x509.Certificate) -> bytes:
    return cert.public_key().public_bytes(
        serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo
    )


def common_name(cert: x509.Certificate) -> str:
    attrs = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    return str(attrs[0].value) if attrs else ""


def verify_issued_by(cert: x509.Certificate, ca: x509.Certificate) -> bool:
    """True if ``cert`` carries a valid signature by ``ca`` (chain of one)."""
    try:
        cert.verify_directly_issued_by(ca)
    except (InvalidSignature, ValueError, TypeError):
        return False
    return True


def _read(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise PkiError(f"{path}: cannot read: {exc.strerror or exc}") from None


def write_file(path: Path, data: bytes, *, private: bool = False) -> None:
    """Write atomically (temp file, fsync, rename, fsync the directory). A private file is
    created 0600 from the start, so it is never readable by anyone else, not even briefly."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        os.fchmod(fd, 0o600 if private else 0o644)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    dir_fd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(dir_fd)
    finally:
        os.close(dir_fd)
