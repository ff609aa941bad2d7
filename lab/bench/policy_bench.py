"""select_action latency of blindgrasp_transformer on one CPU thread, against the compute floor of the model.

What one run measures, interleaved round by round so that every number sees the same machine load:
- `fast`: `BlindgraspTransformerPolicy.predict_normalized_delta`, the network part of `select_action` (rolling
  context, fused attention, last layer on the last token only), over whole episodes from `reset()` (so the padded
  start is included);
- `plain`: `BlindgraspGPT.forward_reference` on the same windows, every token through every layer with explicit
  softmax attention; the fast outputs must equal it (asserted, atol 1e-5);
- matmul throughput of one thread, two ways:
  `model GEMMs` = the plain path's own matrix products (30-token activations times the model's weights, in order),
  `peak GEMM`  = a 1024^3 fp32 product (weights hot in cache);
- floor = the plain model's FLOPs per step / throughput. The target (p50 <= 1.3 x floor) is checked against the
  model-GEMM floor: it is the time the model's matrix products take at this machine's BLAS speed, weights streamed
  from memory as in the real model. The peak-GEMM floor is printed too, to show how far that is from peak.
Latency is wall clock (`time.perf_counter`); CPU time of the thread (`time.thread_time`) is given beside it, as it
is less disturbed by other processes on a shared machine.
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F  # noqa: N812
from lerobot.configs import FeatureType, PolicyFeature
from lerobot.utils.constants import ACTION, OBS_STATE

from lab.bench import BenchConfig
from lerobot_blindgrasp import spec
from lerobot_blindgrasp.policies.blindgrasp_transformer import (
    BlindgraspTransformerConfig,
    BlindgraspTransformerPolicy,
)
from lerobot_blindgrasp.policies.blindgrasp_transformer.configuration_blindgrasp_transformer import SIZES

TARGET_RATIO = 1.3
PEAK_GEMM_N = 1024


@BenchConfig.register_subclass("policy")
@dataclass
class BenchPolicyConfig(BenchConfig):
    """select_action latency of blindgrasp_transformer on one CPU thread, against the model's compute floor."""

    size: str = "paper"  # policy size (the student sizes of the preset registry)
    threads: int = 1  # torch intra-op threads
    steps: int = spec.EPISODE_STEPS  # control steps per round
    rounds: int = 3  # interleaved measurement rounds
    seed: int = 0  # random observations and weights

    def __post_init__(self):
        if self.size not in SIZES:
            raise ValueError(f"--bench.size must be one of {sorted(SIZES)}, got {self.size!r}")


def flops_per_step(config: BlindgraspTransformerConfig, last_token_only: bool = False) -> int:
    """FLOPs (2 per multiply-add) of one control step, batch 1. Attention counts the full T x T product.

    last_token_only=True counts the fast path, whose last layer computes keys/values for all tokens but queries,
    output projection and MLP for the last token only.
    """
    t, d = config.n_obs_steps, config.embed_dim
    full_layer = 2 * t * d * 3 * d + 4 * t * t * d + 2 * t * d * d + 2 * t * d * 8 * d
    last_layer = full_layer
    if last_token_only:
        last_layer = 2 * t * d * 2 * d + 2 * d * d + 4 * t * d + 2 * d * d + 2 * d * 8 * d
    head, width = 0, d
    for hidden in [*config.head_hidden_dims, spec.ACTION_DIM]:
        head += 2 * width * hidden
        width = hidden
    embed = 2 * t * spec.STATE_DIM * d
    return embed + (config.n_layers - 1) * full_layer + last_layer + head


def make_policy(size: str, device: str = "cpu") -> BlindgraspTransformerPolicy:
    config = BlindgraspTransformerConfig(
        size=size,
        device=device,
        input_features={OBS_STATE: PolicyFeature(FeatureType.STATE, (spec.STATE_DIM,))},
        output_features={ACTION: PolicyFeature(FeatureType.ACTION, (spec.ACTION_DIM,))},
    )
    return BlindgraspTransformerPolicy(config).to(config.device).eval()


def _model_gemms(policy: BlindgraspTransformerPolicy):
    """A closure running the plain path's matrix products with the model's own weights, and their FLOPs."""
    model, t = policy.model, policy.config.n_obs_steps
    d = policy.config.embed_dim
    x_obs, x_d, x_4d = torch.randn(t, spec.STATE_DIM), torch.randn(t, d), torch.randn(t, 4 * d)
    products = [(x_obs, model.embed)]
    for block in model.blocks:
        products += [(x_d, block.attn.qkv), (x_d, block.attn.proj), (x_d, block.mlp[0]), (x_4d, block.mlp[2])]
    head_in = x_d[-1:]
    for layer in model.head:
        if isinstance(layer, torch.nn.Linear):
            products.append((head_in, layer))
            head_in = torch.randn(1, layer.out_features)
    flops = sum(2 * x.shape[0] * lin.in_features * lin.out_features for x, lin in products)

    def run():
        for x, lin in products:
            F.linear(x, lin.weight, lin.bias)

    return run, flops


def _timed(fn, n: int) -> tuple[list[float], list[float]]:
    wall, cpu = [], []
    for _ in range(n):
        w0, c0 = time.perf_counter(), time.thread_time()
        fn()
        cpu.append(time.thread_time() - c0)
        wall.append(time.perf_counter() - w0)
    return wall, cpu


def _pct(samples: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(samples) * 1e3, q))


def run(cfg: BenchPolicyConfig) -> dict:
    torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    policy = make_policy(cfg.size)
    gemms, gemm_flops = _model_gemms(policy)
    a = torch.randn(PEAK_GEMM_N, PEAK_GEMM_N)
    samples, max_abs_diff = _timed_rounds(cfg, policy, gemms, a)
    if max_abs_diff > 1e-5:
        raise AssertionError(f"fast path differs from the plain path by {max_abs_diff:.3g} (> 1e-5)")
    config = policy.config
    flops_plain = flops_per_step(config)
    result = {
        "size": cfg.size,
        "threads": cfg.threads,
        "steps_per_round": cfg.steps,
        "rounds": cfg.rounds,
        "context_length": config.n_obs_steps,
        "flops_per_step": flops_plain,
        "flops_per_step_fast": flops_per_step(config, last_token_only=True),
        "max_abs_diff_fast_vs_plain": max_abs_diff,
    }
    for clock, i in (("wall", 0), ("cpu", 1)):
        result[clock] = _clock_entry(samples, i, gemm_flops, 2 * PEAK_GEMM_N**3, flops_plain)
    result["target"] = f"fast p50 <= {TARGET_RATIO} x floor (model-GEMM throughput), wall clock"
    result["target_met"] = result["wall"]["fast_p50_over_floor"] <= TARGET_RATIO
    if not cfg.json:
        print(format_table(result))
    return result


def _timed_rounds(cfg: BenchPolicyConfig, policy, gemms, a) -> tuple[dict, float]:
    """(wall, cpu) samples of each path per step: the deployed fast path step by step from reset, the plain path on
    the same windows, the model's own GEMMs and a peak GEMM; and the largest difference between the two paths."""
    rng = np.random.default_rng(cfg.seed)
    samples = {k: ([], []) for k in ("fast", "plain", "model_gemms", "peak_gemm")}
    max_abs_diff = 0.0

    def timed(key, fn):
        w0, c0 = time.perf_counter(), time.thread_time()
        out = fn()
        samples[key][1].append(time.thread_time() - c0)
        samples[key][0].append(time.perf_counter() - w0)
        return out

    with torch.inference_mode():
        # Warm-up: allocator, BLAS buffers, weights into cache as far as they fit.
        policy.reset()
        for _ in range(5):
            policy.predict_normalized_delta({OBS_STATE: torch.randn(1, spec.STATE_DIM)})
        gemms()
        a @ a
        for _ in range(cfg.rounds):
            episode = torch.from_numpy(rng.standard_normal((cfg.steps, 1, spec.STATE_DIM)).astype(np.float32))
            policy.reset()
            windows, fast_out = [], []
            for obs in episode:
                fast_out.append(timed("fast", lambda o=obs: policy.predict_normalized_delta({OBS_STATE: o})))
                states, is_pad = policy.current_context()
                windows.append((states, is_pad if bool(is_pad.any()) else None))
            for (states, is_pad), out in zip(windows, fast_out, strict=True):
                ref = timed("plain", lambda s=states, p=is_pad: policy.model.forward_reference(s, p))
                max_abs_diff = max(max_abs_diff, float((ref - out).abs().max()))
            for key, fn, n in (("model_gemms", gemms, 20), ("peak_gemm", lambda: a @ a, 5)):
                wall, cpu = _timed(fn, n)
                samples[key][0].extend(wall)
                samples[key][1].extend(cpu)
    return samples, max_abs_diff


def _clock_entry(samples: dict, i: int, gemm_flops: float, peak_flops: float, flops_plain: float) -> dict:
    """Each path's p50/p95 on one clock (0: wall, 1: CPU), against the floors the GEMM throughputs give."""
    gemm_gflops = gemm_flops / statistics.median(samples["model_gemms"][i]) / 1e9
    peak_gflops = peak_flops / statistics.median(samples["peak_gemm"][i]) / 1e9
    floor_ms = flops_plain / gemm_gflops / 1e6
    peak_floor_ms = flops_plain / peak_gflops / 1e6
    entry = {
        "model_gemm_gflops": gemm_gflops,
        "peak_gemm_gflops": peak_gflops,
        "floor_ms": floor_ms,
        "peak_floor_ms": peak_floor_ms,
    }
    for path in ("plain", "fast"):
        entry[path] = {"p50_ms": _pct(samples[path][i], 50), "p95_ms": _pct(samples[path][i], 95)}
    entry["fast_p50_over_floor"] = entry["fast"]["p50_ms"] / floor_ms
    entry["fast_p50_over_peak_floor"] = entry["fast"]["p50_ms"] / peak_floor_ms
    return entry


def format_table(r: dict) -> str:
    w, c = r["wall"], r["cpu"]
    lines = [
        f"blindgrasp_transformer size={r['size']}, {r['threads']} thread(s), context {r['context_length']}, "
        f"{r['rounds']} rounds x {r['steps_per_round']} steps",
        f"FLOPs/step: plain {r['flops_per_step'] / 1e9:.3f} G, fast {r['flops_per_step_fast'] / 1e9:.3f} G; "
        f"fast vs plain max |diff| {r['max_abs_diff_fast_vs_plain']:.2e}",
        "",
        "| path / measure | wall p50 (ms) | wall p95 (ms) | CPU p50 (ms) | CPU p95 (ms) |",
        "|---|---:|---:|---:|---:|",
    ]
    for path, label in (("plain", "plain eager (reference)"), ("fast", "select_action (fast)")):
        lines.append(
            f"| {label} | {w[path]['p50_ms']:.2f} | {w[path]['p95_ms']:.2f} | "
            f"{c[path]['p50_ms']:.2f} | {c[path]['p95_ms']:.2f} |"
        )
    lines += [
        f"| floor: FLOPs / model-GEMM throughput | {w['floor_ms']:.2f} | | {c['floor_ms']:.2f} | |",
        f"| floor: FLOPs / peak 1024^3 GEMM | {w['peak_floor_ms']:.2f} | | {c['peak_floor_ms']:.2f} | |",
        "",
        f"matmul throughput, one thread: model GEMMs {w['model_gemm_gflops']:.0f} GFLOP/s wall "
        f"({c['model_gemm_gflops']:.0f} CPU), peak GEMM {w['peak_gemm_gflops']:.0f} GFLOP/s wall "
        f"({c['peak_gemm_gflops']:.0f} CPU)",
        f"fast p50 / floor: {w['fast_p50_over_floor']:.2f} wall, {c['fast_p50_over_floor']:.2f} CPU "
        f"(target <= {TARGET_RATIO}: {'met' if r['target_met'] else 'NOT met'}); "
        f"vs peak-GEMM floor: {w['fast_p50_over_peak_floor']:.2f} wall, {c['fast_p50_over_peak_floor']:.2f} CPU",
    ]
    return "\n".join(lines)
