"""The shipped models' cards: one "Install and use" section each, in the source card (between `BEGIN` and `END`) and
rewritten for the Hub by `render_model_card` (`blindgrasp-publish`), whose links that leave the model's folder are made
absolute (`links.py`), or plain text while `[project.urls]` are placeholders.
"""

from __future__ import annotations

import json
from pathlib import Path

from lerobot_blindgrasp import project
from lerobot_blindgrasp.cards import links

BEGIN = (
    "<!-- install-and-use: generated (lerobot_blindgrasp/cards/model_cards.py); blindgrasp-publish rewrites it -->"
)
END = "<!-- /install-and-use -->"
HEADING = "## Install and use"
# The student's evaluation: all 18 objects, 20 start states each, as its card's numbers were made.
STUDENT_EVAL = (
    "lerobot-eval --policy.path={ref} --env.type=blindgrasp --env.task=all \\\n"
    "  --eval.n_episodes=20 --eval.batch_size=20 --eval.use_async_envs=false --policy.device=cpu --seed=1000"
)
LOCAL_INSTALL = "pip install -e .   # in a clone of the code; a wheel (python -m build) carries this model too"


def teacher_uses(ref: str, config: dict | None = None) -> list[str]:
    """The commands that use the teacher at `ref` (a folder); `config` is its teacher_config.json, if known."""
    calib = (config or {}).get("joint_calibration_rad") or 0.0
    collect = f"blindgrasp-collect-demos --teacher={ref} --output_dir=runs/demos --repo_id=you/blindgrasp_demos"
    if calib:  # its student's demos are rolled out under the offset it was trained against
        collect = collect.replace(" --output_dir", f" --joint_calibration_rad={calib:g} \\\n  --output_dir")
    return [f"blindgrasp-eval-teacher --teacher={ref} --episodes=20", collect]


def _uses(name: str, ref: str, folder: Path | None) -> list[str]:
    """The commands that use model `name`, found at `ref` (a local folder or, for a student, a Hub repo id)."""
    if not name.startswith("teacher"):
        return [STUDENT_EVAL.format(ref=ref)]
    config = folder / "teacher_config.json" if folder is not None else None
    return teacher_uses(ref, json.loads(config.read_text()) if config is not None and config.is_file() else None)


def install_section(name: str, folder: Path | None = None, repo_id: str | None = None) -> str:
    """The card section, between its markers: local (repo_id None) or for the Hub repo `repo_id`."""
    if repo_id is None:
        install, ref, fetch, code = LOCAL_INSTALL, f"models/{name}", [], ""
    else:
        install, code = f"{project.install_line()}   # the LeRobot plugin", f"\n\n{project.code_line()}"
        teacher = name.startswith("teacher")
        ref = name if teacher else repo_id
        fetch = [f"hf download {repo_id} --local-dir {name}"] if teacher else []
    lines = "\n".join([install, *fetch, *_uses(name, ref, folder)])
    where = (f"From an installed package, `blindgrasp-path --name={name}` prints this model's folder."
             if repo_id is None else
             f"The package carries this model too: `blindgrasp-path --name={name}` prints its installed folder.")  # fmt: skip
    return f"{BEGIN}\n{HEADING}\n\n```bash\n{lines}\n```\n\n{where}{code}\n{END}"


def section_of(text: str, where: str = "card") -> tuple[int, int]:
    """(start, end) of the one marked install section in a card's text."""
    if text.count(BEGIN) != 1 or text.count(END) != 1 or text.index(END) < text.index(BEGIN):
        raise ValueError(f"{where} must hold exactly one install section between {BEGIN!r} and {END!r}")
    return text.index(BEGIN), text.index(END) + len(END)


def render_model_card(folder: Path, repo_id: str) -> str:
    """The card of shipped model `folder` as it goes to the Hub repo `repo_id`."""
    name = folder.name
    text = (folder / "README.md").read_text(encoding="utf-8")
    start, end = section_of(text, str(folder / "README.md"))
    section = install_section(name, folder, repo_id)
    hub = section.removeprefix(BEGIN + "\n").removesuffix("\n" + END)  # the markers serve the source only
    text = text[:start] + hub + text[end:]
    doc, own = f"models/{name}/README.md", f"models/{name}"
    if project.is_placeholder(project.source_url()):
        return links.plain_links(text, doc, keep_under=own)
    return links.absolute_links(text, doc, project.urls(), keep_under=own)
