#!/usr/bin/env bash
# Main job on a fresh machine: virtual environment, install the locked versions, then
# recordings -> fits -> report for the bundled N-50 campaign (or the CSV given as $1, report folder $2).
set -euo pipefail
cd "$(dirname "$0")/.."
csv="${1:-data/n50/recordings.csv}"
out="${2:-reports/n50}"
bash scripts/install.sh
.venv/bin/uq report "$csv" --out "$out"
