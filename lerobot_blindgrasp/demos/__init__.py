"""Curated teacher demonstrations as LeRobotDataset episodes (paper Sec. III-C).

Stages, one module each: `config` (what to collect), `rollout` (teacher episodes in the batched env), `curation`
(which to keep), `dataset` (writing them), `collection_loop` (rollout -> curate -> write until the quotas are met),
`records` (provenance, statistics, yield report, card), `collect_cli` (the `blindgrasp-collect-demos` command
line). Cards and the Hub upload serve glove datasets too and live in `lerobot_blindgrasp.hub`.
"""
