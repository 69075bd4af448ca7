#!/bin/sh
# Run the model benchmarks from the repository root and rewrite benchmarks/RESULTS.md.
# Extra arguments are passed on (e.g. --quick for a smoke run that only prints).
set -e
cd "$(dirname "$0")/.."
exec .venv/bin/python benchmarks/bench_model.py "$@"
