"""`python -m lab.bench --bench.type=...` (see lab/bench/__init__.py)."""

from lab.bench import main

main()
