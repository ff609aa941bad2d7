"""Sharing on the Hugging Face Hub: dataset cards and `blindgrasp-push-dataset` (`cards.py`, `push.py`), where the
code lives and the Hub repo names (`project.py`, read from `[project.urls]`), relative links made absolute from
those URLs (`links.py`, also used by setup.py for the package index's project page), the shipped models' cards with
their one install section (`model_cards.py`), and `blindgrasp-publish`, which pushes the shipped models and a demo
dataset with their cards (`publish.py`).

Dataset cards serve the sim teacher demos (`blindgrasp-collect-demos`) and glove teleoperation datasets
(`lerobot-record`) alike, which is why this sits beside `demos/` rather than inside it.
"""

import re

# The shape of a Hub repo id, checked before anything is written or uploaded.
REPO_ID_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*/[A-Za-z0-9][A-Za-z0-9_.-]*$")
