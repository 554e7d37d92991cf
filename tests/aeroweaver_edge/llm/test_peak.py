"""The CPU peak from /proc/cpuinfo text: cores, clock and SIMD width."""

from __future__ import annotations

from pathlib import Path

import pytest

from aeroweaver_edge.llm.peak import FMA_UNITS, cpu_identity, cpu_peak, parse_cpuinfo


def _cpu(n: int, core: int, mhz: str, flags: str, physical: int = 0) -> str:
    return (
        f"processor\t: {n}\nmodel name\t: Test CPU\nphysical id\t: {physical}\n"
        f"core id\t\t: {core}\ncpu MHz\t\t: {mhz}\nflags\t\t: {flags}\n"
    )


def test_avx512_two_cores() -> None:
    text = "\n".join(
        _cpu(i, i, "2600.000", "fpu fma avx2 avx512f avx512_vnni amx_int8") for i in (0, 1)
    )
    peak = parse_cpuinfo(text)
    assert (peak.physical_cores, peak.simd, peak.mhz, peak.amx) == (2, "avx512", 2600.0, True)
    assert peak.fp32_flops_per_cycle == 16 * 2 * FMA_UNITS
    assert peak.fp32_gflops() == pytest.approx(2 * 2.6 * 64)  # 332.8 with 2 FMA units
    assert peak.fp32_gflops(threads=1) == pytest.approx(2.6 * 64)
    assert peak.fp32_gflops(threads=8) == peak.fp32_gflops()  # never more than the cores
    assert peak.int8_gops() == pytest.approx(2 * 2.6 * 256)


def test_hyperthreads_count_once_and_avx2_is_eight_lanes() -> None:
    # four logical CPUs on two cores (siblings share a core id), AVX2 + FMA, no VNNI
    text = "\n".join(_cpu(i, i % 2, "3000.0", "fma avx avx2") for i in range(4))
    peak = parse_cpuinfo(text)
    assert (peak.physical_cores, peak.simd, peak.int8_ops_per_cycle) == (2, "avx2", 0)
    assert peak.fp32_gflops() == pytest.approx(2 * 3.0 * 8 * 2 * FMA_UNITS)


def test_unreadable_or_odd_cpuinfo_gives_a_floor(tmp_path: Path) -> None:
    assert parse_cpuinfo("").physical_cores == 1
    assert parse_cpuinfo(_cpu(0, 0, "?", "sse2")).simd == "sse"
    assert cpu_peak(tmp_path / "missing").mhz == 0.0


def test_this_machine() -> None:
    peak = cpu_peak()
    assert peak.physical_cores >= 1
    assert peak.as_dict()["fp32_gflops"] == round(peak.fp32_gflops(), 1)


def test_cpu_identity_names_the_generation_and_the_kernel_features(tmp_path: Path) -> None:
    info = tmp_path / "cpuinfo"
    block = (
        "processor\t: {n}\nvendor_id\t: AuthenticAMD\ncpu family\t: 25\nmodel\t\t: 17\n"
        "model name\t: AMD EPYC\nstepping\t: 1\nflags\t\t: fpu sse2 avx fma avx2 avx512f "
        "avx512bw avx512_vnni avx512_bf16\n"
    )
    info.write_text("\n".join(block.format(n=i) for i in (0, 1)))
    ident = cpu_identity(info)
    assert ident == {
        "vendor": "AuthenticAMD",
        "family": "25",
        "model": "17",
        "model_name": "AMD EPYC",
        "stepping": "1",
        "kernel_flags": ["avx2", "fma", "avx512f", "avx512bw", "avx512_vnni", "avx512_bf16"],
    }
    info.write_text(block.format(n=0).replace(" avx512f avx512bw avx512_vnni avx512_bf16", ""))
    assert cpu_identity(info)["kernel_flags"] == ["avx2", "fma"]
    assert cpu_identity(tmp_path / "missing") == {}
