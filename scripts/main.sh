#!/usr/bin/env bash
# README command 1: the method on the shipped teacher (`quick` preset): curated demos, lerobot-train of the student,
# lerobot-eval on all 18 objects, the teacher on the same start states, and a report (creates .venv if missing).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$ROOT/scripts/bootstrap.sh"
cd "$ROOT"
exec blindgrasp-pipeline --preset=quick "$@"
