"""Can the student's 12 inputs tell the small capsule apart after first contact, and does its teacher act differently?

Reads a `blindgrasp-dagger` relabelled dataset: episodes the *student* drove, each frame labelled with the
teacher's action. For every episode, t_c is the first frame a load cell reads above 2 N. Then:
- a logistic regression (L2, episode-level 5-fold cross-validation) on the last W observations up to t_c + k
  (W x 12 numbers, standardised) says whether the object is the small capsule or the other one of a pair;
- the teacher's commanded step (label - measured q) at t_c + k, averaged per object, says how differently the
  teacher wants to act on the two.

    python separability.py RELABELLED_DATASET OUT.json OUT.png
"""
import glob
import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import torch  # noqa: E402

TOUCH_N = 2.0  # the blind-approach teacher's touch threshold
PAIRS = (("capsule_small", "sphere_small"), ("capsule_small", "cylinder_a_small"))
WINDOWS, SINCE = (1, 5, 10), (0, 1, 2, 3, 4, 6, 8, 10, 15, 20)


def episodes(root: str) -> list[dict]:
    df = pd.concat(pd.read_parquet(f) for f in sorted(glob.glob(f"{root}/data/chunk-*/*.parquet")))
    tasks = pd.read_parquet(f"{root}/meta/tasks.parquet")

    def catalogue(task: str) -> str:  # "grasp and lift the small cylinder a" -> "cylinder_a_small"
        size, *rest = task.removeprefix("grasp and lift the ").split(" ")
        return "_".join(rest) + "_" + size

    names = {i: catalogue(t) for t, i in tasks["task_index"].items()}
    out = []
    for _, g in df.groupby("episode_index"):
        s, a = np.stack(g["observation.state"].to_numpy()), np.stack(g["action"].to_numpy())
        touch = np.nonzero((s[:, 9:12] > TOUCH_N).any(1))[0]
        if len(touch):
            out.append({"obj": names[g["task_index"].iloc[0]], "s": s, "a": a, "c": int(touch[0])})
    return out


def window(e: dict, k: int, w: int) -> np.ndarray:
    t = min(e["c"] + k, len(e["s"]) - 1)
    return e["s"][np.clip(np.arange(t - w + 1, t + 1), 0, None)].reshape(-1)


def cv_accuracy(x: np.ndarray, y: np.ndarray, folds: int = 5, l2: float = 1e-2) -> float:
    perm, hits = np.random.default_rng(0).permutation(len(y)), []
    for f in range(folds):
        te = perm[f::folds]
        tr = np.setdiff1d(perm, te)
        mu, sd = x[tr].mean(0), x[tr].std(0) + 1e-6
        xt, yt = torch.tensor((x[tr] - mu) / sd, dtype=torch.float32), torch.tensor(y[tr], dtype=torch.float32)
        w, b = torch.zeros(x.shape[1], requires_grad=True), torch.zeros(1, requires_grad=True)
        opt = torch.optim.LBFGS([w, b], max_iter=200)

        def loss():
            opt.zero_grad()
            value = torch.nn.functional.binary_cross_entropy_with_logits(xt @ w + b, yt) + l2 * (w**2).sum()
            value.backward()
            return value

        opt.step(loss)
        pred = (torch.tensor((x[te] - mu) / sd, dtype=torch.float32) @ w + b > 0).numpy()
        hits.extend(pred == (y[te] > 0.5))
    return float(np.mean(hits))


def main(root: str, out_json: str, out_png: str) -> None:
    torch.manual_seed(0)
    torch.set_num_threads(1)
    eps = episodes(root)
    res = {"episodes": {o: sum(e["obj"] == o for e in eps) for o in sorted({e["obj"] for e in eps})}, "accuracy": {},
           "teacher_step_difference_rad": {}}
    for a, b in PAIRS:
        sub = [e for e in eps if e["obj"] in (a, b)]
        y = np.array([e["obj"] == a for e in sub], float)
        for w in WINDOWS:
            res["accuracy"][f"{a} vs {b}, window {w}"] = [
                cv_accuracy(np.stack([window(e, k, w) for e in sub]), y) for k in SINCE]
    for k in SINCE:  # capsule minus sphere, the teacher's commanded step, in units of its pooled std
        step = {o: np.stack([e["a"][min(e["c"] + k, len(e["a"]) - 1)] - e["s"][min(e["c"] + k, len(e["a"]) - 1), :9]
                             for e in eps if e["obj"] == o]) for o in PAIRS[0]}
        diff = step[PAIRS[0][0]].mean(0) - step[PAIRS[0][1]].mean(0)
        res["teacher_step_difference_rad"][k] = {"mean": diff.round(3).tolist(),
                                                 "pooled_std": np.concatenate(list(step.values())).std(0).round(3).tolist()}
    res["since_contact_steps"] = list(SINCE)
    with open(out_json, "w") as f:
        json.dump(res, f, indent=1)
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    for key, acc in res["accuracy"].items():
        ax[0].plot(SINCE, acc, marker="o", ls="-" if "sphere" in key else "--", label=key.replace("capsule_small vs ", ""))
    ax[0].axhline(0.5, color="grey", lw=0.8)
    ax[0].set(xlabel="control steps since first contact (50 ms)", ylabel="cross-validated accuracy", ylim=(0.4, 1.0),
              title="small capsule vs ..., from the student's inputs")
    ax[0].legend(fontsize=7)
    d = np.array([res["teacher_step_difference_rad"][k]["mean"] for k in SINCE])
    sd = np.array([res["teacher_step_difference_rad"][k]["pooled_std"] for k in SINCE])
    for j in range(9):
        ax[1].plot(SINCE, d[:, j] / sd[:, j], label=f"joint {j}")
    ax[1].axhline(0, color="grey", lw=0.8)
    ax[1].set(xlabel="control steps since first contact", ylabel="capsule - sphere, in pooled std",
              title="the teacher's commanded step")
    ax[1].legend(fontsize=6, ncol=3)
    fig.tight_layout()
    fig.savefig(out_png, dpi=110)
    from PIL import Image  # a 64-colour palette: a quarter of the bytes, the same figure

    Image.open(out_png).convert("RGB").quantize(64).save(out_png, optimize=True)
    print(json.dumps(res["accuracy"], indent=0))


if __name__ == "__main__":
    main(*sys.argv[1:4])
