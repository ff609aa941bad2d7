"""The card of a demo collection: what `blindgrasp-collect-demos` made (objects and their yield, curation, the
randomization, the teacher, every run), rendered by `cards.dataset_cards` from the collection's own records."""

from __future__ import annotations

from pathlib import Path

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.cards import dataset_cards
from lerobot_blindgrasp.demos import dataset as demo_dataset
from lerobot_blindgrasp.demos import provenance, yield_report
from lerobot_blindgrasp.sim import objects


def sim_context(root: Path, repo_id: str, meta) -> dict:
    prov = provenance.load_provenance(root)
    tally = yield_report.load_tally(root)
    rows = []
    for name in prov["objects"]:
        o = tally.of(name)
        rows.append({"name": name, "task": objects.get_object(name).task, "yield": o.yield_rate, **vars(o)})
    total = tally.total()
    return {
        **dataset_cards.dataset_fields(repo_id, meta),
        "objects": rows,
        "total": {"yield": total.yield_rate, **vars(total)},
        "stochastic": prov["stochastic"],
        "curation": prov["curation"],
        "teacher": prov["teacher"],
        "randomization": dataset_cards.randomization_rows(prov["randomization"]),
        "runs": prov["runs"],
        "state_names": list(spec.STATE_NAMES),
        "action_names": list(spec.ACTION_NAMES),
        "metadata_features": demo_dataset.EPISODE_FEATURES,
        "merge_hint": demo_dataset.MERGE_HINT.format(
            repo_id=repo_id, root="<root>", names=list(demo_dataset.METADATA_FEATURE_NAMES)
        ),
        **dataset_cards.versions(),
    }


def sim_card_kwargs(root: Path, repo_id: str, **kw) -> dict:
    """`dataset_cards.card_kwargs` of the collection in `root`."""
    from lerobot.datasets.dataset_metadata import LeRobotDatasetMetadata

    meta = LeRobotDatasetMetadata(repo_id, root=Path(root))
    return dataset_cards.card_kwargs(repo_id, "sim", sim_context(Path(root), repo_id, meta), meta, **kw)


def write(root: Path, repo_id: str) -> Path:
    """The collection's card as root/README.md."""
    return dataset_cards.write_card(root, repo_id, sim_card_kwargs(root, repo_id))
