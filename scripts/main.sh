#!/usr/bin/env bash
# README command 1: the shipped blind-approach teacher -> curated demos -> lerobot-train of the student ->
# lerobot-eval on all 18 objects, the teacher on the same start states, and a report (creates .venv if missing).
# Preset `quick_blind` goes beyond the paper (its report and card say how); `--preset=quick` runs the paper's
# student recipe on the default shipped teacher instead.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$ROOT/scripts/bootstrap.sh"
cd "$ROOT"
preset=(--preset=quick_blind)
for a in "$@"; do [[ "$a" == --preset=* ]] && preset=(); done
exec blindgrasp-pipeline "${preset[@]}" "$@"
