"""The golden simulation test's key for a CPU family (tests/sim/test_sim_golden.py, tests/golden_sim.py): what decides
the last bits of the simulation's and the teacher's floats. Only the tests use it; the product records none.

MuJoCo's physics (through the C library's math functions) and the teacher's matrix products (through MKL and
oneDNN kernels) pick their code paths by CPU instruction set, so the same code on another CPU family gives other
last bits; a contact-rich rollout amplifies them. So the golden record keeps bit-for-bit digests per platform, and
compares them only on the platform that made them:

    platform()          {"cpu": model name, "isa": float-relevant instruction sets, "env": float-path overrides,
                         "versions": mujoco, torch, numpy}
    same(a, b)          True when two records' floats are expected to agree to the bit
    describe(p)         one line for messages

`BLINDGRASP_CPU_MODEL` overrides the model name read from /proc/cpuinfo: tests use it to play a machine that no
record has seen (tests/repo/test_unseen_machine.py). Environment variables that can move the math libraries onto another
code path (`MKL_CBWR`, `ATEN_CPU_CAPABILITY`, `GLIBC_TUNABLES`, ...) count as part of the platform: what each moves
depends on the CPU (`MKL_CBWR=SSE4_2` moves every MKL product on Intel but only single-row ones on AMD;
`ATEN_CPU_CAPABILITY=default` moves torch's kernels on both), so a record made with one set is never taken as
bit-identical to one made without.
"""

from __future__ import annotations

import os
import platform as _platform
from importlib import metadata
from pathlib import Path

CPU_MODEL_ENV = "BLINDGRASP_CPU_MODEL"

# Instruction sets that some math library dispatches on (glibc's libm, MKL, oneDNN, NumPy's SIMD loops); the
# others in /proc/cpuinfo (virtualisation, security, power) move no float.
FLOAT_ISA = (
    "sse4_1",
    "sse4_2",
    "avx",
    "avx2",
    "fma",
    "f16c",
    "avx512f",
    "avx512dq",
    "avx512cd",
    "avx512bw",
    "avx512vl",
    "avx512_vnni",
    "avx512_bf16",
    "avx512_fp16",
    "amx_tile",
    "amx_bf16",
    "asimd",
    "sve",
    "sve2",
)
# Environment variables that select another code path in those libraries.
FLOAT_ENV = (
    "MKL_CBWR",
    "MKL_ENABLE_INSTRUCTIONS",
    "MKL_DEBUG_CPU_TYPE",
    "ATEN_CPU_CAPABILITY",
    "ONEDNN_MAX_CPU_ISA",
    "DNNL_MAX_CPU_ISA",
    "OPENBLAS_CORETYPE",
    "NPY_DISABLE_CPU_FEATURES",
    "GLIBC_TUNABLES",
)
VERSIONED = ("mujoco", "torch", "numpy")


def _cpuinfo() -> list[str]:
    path = Path("/proc/cpuinfo")
    return path.read_text(errors="replace").splitlines() if path.exists() else []


def _field(lines: list[str], *names: str) -> str | None:
    for line in lines:
        key, sep, value = line.partition(":")
        if sep and key.strip() in names:
            return value.strip()
    return None


def cpu_model() -> str:
    """The CPU's model name (`BLINDGRASP_CPU_MODEL` if set), as /proc/cpuinfo gives it."""
    override = os.environ.get(CPU_MODEL_ENV, "").strip()
    if override:
        return override
    return _field(_cpuinfo(), "model name", "Model", "cpu model") or _platform.processor() or _platform.machine()


def isa() -> list[str]:
    """The float-relevant instruction sets of the first CPU, sorted (empty where /proc/cpuinfo says nothing)."""
    flags = set((_field(_cpuinfo(), "flags", "Features") or "").split())
    return sorted(flags & set(FLOAT_ISA))


def float_env() -> dict[str, str]:
    return {k: os.environ[k] for k in FLOAT_ENV if os.environ.get(k)}


def versions() -> dict[str, str]:
    out = {}
    for name in VERSIONED:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "absent"
    return out


def platform() -> dict:
    """This process's float platform, as a record stores it."""
    return {"cpu": cpu_model(), "isa": isa(), "env": float_env(), "versions": versions()}


def same(a: dict | None, b: dict | None) -> bool:
    """Whether floats made on platform `a` are expected to equal, to the bit, those made on `b`. A record without
    a platform (made before records kept one) matches nothing: nobody can say where it came from."""
    if not a or not b:
        return False
    return all(a.get(k) == b.get(k) for k in ("cpu", "isa", "env", "versions"))


def _widest_vectors(flags: list[str]) -> str:
    """The widest SIMD the math libraries can use: what tells apart two CPUs that report one model name."""
    for flag, name in (
        ("avx512f", "AVX-512"),
        ("avx2", "AVX2"),
        ("avx", "AVX"),
        ("sve", "SVE"),
        ("asimd", "NEON"),
    ):
        if flag in flags:
            return name
    return "no AVX"


def describe(p: dict | None) -> str:
    if not p:
        return "an unrecorded machine"
    extra = [f"{k}={v}" for k, v in sorted((p.get("env") or {}).items())]
    soft = ", ".join(f"{k} {v}" for k, v in sorted((p.get("versions") or {}).items()))
    isa_note = f" [{_widest_vectors(p['isa'])}]" if p.get("isa") is not None else ""
    return (
        f"{p.get('cpu')!r}{isa_note}"
        + (f" with {' '.join(extra)}" if extra else "")
        + (f" ({soft})" if soft else "")
    )
