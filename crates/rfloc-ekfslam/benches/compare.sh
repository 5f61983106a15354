#!/usr/bin/env bash
# Compares the Rust EKF-SLAM predict+update cost with filterpy's ExtendedKalmanFilter on the
# same sequence (4, 50 and 200 beacons). Creates a throw-away venv with filterpy and numpy.
# Usage: crates/rfloc-ekfslam/benches/compare.sh   (honours CARGO_TARGET_DIR)
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
venv="${RFLOC_BENCH_VENV:-${TMPDIR:-/tmp}/rfloc-filterpy-venv}"
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet filterpy numpy
fi
rust_out="$(cd "$here/.." && cargo run --quiet --release -p rfloc-ekfslam --example ekf_timing)"
py_out="$("$venv/bin/python" "$here/filterpy_compare.py")"
printf '%-8s %14s %16s %8s\n' beacons "rust ns/step" "filterpy ns/step" ratio
while read -r _ n ns; do
  fp="$(printf '%s\n' "$py_out" | awk -v n="$n" '$2 == n { print $3 }')"
  ratio="$(awk -v a="$fp" -v b="$ns" 'BEGIN { if (b > 0) printf "%.1f", a / b; else print "-" }')"
  printf '%-8s %14s %16s %8s\n' "$n" "$ns" "$fp" "${ratio}x"
done <<< "$rust_out"
