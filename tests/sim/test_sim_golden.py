"""The simulation's task definition is the recorded one, on any CPU: the shipped teacher, driven deterministically
through `BatchedGraspEnv`, sees the observations, rewards (term by term), targets and successes recorded in
tests/data/sim_golden.json. Two settings: evaluation (`EVAL_DR`, on the shipped teacher's own evaluation start
states, whose successes must also match its recorded `models/teacher_cpu_bc/eval/eval.json`) and training
(`PAPER_DR`: Table II's pushes, a multi-object batch with autoreset).

MuJoCo's and the teacher's floats differ in their last bits between CPU families, and a contact-rich closed loop
amplifies them (measured across stand-ins for other families: 2e-7 of scale at the first step, 8e-5 by step 30
of the evaluation, 20 % of scale by step 60). So, on every machine (tests/golden_sim.py):
- exact: shapes, the steps each env was done at (episode lengths), physics failures, each episode's success, in
  both settings: which episodes succeed holds across CPU families, only the step a success latches at may move;
- exact: eq. 1's identity, the reward equals the recorded weights times the logged terms at every step (IEEE
  arithmetic in a fixed order rounds alike on every CPU); a one-ulp change in a reward weight breaks it;
- within tolerance: the floats of the first steps (29 of the evaluation, 4 of training): per step, 100 x the
  largest deviation any stand-in showed by that step, plus 1e-9 of the quantity's scale. The stand-ins, each a
  code path another CPU takes (`python tests/sim/test_sim_golden.py --record` measures them,
  docs/results/cpu_portability.md has the numbers): MKL_CBWR=COMPATIBLE and SSE4_2, ATEN_CPU_CAPABILITY=default
  and avx2, NumPy without AVX-512, glibc's libm without FMA/AVX2, OpenBLAS as Haswell, two torch threads;
- bit for bit: every quantity's sha256, where this machine's platform (tests/float_platform.py: CPU model,
  float-relevant instruction sets, float-path environment variables, mujoco/torch/numpy versions) is recorded in
  the golden file's `platforms`, so a refactor on a recorded machine must still be bit-identical.
An unrecorded family (`BLINDGRASP_CPU_MODEL=...` plays one) thus fails for no float noise up to 100 x the
stand-ins' spread, and a real change fails everywhere: the last tests make one (a reward weight one ulp off, a
success flipped), and tests/repo/test_unseen_machine.py runs this module as a machine no record has seen. A change
that moves a float here changes the teacher's evaluation: re-record that too."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import float_platform
import golden_sim as g
import numpy as np
import pytest

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.durable import atomic_write_text
from lerobot_blindgrasp.sim import objects

GOLDEN = Path(__file__).resolve().parents[1] / "data" / "sim_golden.json"
ROOT = Path(__file__).resolve().parents[2]
NEWCOMER = (
    "Newcomer CPU 9000 (no record holds it)"  # in-process; tests/repo/test_unseen_machine.py plays a whole one
)
# NumPy's SIMD loops without AVX-512: on an AVX-512 CPU, what a CPU without it computes (a no-op on one without)
NUMPY_NO_AVX512 = "AVX512F AVX512CD AVX512_SKX AVX512_CLX AVX512_CNL AVX512_ICL AVX512_SPR"
# Other families' code paths on this machine (docs/results/cpu_portability.md says what each moves).
STAND_INS = (
    {"MKL_CBWR": "COMPATIBLE"},
    {"MKL_CBWR": "SSE4_2"},
    {"ATEN_CPU_CAPABILITY": "default"},
    {"ATEN_CPU_CAPABILITY": "avx2"},
    {"NPY_DISABLE_CPU_FEATURES": NUMPY_NO_AVX512},
    {"GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2,-FMA,-AVX512F"},
    {"OPENBLAS_CORETYPE": "Haswell"},
    {"GOLDEN_TORCH_THREADS": "2"},
)


@pytest.fixture(scope="module")
def golden() -> dict:
    return json.loads(GOLDEN.read_text())


@pytest.fixture(scope="module")
def runs():
    return g.rollouts()


def test_the_shipped_teacher_sees_the_recorded_simulation(golden, runs):
    problems = g.compare(golden, runs, float_platform.platform())
    assert not problems, f"on {float_platform.describe(float_platform.platform())}:\n" + "\n".join(problems)
    if os.environ.get("GOLDEN_REPORT"):  # tests/repo/test_unseen_machine.py: which recorded digests it reproduced
        Path(os.environ["GOLDEN_REPORT"]).write_text(json.dumps(g.matching_platforms(golden, runs)))


def test_the_golden_successes_are_the_shipped_teachers_recorded_evaluation(golden):
    recorded = json.loads((ROOT / "models/teacher_cpu_bc/eval/eval.json").read_text())
    per_object = recorded["modes"]["deterministic"]["per_object"]
    flags = golden["settings"]["evaluation"]["exact"]["success"]
    assert recorded["seed"] == spec.EVAL_SEED and set(objects.CATALOGUE) >= set(g.EVAL_OBJECTS)
    for i, name in enumerate(g.EVAL_OBJECTS):
        assert flags[i * g.EPISODES : (i + 1) * g.EPISODES] == per_object[name]["successes"][: g.EPISODES], name


@pytest.mark.parametrize("where", ["this machine", "a machine no record has seen"])
def test_a_flipped_success_fails_everywhere(golden, runs, where):
    here = float_platform.platform() if where == "this machine" else {**float_platform.platform(), "cpu": NEWCOMER}
    changed = json.loads(json.dumps(golden))
    flags = changed["settings"]["evaluation"]["exact"]["success"]
    flags[0] = not flags[0]
    episodes = changed["settings"]["training"]["exact"]["episode_successes"]
    episodes[-1][-1] = not episodes[-1][-1]
    problems = g.compare(changed, runs, here)
    assert any(p.startswith("evaluation: success differ") for p in problems), problems
    assert any(p.startswith("training: episode_successes differ") for p in problems), problems


def test_float_noise_fails_only_where_this_platform_is_recorded(golden, runs):
    """One ulp more on the last step's lift of one env, past the tolerant horizon, as another family's noise: on
    this machine (recorded) the bit-for-bit check names it; as a newcomer it passes."""
    noisy = {s: dict(run) for s, run in runs.items()}
    lift = noisy["evaluation"]["lift"].copy()
    lift[-1, 0] = np.nextafter(lift[-1, 0], np.inf)
    noisy["evaluation"]["lift"] = lift
    if any(float_platform.same(p.get("platform"), float_platform.platform()) for p in golden["platforms"]):
        problems = g.compare(golden, noisy, float_platform.platform())
        assert len(problems) == 1 and "no longer bit-identical: ['evaluation/lift']" in problems[0], problems
    assert g.compare(golden, noisy, {**float_platform.platform(), "cpu": NEWCOMER}) == []


@pytest.fixture(scope="module")
def nudged():
    """The evaluation setting with the task weight one ulp larger (np.nextafter): every step's physics is the same,
    only the reward's last bit moves where the task term is not 0."""
    return g.rollouts(nudge="task", settings=("evaluation",))


@pytest.mark.parametrize("where", ["this machine", "a machine no record has seen"])
def test_a_reward_weight_one_ulp_off_fails_everywhere(golden, nudged, where):
    here = float_platform.platform() if where == "this machine" else {**float_platform.platform(), "cpu": NEWCOMER}
    problems = g.compare(golden, nudged, here)
    assert any("not eq. 1 of the terms" in p for p in problems), problems


def _dump(path: Path) -> None:
    runs = g.rollouts(threads=int(os.environ.get("GOLDEN_TORCH_THREADS", "1")))
    np.savez_compressed(path, **{f"{s}/{k}": v for s, run in runs.items() for k, v in run.items()})


def _load(path: Path) -> dict:
    data = np.load(path)
    out: dict = {}
    for key in data.files:
        s, k = key.split("/", 1)
        out.setdefault(s, {})[k] = data[key]
    return out


def _stand_in_runs(folder: Path) -> list[tuple[dict, dict]]:
    out = []
    for i, extra in enumerate(STAND_INS):
        path = folder / f"stand_in_{i}.npz"
        print("stand-in", extra, flush=True)
        subprocess.run([sys.executable, __file__, "--dump", str(path)], env={**os.environ, **extra}, check=True)
        out.append((extra, _load(path)))
    return out


def spread(base: dict, stand_ins: list[tuple[dict, dict]], golden: dict | None = None) -> None:
    """Print, per setting and quantity, the largest deviation of any stand-in from `base` up to each of a few
    steps, relative to the quantity's scale; and which recorded platforms' digests each stand-in reproduces."""
    steps = (1, 5, 10, 20, 30, 40, 60, 100, 160)
    for s in g.SETTINGS:
        ref, others = g.floats(base[s]), [g.floats(run[s]) for _, run in stand_ins]
        print(f"{s}: max |stand-in - this machine| / scale, up to step " + ", ".join(map(str, steps)))
        for k, a in ref.items():
            dev = np.zeros(len(a))
            for o in others:
                dev = np.maximum(dev, np.abs(o[k] - a).reshape(len(a), -1).max(axis=1))
            env = np.maximum.accumulate(dev) / max(float(np.abs(a).max()), 1e-12)
            print(f"  {k:18s} " + " ".join(f"{env[min(t, len(env)) - 1]:8.1e}" for t in steps))
    for extra, run in stand_ins:
        same = g.matching_platforms(golden, run) if golden else []
        n = g.successful_episodes(run["training"])
        print(f"{extra}: {n} successful training episodes; bit-identical to: {same or 'no recorded platform'}")


def record(folder: Path) -> dict:
    """A fresh record: this machine's rollouts, the tolerances measured from the stand-ins, the platforms."""
    from lerobot_blindgrasp.teacher.policy import TeacherPolicy, default_teacher

    base = g.rollouts()
    stand_ins = _stand_in_runs(folder)
    for extra, run in stand_ins:  # what the record calls exact must be exact under every stand-in
        for s in g.SETTINGS:
            assert g.exact(base[s], s) == g.exact(run[s], s), f"{extra}: {s} differs in an exact quantity"
    tol = {s: g.tolerances(base[s], [run[s] for _, run in stand_ins]) for s in g.SETTINGS}
    weights = TeacherPolicy(default_teacher()).config["reward"]
    out = g.summary(base, tol, weights)
    out["stand_ins"] = [
        {"env": extra, "successful_training_episodes": g.successful_episodes(run["training"])}
        for extra, run in stand_ins
    ]
    mine = {s: g.digests(base[s]) for s in g.SETTINGS}
    out["platforms"] = [{"platform": float_platform.platform(), "digests": mine}]
    return out


if __name__ == "__main__" and "--dump" in sys.argv:
    _dump(Path(sys.argv[sys.argv.index("--dump") + 1]))
elif __name__ == "__main__" and "--record" in sys.argv:
    import tempfile

    old = json.loads(GOLDEN.read_text()) if GOLDEN.exists() else {}
    kept = old.get("platforms") or [  # the first format: digests of the first record, then one per CPU name
        {"cpu": p.get("cpu", "first record"), "digests": {s: p[s] for s in g.SETTINGS}}
        for p in ([old, *old.get("other_platforms", [])] if old else [])
    ]
    with tempfile.TemporaryDirectory() as tmp:
        new = record(Path(tmp))
    mine = new["platforms"][0]["digests"]
    # Earlier records' digests stay, where they are not this machine's (the digests are made as they were).
    new["platforms"] += [p for p in kept if p["digests"] != mine]
    atomic_write_text(GOLDEN, json.dumps(new, indent=1) + "\n")
    print("wrote", GOLDEN)
elif __name__ == "__main__" and "--spread" in sys.argv:
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        base = g.rollouts()
        print(
            "this machine:",
            float_platform.describe(float_platform.platform()),
            "; training successes",
            g.successful_episodes(base["training"]),
        )
        spread(base, _stand_in_runs(Path(tmp)), json.loads(GOLDEN.read_text()))
elif __name__ == "__main__" and "--record-platform" in sys.argv:
    golden, runs = json.loads(GOLDEN.read_text()), g.rollouts()
    problems = g.compare(golden, runs, float_platform.platform())
    assert not problems, "not the recorded simulation, so not a new platform's floats:\n" + "\n".join(problems)
    mine = {"platform": float_platform.platform(), "digests": {s: g.digests(runs[s]) for s in g.SETTINGS}}
    # An entry of the first format (a model name, no platform) with these very digests is this family: complete it.
    kept = [p for p in golden["platforms"] if p.get("platform") or p["digests"] != mine["digests"]]
    golden["platforms"] = [*kept, mine]
    atomic_write_text(GOLDEN, json.dumps(golden, indent=1) + "\n")
    print("added", float_platform.describe(float_platform.platform()), "to", GOLDEN)
