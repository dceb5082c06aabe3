#!/usr/bin/env bash
# Test suite on a fresh machine: virtual environment, install with test extras, lint, fast tests.
# Slow statistical suites are marked `slow`: run them with  scripts/test.sh -m slow
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x .venv/bin/python ] || python3 -m venv .venv
.venv/bin/python -m pip install -q --disable-pip-version-check -e '.[test]'
.venv/bin/ruff check uq tests scripts
.venv/bin/python -m pytest -q "$@"
