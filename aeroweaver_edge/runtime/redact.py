"""Credentials never reach a log line or a terminal: the one helper for printing URLs.

An operator may put a key in a base URL (``https://user:key@host/v1`` or
``...?api_key=...``). Anything that prints or logs a URL goes through ``redact_url``;
free text that may embed one (exception messages) goes through ``redact_text``. Libraries
log URLs themselves (httpx: every request at INFO, shown under ``-v``), so their loggers
carry ``RedactingFilter``, which also masks the literal secrets clients registered.
"""

from __future__ import annotations

import logging
import re
import threading
from typing import Final
from urllib.parse import parse_qsl, urlencode, urlsplit, urlunsplit

MASK: Final = "***"
# Query parameters whose values are secrets (compared case-insensitively, '-' == '_').
SECRET_PARAMS: Final = frozenset(
    {
        "api_key", "apikey", "key", "token", "access_token", "auth", "authorization",
        "password", "pass", "pwd", "secret", "client_secret", "sig", "signature",
        "x_api_key", "code", "session", "sessionid", "credential", "credentials",
    }
)  # fmt: skip
_URL = re.compile(r"\b[a-zA-Z][a-zA-Z0-9+.-]*://[^\s'\"<>]+")


def _secret(name: str) -> bool:
    return name.lower().replace("-", "_") in SECRET_PARAMS


def redact_url(url: str) -> str:
    """``url`` with user info and secret query values masked; anything unparsable is
    masked whole rather than risked."""
    try:
        parts = urlsplit(url)
        host = parts.hostname or ""
        port = f":{parts.port}" if parts.port is not None else ""
    except ValueError:
        return MASK
    netloc = parts.netloc
    if parts.username is not None or parts.password is not None:
        if ":" in host:  # IPv6 literal
            host = f"[{host}]"
        netloc = f"{MASK}@{host}{port}"
    query = parts.query
    if query:
        pairs = parse_qsl(query, keep_blank_values=True)
        if any(_secret(k) for k, _ in pairs):
            query = urlencode([(k, MASK if _secret(k) else v) for k, v in pairs], safe="*")
    return urlunsplit((parts.scheme, netloc, parts.path, query, parts.fragment))


def redact_text(text: str) -> str:
    """Every URL inside ``text`` redacted (for error messages from libraries)."""

    def one(match: re.Match[str]) -> str:
        url = match.group(0)
        core = url.rstrip(".,:;)]}")
        return redact_url(core) + url[len(core) :]

    return _URL.sub(one, text)


def url_secrets(url: str) -> list[str]:
    """The literal secret strings inside ``url`` (password, user, secret query values),
    so text that echoes them without the URL around it can be scrubbed too."""
    try:
        parts = urlsplit(url)
        found = [parts.password or "", parts.username or ""]
        found += [v for k, v in parse_qsl(parts.query, keep_blank_values=True) if _secret(k)]
    except ValueError:
        return []
    return [s for s in found if len(s) >= 4]  # never mask every "a" in a message


def scrub(text: str, secrets: list[str]) -> str:
    """``text`` with URLs redacted and each literal secret replaced by the mask."""
    text = redact_text(text)
    for secret in sorted(secrets, key=len, reverse=True):
        text = text.replace(secret, MASK)
    return text


_registered: set[str] = set()
_lock = threading.Lock()

HTTP_LOGGERS: Final = (
    "httpx", "httpcore", "httpcore.connection", "httpcore.http11", "httpcore.http2",
    "httpcore.proxy", "httpcore.socks", "hpack", "urllib3", "urllib3.connectionpool",
)  # fmt: skip
"""Loggers of the HTTP libraries (a logger filter sees only its own logger's records)."""


def register_secrets(secrets: list[str]) -> None:
    """Literal secrets (API keys, URL passwords) every filtered log line masks."""
    with _lock:
        _registered.update(s for s in secrets if len(s) >= 4)


class RedactingFilter(logging.Filter):
    """Formats the record once and replaces it by its redacted text (URLs with user info or
    secret query values masked, registered secrets masked). Never drops a record."""

    def filter(self, record: logging.LogRecord) -> bool:
        try:
            message = record.getMessage()
        except Exception:  # a broken format string: leave it to logging's own handling
            return True
        with _lock:
            secrets = list(_registered)
        cleaned = scrub(message, secrets)
        if cleaned != message or record.args:
            record.msg, record.args = cleaned, None
        return True


_FILTER = RedactingFilter()


def install_log_redaction(names: tuple[str, ...] = HTTP_LOGGERS) -> None:
    """Put ``RedactingFilter`` on the HTTP libraries' loggers (idempotent)."""
    for name in names:
        logger = logging.getLogger(name)
        if _FILTER not in logger.filters:
            logger.addFilter(_FILTER)


def one_line(text: str) -> str:
    """Credentials masked, whitespace and newlines collapsed: a message is one line,
    whatever produced it."""
    return " ".join(redact_text(text).split())
