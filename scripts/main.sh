#!/usr/bin/env bash
# README command 1: blindgrasp-pipeline with its default preset, `quick_blind` (beyond the paper; its report says
# how): the shipped calibration-blind teacher -> curated demos -> lerobot-train of the student -> lerobot-eval on all
# 18 objects, the teacher on the same start states, and a report (creates .venv if missing).
# `bash scripts/main.sh --preset=quick` runs the paper's student recipe on the default shipped teacher instead.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$ROOT/scripts/bootstrap.sh"
cd "$ROOT"
exec blindgrasp-pipeline "$@"
