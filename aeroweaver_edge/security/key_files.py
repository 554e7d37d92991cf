"""Private key files are checked the way ssh checks them, before a byte is used.

A private key (TLS key, Ed25519 signing key, the CA key) must be a regular file owned by
this user or root and not accessible by group or others (mode 0600 or 0400): a key others
can read is as good as published, so it is refused with the file and the fix (``chmod
600``), never used with a warning. One exception: a file carrying a POSIX ACL, where the
mode's group bits are the ACL mask; systemd's ``LoadCredential=`` grants the service user
read access that way (root-owned, ``user:<svc>:r``). Others still get nothing.

An empty, truncated or foreign file is one ``PkiError`` naming the file and what it should
hold, not a ``ValueError`` from the crypto library.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from cryptography.exceptions import UnsupportedAlgorithm
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.types import PrivateKeyTypes

MAX_KEY_BYTES = 64 * 1024
"""A PEM private key is a few hundred bytes; anything this large is not one."""

_ACL_XATTR = "system.posix_acl_access"


class PkiError(ValueError):
    """Key material is missing, malformed or does not fit together; the message says which."""


def _has_acl(path: Path) -> bool:
    try:
        return bool(os.getxattr(path, _ACL_XATTR))
    except OSError:  # no ACL, or a file system without xattrs
        return False


def check_private(path: Path, what: str) -> os.stat_result:
    """Refuse a key file that others may read or write; returns its ``stat``."""
    try:
        st = path.stat()
    except OSError as exc:
        raise PkiError(f"{path}: cannot read the {what}: {exc.strerror or exc}") from None
    if not stat.S_ISREG(st.st_mode):
        raise PkiError(f"{path}: the {what} must be a regular file")
    mode = stat.S_IMODE(st.st_mode)
    loose = mode & 0o007 or (mode & 0o070 and not _has_acl(path))
    if loose:
        raise PkiError(
            f"{path}: the {what} is accessible by group/others (mode {mode:04o}); chmod 600 {path}"
        )
    if st.st_uid not in (os.geteuid(), 0):
        raise PkiError(
            f"{path}: the {what} is owned by uid {st.st_uid}, not by this user or root; "
            f"chown it to the user that runs this process"
        )
    return st


def read_private(path: Path, what: str) -> bytes:
    """The bytes of a checked private key file (non-empty, bounded)."""
    st = check_private(path, what)
    if st.st_size > MAX_KEY_BYTES:
        raise PkiError(f"{path}: {st.st_size} bytes is no {what} (a PEM key is under 1 KiB)")
    try:
        data = path.read_bytes()[: MAX_KEY_BYTES + 1]
    except OSError as exc:
        raise PkiError(f"{path}: cannot read the {what}: {exc.strerror or exc}") from None
    if not data.strip():
        raise PkiError(
            f"{path}: the {what} is empty; restore it from the swarm directory "
            "(aeroweaver keys rotate NAME makes a new one)"
        )
    return data


def load_private_key(path: Path, what: str) -> PrivateKeyTypes:
    """A checked, parsed PEM private key (unencrypted PKCS#8, as ``keys init`` writes)."""
    data = read_private(path, what)
    try:
        return serialization.load_pem_private_key(data, password=None)
    except (ValueError, TypeError, UnsupportedAlgorithm) as exc:
        why = str(exc).split("\n", 1)[0][:120] or type(exc).__name__
        raise PkiError(
            f"{path}: not a PEM private key ({why}); the {what} is damaged or the wrong "
            "file: restore it, or aeroweaver keys rotate NAME"
        ) from None


__all__ = ["MAX_KEY_BYTES", "check_private", "load_private_key", "read_private"]
