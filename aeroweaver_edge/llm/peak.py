"""This CPU's arithmetic peak, to say how far the embedded model's prompt rate is from it.

Peak = physical cores used x clock x FLOPs per cycle per core, with FLOPs per cycle = SIMD
lanes (16 fp32 with AVX-512F, 8 with AVX2/FMA, 4 otherwise) x 2 (a fused multiply-add is
two FLOPs) x FMA units. ``/proc/cpuinfo`` does not tell how many FMA units a core has: 2 is
assumed (Intel server cores with AVX-512 and AMD Zen 4/5 have 2), and the figure says so.
The int8 peak is also given (AVX-512 VNNI ``vpdpbusd``: 64 multiply-adds per 512-bit
instruction): llama.cpp multiplies Q8_0/Q4_x weights with int8-quantised activations, so that
is the ceiling its quantised kernels actually run against. AMX tiles, when present, are
noted but not counted.

A prompt token of a transformer with P parameters costs about 2 P FLOPs (issue 23's rule of
thumb, P = 135e6 for SmolLM2-135M; the matrices a prompt token really multiplies hold 106e6,
the rest is the token embedding, a lookup).
"""

from __future__ import annotations

import contextlib
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

CPUINFO = Path("/proc/cpuinfo")
MODEL_PARAMS = 135e6  # SmolLM2-135M, the 2 x P rule of thumb
FMA_UNITS = 2  # per core; not in /proc/cpuinfo (assumed, see the module docstring)


@dataclass(frozen=True)
class Peak:
    model: str
    physical_cores: int
    mhz: float
    simd: str  # "avx512" | "avx2" | "sse"
    fp32_flops_per_cycle: int  # per core
    int8_ops_per_cycle: int  # per core (0 without VNNI)
    amx: bool
    fma_units_assumed: int = FMA_UNITS

    def fp32_gflops(self, threads: int | None = None) -> float:
        cores = self.physical_cores if threads is None else min(threads, self.physical_cores)
        return cores * self.mhz * 1e6 * self.fp32_flops_per_cycle / 1e9

    def int8_gops(self, threads: int | None = None) -> float:
        cores = self.physical_cores if threads is None else min(threads, self.physical_cores)
        return cores * self.mhz * 1e6 * self.int8_ops_per_cycle / 1e9

    def as_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["fp32_gflops"] = round(self.fp32_gflops(), 1)
        out["int8_gops"] = round(self.int8_gops(), 1)
        return out


def parse_cpuinfo(text: str) -> Peak:
    """The peak described by a ``/proc/cpuinfo`` text (x86 field names)."""
    blocks = [b for b in text.strip().split("\n\n") if b.strip()]
    cores: set[tuple[str, str]] = set()
    mhz: list[float] = []
    flags: set[str] = set()
    model = ""
    for i, block in enumerate(blocks):
        fields: dict[str, str] = {}
        for line in block.splitlines():
            key, sep, value = line.partition(":")
            if sep:
                fields[key.strip()] = value.strip()
        if "processor" not in fields:
            continue
        cores.add((fields.get("physical id", "0"), fields.get("core id", str(i))))
        with contextlib.suppress(ValueError):
            mhz.append(float(fields.get("cpu MHz", "")))
        flags |= set(fields.get("flags", "").split())
        model = model or fields.get("model name", "")
    if "avx512f" in flags:
        simd, lanes = "avx512", 16
    elif "avx2" in flags and "fma" in flags:
        simd, lanes = "avx2", 8
    else:
        simd, lanes = "sse", 4
    # vpdpbusd: 4 int8 products summed into each 32-bit lane = 4 multiply-adds = 8 ops.
    vnni = "avx512_vnni" in flags or "avx_vnni" in flags
    int8 = lanes * 4 * 2 * FMA_UNITS if vnni and simd != "sse" else 0
    return Peak(
        model=model,
        physical_cores=max(1, len(cores)),
        mhz=max(mhz) if mhz else 0.0,
        simd=simd,
        fp32_flops_per_cycle=lanes * 2 * FMA_UNITS,
        int8_ops_per_cycle=int8,
        amx="amx_int8" in flags,
    )


KERNEL_FLAGS: tuple[str, ...] = (
    "avx2",
    "fma",
    "f16c",
    "avx512f",
    "avx512bw",
    "avx512_vnni",
    "avx512_bf16",
    "avx_vnni",
    "amx_int8",
)
"""The features llama.cpp's CPU backend picks its kernels by (x86)."""


def cpu_identity(path: Path = CPUINFO) -> dict[str, Any]:
    """Vendor, family, model, stepping and kernel-selecting SIMD features of the first CPU.

    Why: the same weights, prompt and thread count give first-token logprobs that differ by
    up to ~0.5 nats between two CPUs whose llama.cpp kernel paths differ (docs/benchmark.md,
    "Model, code, machine"), so a benchmark session records which CPU ran it. A KVM guest's
    model name is often just "AMD EPYC"; family/model/stepping tell the generation.
    """
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return {}
    block = next((b for b in text.strip().split("\n\n") if "processor" in b), "")
    fields: dict[str, str] = {}
    for line in block.splitlines():
        key, sep, value = line.partition(":")
        if sep:
            fields.setdefault(key.strip(), value.strip())
    flags = set(fields.get("flags", "").split())
    names = (("vendor_id", "vendor"), ("cpu family", "family"), ("model", "model"))
    out: dict[str, Any] = {name: fields[key] for key, name in names if key in fields}
    if "model name" in fields:
        out["model_name"] = fields["model name"]
    if "stepping" in fields:
        out["stepping"] = fields["stepping"]
    out["kernel_flags"] = [f for f in KERNEL_FLAGS if f in flags]
    return out


def cpu_peak(path: Path = CPUINFO) -> Peak:
    try:
        return parse_cpuinfo(path.read_text(encoding="utf-8", errors="replace"))
    except OSError:
        return parse_cpuinfo("")


__all__ = ["FMA_UNITS", "MODEL_PARAMS", "Peak", "cpu_peak", "parse_cpuinfo"]
