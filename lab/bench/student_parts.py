"""The student bench's update figures: the update split into its parts, three AdamW implementations, an operator
profile, `torch.compile` against eager, and this machine's GEMM rate at the model's shapes
(`python -m lab.bench --bench.type=student`)."""

from __future__ import annotations

import time
from collections import defaultdict

import torch
import torch.nn.functional as F  # noqa: N812

from lab.bench.policy_bench import make_policy
from lerobot_blindgrasp import spec

PARTS = ("forward", "backward", "clip", "step", "zero_grad")
# torch.optim.AdamW as LeRobot's AdamWConfig builds it (for-loop on CPU tensors), and its two other implementations.
ADAMW = {"lerobot_adamw": {}, "foreach_adamw": {"foreach": True}, "fused_adamw": {"fused": True}}


def _batch(batch_size: int, t_ctx: int, device: str = "cpu") -> dict:
    return {
        spec.STATE_KEY: torch.randn(batch_size, t_ctx, spec.STATE_DIM, device=device),
        f"{spec.STATE_KEY}_is_pad": torch.zeros(batch_size, t_ctx, dtype=torch.bool, device=device),
        spec.ACTION_KEY: torch.rand(batch_size, spec.ACTION_DIM, device=device) * 2 - 1,
    }


def clock(device: str):
    """A wall clock for work on `device`: on a GPU it first waits for the queued kernels, so each mark counts
    the work launched before it, not just its launch."""
    if str(device).startswith("cuda"):

        def synced() -> float:
            torch.cuda.synchronize()
            return time.perf_counter()

        return synced
    return time.perf_counter


def _timed_steps(policy, opt, batch: dict, steps: int, clip: float) -> dict[str, float]:
    """Seconds per part of the fastest of `steps` steps (lerobot-train's update_policy order); on a shared machine
    the least-disturbed step is the closest to the update's own cost."""
    best: dict[str, float] = {}
    params = list(policy.parameters())
    now = clock(policy.config.device)
    for _ in range(steps):
        marks = [now()]
        loss, _ = policy.forward(batch)
        marks.append(now())
        loss.backward()
        marks.append(now())
        torch.nn.utils.clip_grad_norm_(params, clip)
        marks.append(now())
        opt.step()
        marks.append(now())
        opt.zero_grad()
        marks.append(now())
        spent = {part: b - a for part, a, b in zip(PARTS, marks, marks[1:], strict=False)}
        if not best or sum(spent.values()) < sum(best.values()):
            best = spent
    return best


def _trainable(size: str, seed: int, device: str = "cpu", **adamw):
    torch.manual_seed(seed)
    policy = make_policy(size, device).train()
    preset = policy.config.get_optimizer_preset()
    opt = torch.optim.AdamW(
        policy.parameters(),
        lr=preset.lr,
        betas=preset.betas,
        eps=preset.eps,
        weight_decay=preset.weight_decay,
        **adamw,
    )
    return policy, opt, preset.grad_clip_norm


def compiled_vs_eager(size: str, batch_size: int, steps: int, seed: int) -> dict:
    """`torch.compile` of the model against eager, one step of each in turn (fastest of `steps`), plus the
    compile time (the first two compiled steps)."""
    eager, opt_e, clip = _trainable(size, seed)
    compiled, opt_c, _ = _trainable(size, seed)
    compiled.model = torch.compile(compiled.model)
    batch = _batch(batch_size, eager.config.n_obs_steps)
    t = time.perf_counter()
    _timed_steps(compiled, opt_c, batch, 2, clip)
    compile_s = time.perf_counter() - t
    _timed_steps(eager, opt_e, batch, 2, clip)
    best = {"eager": float("inf"), "compiled": float("inf")}
    for _ in range(steps):
        for name, policy, opt in (("eager", eager, opt_e), ("compiled", compiled, opt_c)):
            best[name] = min(best[name], sum(_timed_steps(policy, opt, batch, 1, clip).values()))
    ms = {f"{k}_ms": v / batch_size * 1e3 for k, v in best.items()}
    return {**ms, "compiled_over_eager": best["compiled"] / best["eager"], "compile_s": compile_s}


def update_parts(size: str, batch_size: int, steps: int, seed: int, profile: bool, device: str = "cpu") -> dict:
    """ms per sample of each part of forward + backward + clip + AdamW step, per AdamW implementation."""
    out = {}
    for name, kwargs in ADAMW.items():
        policy, opt, _ = _trainable(size, seed, device, **kwargs)
        preset = policy.config.get_optimizer_preset()
        batch = _batch(batch_size, policy.config.n_obs_steps, policy.config.device)
        _timed_steps(policy, opt, batch, 2, preset.grad_clip_norm)  # warm-up
        spent = _timed_steps(policy, opt, batch, steps, preset.grad_clip_norm)
        parts = {p: spent[p] / batch_size * 1e3 for p in PARTS}
        out[name] = {**parts, "total": sum(parts.values())}
        if profile and name == "lerobot_adamw":
            out["profile"] = operator_profile(policy, batch)
    return out


def _category(op: str) -> str:
    if any(k in op for k in ("scaled_dot_product", "flash_attention", "efficient_attention", "softmax")):
        return "attention"
    if op in ("aten::mm", "aten::addmm", "aten::bmm", "aten::matmul", "aten::linear"):
        return "matmul"
    return "other"


def operator_profile(policy, batch: dict, steps: int = 3) -> dict:
    """Forward + backward self CPU time per sample by operator kind, the operator count, and the cost of one
    dispatch of an empty-sized operator (what `count` operators cost before any arithmetic)."""
    from torch.profiler import ProfilerActivity, profile

    with profile(activities=[ProfilerActivity.CPU]) as prof:  # shares of the time, so the load matters less
        for _ in range(steps):
            loss, _ = policy.forward(batch)
            loss.backward()
            policy.zero_grad()
    n = steps * len(batch[spec.ACTION_KEY])
    by_kind, count = defaultdict(float), 0
    for evt in prof.key_averages():
        if evt.key.startswith("aten::") or "Backward" in evt.key:
            by_kind[_category(evt.key)] += evt.self_cpu_time_total / 1e3 / n
            count += evt.count if evt.key.startswith("aten::") else 0
    x = torch.zeros(1)
    t = time.perf_counter()
    for _ in range(2000):
        torch.add(x, x)
    dispatch_us = (time.perf_counter() - t) / 2000 * 1e6
    return {
        **{f"{k}_ms": v for k, v in by_kind.items()},
        "aten_ops_per_step": count // steps,
        "dispatch_us_per_op": dispatch_us,
    }


def gemm_gflops(size: str, batch_size: int, repeats: int = 20, device: str = "cpu") -> float:
    """GFLOP/s of this machine's matrix products at the model's training shapes (batch x 30 tokens rows)."""
    policy = make_policy(size)
    d, t = policy.config.embed_dim, policy.config.n_obs_steps
    rows = batch_size * t
    shapes = [(rows, d, 3 * d), (rows, d, d), (rows, d, 4 * d), (rows, 4 * d, d)]
    mats = [(torch.randn(m, k, device=device), torch.randn(n, k, device=device)) for m, k, n in shapes]
    flops = sum(2 * m * k * n for m, k, n in shapes)
    for a, w in mats:
        F.linear(a, w)
    best, now = float("inf"), clock(device)
    for _ in range(repeats):  # the fastest round, as for the update
        t0 = now()
        for a, w in mats:
            F.linear(a, w)
        best = min(best, now() - t0)
    return flops / best / 1e9


def format_table(r: dict) -> str:
    load, upd = r["load_ms_per_sample"], r["update_ms_per_sample"]
    lines = [
        f"student {r['size']}, batch {r['batch_size']}, update on {r['device']}, loading on one CPU thread "
        "(per sample; ratios within this run)"
    ]
    for path in ("lerobot", "lerobot_row", "lerobot_window", "streaming", "cache"):
        lines.append(f"  load {path:15s} {load[path]:8.3f} ms  = {r['load_over_update'][path]:6.2f} x update")
    for name in ADAMW:
        u = upd[name]
        parts = ", ".join(f"{p} {u[p]:.3f}" for p in PARTS)
        lines.append(f"  update, {name:14s} {u['total']:.3f} ms  ({parts})")
    if "profile" in upd:
        p = upd["profile"]
        kinds = ", ".join(f"{k[:-3]} {v:.3f} ms" for k, v in p.items() if k.endswith("_ms"))
        lines.append(
            f"  fwd+bwd by operator: {kinds}; {p['aten_ops_per_step']} aten ops/step at "
            f"{p['dispatch_us_per_op']:.1f} us each"
        )
    if "compile" in r:
        c = r["compile"]
        lines.append(
            f"  torch.compile: {c['compiled_ms']:.3f} ms against eager {c['eager_ms']:.3f} ms "
            f"(x {c['compiled_over_eager']:.2f}), after {c['compile_s']:.0f} s of compiling"
        )
    lines.append(
        f"  floor ({r['train_flops_per_sample'] / 1e6:.1f} MFLOP at {r['gemm_gflops']:.1f} GFLOP/s): "
        f"{r['floor_ms_per_sample']:.3f} ms (update = {r['update_over_floor']:.2f} x floor)"
    )
    lines.append(
        "  bound, samples/s with "
        + f"{r['num_workers']} loader process(es): "
        + ", ".join(f"{k} {v:.0f}" for k, v in r["bound_samples_per_s"].items())
    )
    m = r["cache_memory"]
    lines.append(
        f"  cache: {m['bytes_per_frame']:.0f} bytes/frame, {m['cache_bytes'] / 2**20:.1f} MiB for {m['frames']} "
        f"frames per process"
    )
    for row in r.get("loader", []):
        lines.append(
            f"  DataLoader {row['path']:8s} num_workers={row['num_workers']} prefetch={row['prefetch_factor']}: "
            f"{row['samples_per_s']:.0f} samples/s"
        )
    for lt in r.get("lerobot_train", []):
        steady = f", updt_s {lt['updt_s']:.4f} data_s {lt['data_s']:.4f}" if lt["updt_s"] is not None else ""
        lines.append(
            f"  lerobot-train {lt['path']:8s}: {lt['steps']} steps in {lt['wall_s']:.1f} s = "
            f"{lt['samples_per_s']:.0f} samples/s{steady}"
        )
    return "\n".join(lines)
