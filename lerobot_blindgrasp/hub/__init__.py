"""Sharing on the Hugging Face Hub: `blindgrasp-push-dataset` (`push.py`) and `blindgrasp-publish` (`publish.py`).
The cards are rendered in `lerobot_blindgrasp.cards`; the code's location and repo names are in `project`."""
