#!/usr/bin/env bash
# The package as a user gets it: `pip install .` (not editable) into a fresh virtual environment,
# then, from an empty folder outside the checkout, the rig through the FMUs (built on demand into
# an empty per-user cache) and an identification on its data.
set -euo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd)"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
python3 -m venv "$work/venv"
"$work/venv/bin/python" -m pip install -q "$repo"
mkdir "$work/empty"
cd "$work/empty"
export L1B2_CACHE_DIR="$work/cache" MPLBACKEND=Agg
"$work/venv/bin/l1b2" rig --out r --engine fmu --quiet --no-plots
"$work/venv/bin/l1b2" identify --train r/train.csv --test r/test.csv --out i
test -s i/identification.json
echo "install check: pip install . + l1b2 rig --engine fmu + l1b2 identify from an empty folder: OK"
