"""End-to-end payload signatures (Ed25519) carried in the Zenoh attachment.

The signature covers a domain tag, the key expression and the exact payload bytes as sent::

    sign(b"aeroweaver/1\\0" + key + b"\\0" + payload)

and travels as the sample's attachment: ``version (1 byte) | key id (8) | signature (64)``.

Why the attachment and not a field in the payload: the receiver verifies the bytes it
received, with no re-encoding and no canonical-form pitfalls; no payload schema changes,
so an unsigned (``--insecure``) swarm runs the same structs; and the header inside the
payload (sender, boot epoch, sequence) is covered, so the epoch is authenticated. Covering
the key binds a message to its topic (a valid message moved to another key fails).

A payload is accepted only if it is signed by the key registered for its claimed sender
(``h.sender``) in the CA-signed identity list and that sender may write the key (the same
table as the Zenoh ACL). A relay or router that forwards traffic cannot forge either.
"""

from __future__ import annotations

from dataclasses import dataclass

from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives.asymmetric import ed25519

from aeroweaver_edge.security.identity import IdentityList
from aeroweaver_edge.security.pki import fingerprint, raw_public
from aeroweaver_edge.security.policy import Authorizer

VERSION = 1
_DOMAIN = b"aeroweaver/1\x00"
_KEY_ID_BYTES = 8
_SIG_BYTES = 64
ATTACHMENT_BYTES = 1 + _KEY_ID_BYTES + _SIG_BYTES
_MAY_CACHE = 4096  # (signer, key) write decisions remembered


def key_id(public_raw: bytes) -> bytes:
    return bytes.fromhex(fingerprint(public_raw))[:_KEY_ID_BYTES]


def _message(key: str, payload: bytes) -> bytes:
    return b"".join((_DOMAIN, key.encode(), b"\x00", payload))


class Signer:
    """Signs what one identity publishes."""

    def __init__(self, name: str, key: ed25519.Ed25519PrivateKey) -> None:
        self.name = name
        self._key = key
        self._key_id = key_id(raw_public(key))

    def sign(self, key: str, payload: bytes) -> bytes:
        """The attachment for ``payload`` published on ``key``."""
        return bytes((VERSION,)) + self._key_id + self._key.sign(_message(key, payload))


class Verifier:
    """Checks attachments against the swarm's identity list and write permissions."""

    def __init__(self, identities: IdentityList, authorizer: Authorizer | None = None) -> None:
        self.identities = identities
        self.authorizer = authorizer or Authorizer(identities.swarm, identities.roles())
        self._keys: dict[str, dict[bytes, ed25519.Ed25519PublicKey]] = {}
        self._may: dict[tuple[str, str], bool] = {}
        self._by_key_id: dict[bytes, str] = {}  # key id -> identity, for the cheap checks
        for name, member in identities.members.items():
            pub = ed25519.Ed25519PublicKey.from_public_bytes(member.signing_key)
            kid = key_id(member.signing_key)
            self._keys[name] = {kid: pub}
            self._by_key_id[kid] = name

    def signer_of(self, attachment: bytes | None) -> tuple[str | None, str | None]:
        """The cheap checks, before any decoding or crypto: ``(signer, None)`` when the
        attachment is well formed and names a key id of the identity list; else ``(None,
        reason)``. A dict lookup, so a flood is refused here for almost nothing."""
        if not attachment:
            return None, "unsigned"
        if len(attachment) != ATTACHMENT_BYTES or attachment[0] != VERSION:
            return None, "bad_attachment"
        signer = self._by_key_id.get(attachment[1 : 1 + _KEY_ID_BYTES])
        if signer is None:
            return None, "wrong_key"  # no identity of the list holds that key
        return signer, None

    def may_write(self, signer: str, key: str) -> bool:
        """``Authorizer.may_write``, remembered (see ``_may_write``)."""
        return self._may_write(signer, key)

    def name_of_key_id(self, kid: bytes) -> str | None:
        """The identity that signs with key id ``kid``, if any (thread-safe: read only)."""
        return self._by_key_id.get(kid)

    def _may_write(self, signer: str, key: str) -> bool:
        """``authorizer.may_write`` remembered per (signer, key): a flood repeats its keys,
        and parsing a key expression costs more than the rest of the cheap checks."""
        known = self._may.get((signer, key))
        if known is None:
            if len(self._may) >= _MAY_CACHE:
                self._may.clear()
            known = self._may[(signer, key)] = self.authorizer.may_write(signer, key)
        return known

    def verify(self, key: str, payload: bytes, attachment: bytes, sender: str) -> str | None:
        """The expensive part: the Ed25519 signature of ``sender`` (whose key id the
        attachment must carry) over ``key`` and ``payload``. None if valid."""
        keys = self._keys.get(sender)
        if keys is None:
            return "unknown_signer"
        pub = keys.get(attachment[1 : 1 + _KEY_ID_BYTES])
        if pub is None:
            return "wrong_key"
        try:
            pub.verify(attachment[1 + _KEY_ID_BYTES :], _message(key, payload))
        except InvalidSignature:
            return "bad_signature"
        return None

    def check(self, key: str, payload: bytes, attachment: bytes | None, sender: str) -> str | None:
        """``None`` if authentic and authorised; otherwise the reason it is not."""
        if not attachment:
            return "unsigned"
        if len(attachment) != ATTACHMENT_BYTES or attachment[0] != VERSION:
            return "bad_attachment"
        if sender not in self._keys:
            return "unknown_signer"
        why = self.verify(key, payload, attachment, sender)
        if why is not None:
            return why
        if not self.authorizer.may_write(sender, key):
            return "unauthorised_signer"
        return None


@dataclass(frozen=True)
class MessageAuth:
    """What a Mesh needs: a signer (None: this process publishes nothing signed, e.g. an
    observer) and a verifier; every payload received must pass ``verifier.check``."""

    verifier: Verifier
    signer: Signer | None = None

    @property
    def identity(self) -> str | None:
        return self.signer.name if self.signer else None
