#!/usr/bin/env bash
# README command 1: the whole pipeline on the `quick` preset, ending in a report (creates .venv if missing).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$ROOT/scripts/bootstrap.sh"
cd "$ROOT"
exec blindgrasp-pipeline --preset quick "$@"
