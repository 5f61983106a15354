#!/usr/bin/env bash
# Times the same problems in Rust (examples/snapshot_timing.rs) and Python (compare.py) and
# prints a ratio table. Creates a virtualenv in ${VENV:-/tmp/rfloc-snapshot-bench-venv}.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
venv="${VENV:-/tmp/rfloc-snapshot-bench-venv}"
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
    "$venv/bin/pip" install --quiet kmedoids pymdptoolbox numpy scipy
fi
out="$(mktemp)"
euclid="$(mktemp)"
snaps="$(mktemp)"
trap 'rm -f "$out" "$euclid" "$snaps"' EXIT
(cd "$here/.." && cargo run --quiet --release -p rfloc-snapshot --example snapshot_timing -- "$euclid" "$snaps") > "$out"
echo "Rust timings:"; cat "$out"; echo
"$venv/bin/python" "$here/compare.py" "$out" "$euclid" "$snaps"
