#!/usr/bin/env bash
# README command 2: run the test suite (creates .venv first if it is missing).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$ROOT/scripts/bootstrap.sh"
cd "$ROOT"
set +e
# Idle OpenMP threads sleep instead of spinning (libgomp reads this once, when torch loads): the suite runs torch in
# its own process and in the lerobot-train / lerobot-eval subprocesses it starts, and on 2 cores spinning threads
# of one process starve the others. The package itself sets nothing on import; a user's own setting wins.
export OMP_WAIT_POLICY="${OMP_WAIT_POLICY:-PASSIVE}"
python -m pytest -q --durations=15 "$@"
code=$?
set -e
if [ "$code" -eq 5 ]; then
  echo "error: pytest collected no tests (exit 5); the suite must not be empty" >&2
fi
exit "$code"
