"""Sharing datasets on the Hugging Face Hub: dataset cards and `blindgrasp-push-dataset`.

Serves the sim teacher demos (`blindgrasp-collect-demos`) and glove teleoperation datasets (`lerobot-record`)
alike, which is why it sits beside `demos/` rather than inside it.
"""

import re

# The shape of a Hub repo id, checked before anything is written or uploaded.
REPO_ID_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*/[A-Za-z0-9][A-Za-z0-9_.-]*$")
