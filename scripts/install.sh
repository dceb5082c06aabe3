#!/usr/bin/env bash
# Install into .venv exactly the versions of requirements/lock.txt (hash-checked), then the
# project itself without touching them. Used by main.sh and test.sh; safe to rerun.
# pyproject.toml keeps compatible ranges for library users; the lock is what CI and the README's
# numbers were made with. Regenerate it (e.g. after changing pyproject.toml) with uv:
#   uv pip compile pyproject.toml requirements/build.in --extra test --extra docs --python-version 3.11 \
#       --generate-hashes -o requirements/lock.txt          (add --upgrade to move to newer versions)
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x .venv/bin/python ] || python3 -m venv .venv
pip=(.venv/bin/python -m pip install -q --disable-pip-version-check)
"${pip[@]}" --require-hashes -r requirements/lock.txt
# --no-build-isolation: build with the locked setuptools instead of fetching an unpinned one.
"${pip[@]}" --no-deps --no-build-isolation -e .
