"""Which float-path environment variables move torch's float32 products on this CPU: an MLP of the teacher's
shape (92 -> 256 -> 128 -> 64 -> 9, ELU, fixed seed) at batch sizes 1, 6, 18 and 20, each variable in a fresh
process, compared with none set. Needs torch only: `python float_paths.py` (docs/results/cpu_portability.md)."""

import hashlib
import os
import subprocess
import sys

BATCHES = (1, 6, 18, 20)
VARIABLES = (
    {},
    {"MKL_CBWR": "SSE4_2"},
    {"MKL_CBWR": "COMPATIBLE"},
    {"MKL_CBWR": "AVX2"},
    {"MKL_ENABLE_INSTRUCTIONS": "AVX2"},
    {"ATEN_CPU_CAPABILITY": "default"},
    {"ATEN_CPU_CAPABILITY": "avx2"},
    {"ONEDNN_MAX_CPU_ISA": "AVX2"},
    {"GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX512F"},
)


def products() -> str:
    import torch

    torch.set_num_threads(1)
    torch.manual_seed(0)
    layers, sizes = [], (92, 256, 128, 64, 9)
    for a, b in zip(sizes[:-1], sizes[1:], strict=True):
        layers += [torch.nn.Linear(a, b), torch.nn.ELU()]
    mlp = torch.nn.Sequential(*layers[:-1])
    with torch.no_grad():
        out = [mlp(torch.randn(n, sizes[0]) * 3).numpy().tobytes() for n in BATCHES]
    return torch.backends.cpu.get_cpu_capability() + " " + "/".join(hashlib.sha256(o).hexdigest()[:6] for o in out)


def main() -> None:
    info = open("/proc/cpuinfo").read().splitlines()
    print(next(line for line in info if line.startswith("model name")))
    flags = next(line for line in info if line.startswith("flags")).split()
    print("float ISA:", " ".join(sorted(f for f in flags if f.startswith(("avx", "fma", "amx")))))
    print("variable: torch capability, sha256 of the outputs at batch", "/".join(map(str, BATCHES)))
    base = None
    for extra in VARIABLES:
        env = {**os.environ, **extra}
        got = subprocess.run([sys.executable, __file__, "--child"], env=env, capture_output=True, text=True)
        cap, digests = got.stdout.split()
        base = base or digests.split("/")
        moved = [n for n, a, b in zip(BATCHES, base, digests.split("/"), strict=True) if a != b]
        print(f"{extra or 'none'}: {cap} {digests}  moves batch {moved or 'none'}", flush=True)


if __name__ == "__main__":
    print(products()) if "--child" in sys.argv else main()
