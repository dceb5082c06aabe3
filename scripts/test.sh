#!/usr/bin/env bash
# Test suite on a fresh machine: virtual environment, install the locked versions (with the test
# tools), lint and format check, the documentation site (mkdocs, strict), fast tests. Slow
# statistical suites are marked `slow`: scripts/test.sh -m slow
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh
# The tests render the report pages in a headless browser and check the screenshots; Debian's
# chromium is not on a fresh machine and is no Python package, so install it here with apt-get
# (as root). Without it those tests fail when CI is set, and are skipped otherwise.
if ! command -v chromium >/dev/null 2>&1; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
        apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium >/dev/null
    else
        echo "test.sh: chromium is missing and cannot be installed here (needs root and apt-get)" >&2
    fi
fi
.venv/bin/ruff check uq tests scripts fits benchmarks
.venv/bin/ruff format --check uq tests scripts fits benchmarks
# The documentation site: a broken link, a missing anchor or any warning fails the build.
site="$(mktemp -d)"
trap 'rm -rf "$site"' EXIT
.venv/bin/mkdocs build --strict --quiet --site-dir "$site"
# Two workers (pytest-xdist): the suite's tests are independent and most of their time is one
# core's (a fit, a figure, a subprocess), so the machine's two cores halve the wall time.
.venv/bin/python -m pytest -q -n 2 "$@"
