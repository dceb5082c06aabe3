#!/usr/bin/env bash
# Test suite on a fresh machine: virtual environment, install the locked versions (with the test
# tools), lint and format check, fast tests. Slow statistical suites are marked `slow`: scripts/test.sh -m slow
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh
.venv/bin/ruff check uq tests scripts fits benchmarks
.venv/bin/ruff format --check uq tests scripts fits benchmarks
.venv/bin/python -m pytest -q "$@"
