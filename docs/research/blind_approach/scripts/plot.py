"""The blind-approach page's figure: (a) the teacher's fine-tune curve, (b) success per object.

    python plot.py curve RUN_DIR SHIPPED_TB_DIR OUT.json    training success per iteration from TensorBoard scalars
    python plot.py rows OUT.json LABEL=PATH ...             success per object and episode of each evaluation
    python plot.py figure OUT.png                           from the records in docs/research/blind_approach/

A PATH is a lerobot-eval output, or a blind_approach.py / masked_teacher.py eval record (object -> successes, or
object -> {"teacher": [...], ...}: the plain teacher's).
"""
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parents[1]
TAGS = ("Metrics/success", "Success/capsule_small")


def scalars(run_dir: str) -> dict[str, dict[int, float]]:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    out = {t: {} for t in TAGS}
    for f in sorted(Path(run_dir).glob("events.out.tfevents.*")):
        ea = EventAccumulator(str(f), size_guidance={"scalars": 0})
        ea.Reload()
        for t in TAGS:
            if t in ea.Tags()["scalars"]:
                out[t].update({e.step: round(e.value, 4) for e in ea.Scalars(t)})
    return out


def curve(run_dir: str, shipped_tb: str, out: str) -> None:
    run, ship = scalars(run_dir), scalars(shipped_tb)
    rec = {t: sorted(run[t].items()) for t in TAGS}
    # the shipped teacher's own level over its last 50 iterations (2050-2099), same stochastic training metric
    rec["shipped_last50"] = {t: float(np.mean([v for s, v in ship[t].items() if s >= 2050])) for t in TAGS}
    Path(out).write_text(json.dumps(rec, separators=(",", ":")))


def rows(out: str, *specs: str) -> None:
    from lerobot_blindgrasp.analysis.compare import load_successes
    from lerobot_blindgrasp.sim.objects import PAPER_OBJECTS

    res = {}
    for lab, _, path in (x.partition("=") for x in specs):
        if path.endswith("eval_info.json") or Path(path).is_dir():
            res[lab] = load_successes(path)
        else:
            d = json.loads(Path(path).read_text())
            res[lab] = {k: v["teacher"] if isinstance(v, dict) else v for k, v in d.items()}
        res[lab] = {k: [bool(x) for x in res[lab][k]] for k in PAPER_OBJECTS}
    Path(out).write_text(json.dumps({"objects": list(PAPER_OBJECTS), "rows": res}, separators=(",", ":")))
    for lab, r in res.items():
        print(f"{lab}: {sum(map(sum, r.values()))}/{sum(map(len, r.values()))}")


def figure(out: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c = json.loads((HERE / "teacher_curve.json").read_text())
    ev = json.loads((HERE / "per_object.json").read_text())
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 5), gridspec_kw={"width_ratios": [1, 1.8]})
    for t, col, lab in ((TAGS[0], "C0", "all objects"), (TAGS[1], "C3", "small capsule")):
        it, v = np.array(c[t]).T
        k = 10
        a.plot(it[k - 1:], np.convolve(v, np.ones(k) / k, "valid"), color=col, label=f"{lab} (10-it mean)")
        a.axhline(c["shipped_last50"][t], color=col, ls="--", lw=1, label=f"{lab}, shipped teacher (its last 50 it)")
    a.set(xlabel="PPO iteration", ylabel="training success (stochastic, 4x capsule envs)", ylim=(0, 1),
          title="(a) teacher fine-tuned to approach blind")
    a.legend(fontsize=7, loc="lower right")
    names = list(ev["objects"])
    w = 0.8 / len(ev["rows"])
    for i, (lab, flags) in enumerate(ev["rows"].items()):
        b.bar(np.arange(len(names)) + i * w, [np.mean(flags[n]) for n in names], w, label=lab)
    b.set_xticks(np.arange(len(names)) + 0.4 - w / 2, [n.replace("_", " ") for n in names], rotation=70, fontsize=7)
    b.set(ylabel="success (20 episodes, seed 1000)", ylim=(0, 1.05), title="(b) per object, same start states")
    b.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.42), ncol=3)
    fig.tight_layout()
    fig.savefig(out, dpi=80)


if __name__ == "__main__":
    {"curve": lambda: curve(*sys.argv[2:5]), "rows": lambda: rows(*sys.argv[2:]),
     "figure": lambda: figure(sys.argv[2])}[sys.argv[1]]()
