"""Sharing on the Hugging Face Hub: `blindgrasp-push-dataset` (`push.py`: a sim demo set or a glove recording, with
its card) and `blindgrasp-publish` (`publish.py`: the shipped models and a demo dataset, each with its card).

The cards themselves are rendered in `lerobot_blindgrasp.cards`; where the code lives and the Hub repo names are said
once, in `lerobot_blindgrasp.project` (read from `[project.urls]`).
"""
