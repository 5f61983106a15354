#!/usr/bin/env python3
"""Times the benchmark problems of benches/problems.rs in Python (python-kmedoids FasterPAM,
pymdptoolbox ValueIteration) and prints them next to the Rust timings.

Usage: compare.py RUST_TIMING_OUTPUT_FILE [EUCLIDEAN_MATRIX SNAPSHOT_MATRIX]   (see compare.sh)
With the matrix files (n × n little-endian f32, written by the Rust side), python-kmedoids
clusters exactly the matrices Rust clustered, both as float32 and as float64 arrays.
The problem data come from the same 32-bit LCG as benches/problems.rs, so both sides solve
identical problems; the cross-check columns show that they agree.
"""
import statistics
import sys
import time

import kmedoids
import mdptoolbox.mdp
import numpy as np
import scipy.sparse as sp


class Lcg:
    def __init__(self, seed):
        self.x = seed

    def next_f64(self):
        self.x = (self.x * 1664525 + 1013904223) & 0xFFFFFFFF
        return self.x / 4294967296.0


def clustering_problem(n):
    rng = Lcg(12345)
    pts = np.array([[5.0 * rng.next_f64(), 5.0 * rng.next_f64(), 2.0 * rng.next_f64()] for _ in range(n)])
    diff = pts[:, None, :] - pts[None, :, :]
    return np.sqrt((diff[:, :, 0] ** 2 + diff[:, :, 1] ** 2) + diff[:, :, 2] ** 2)


def vi_problem(states):
    rng = Lcg(777)
    p = np.zeros((5, states, states))
    for a in range(5):
        for s in range(states):
            js, ws = [], []
            for _ in range(5):
                js.append((s + int(rng.next_f64() * 20.0)) % states)
                ws.append(0.1 + rng.next_f64())
            total = sum(ws)
            for j, w in zip(js, ws):
                p[a, s, j] += w / total
    r = np.zeros((states, 5))
    for s in range(states):
        for a in range(5):
            r[s, a] = rng.next_f64()
    r[0, :] = 10.0
    return p, r


def median_time(reps, f):
    times = []
    for _ in range(reps):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def main():
    rust = {}
    with open(sys.argv[1]) as fh:
        for line in fh:
            parts = line.split()
            if len(parts) >= 2:
                rust[parts[0]] = (float(parts[1]), " ".join(parts[2:]))

    rows = []

    def kmedoids_rows(name, d):
        n = d.shape[0]
        init = np.arange(0, n - 1, 2)
        for dtype in (np.float32, np.float64):
            dd = np.ascontiguousarray(d.astype(dtype))
            res = kmedoids.fasterpam(dd, init.copy(), max_iter=100, n_cpu=1)
            t = median_time(5, lambda: kmedoids.fasterpam(dd, init.copy(), max_iter=100, n_cpu=1))
            rows.append((name, f"python-kmedoids 1 thread, {np.dtype(dtype).name}", t,
                         f"loss={res.loss:.6f} swaps={res.n_swap} iterations={res.n_iter}"))

    if len(sys.argv) > 3:
        for name, path in (("fasterpam_1625_k812", sys.argv[2]),
                           ("fasterpam_snapshots_1625_k812", sys.argv[3])):
            raw = np.fromfile(path, dtype="<f4")
            n = int(round(len(raw) ** 0.5))
            kmedoids_rows(name, raw.reshape(n, n))
    else:
        kmedoids_rows("fasterpam_1625_k812", clustering_problem(1625))

    p, r = vi_problem(1000)

    def run_vi(pp):
        vi = mdptoolbox.mdp.ValueIteration(pp, r, 0.95, epsilon=0.01, max_iter=1000)
        vi.run()
        return vi

    vi = run_vi(p)
    t = median_time(5, lambda: run_vi(p))
    detail = f"iter={vi.iter} max_iter={vi.max_iter} sumV={sum(vi.V):.6f} sumPolicy={sum(vi.policy)}"
    rows.append(("value_iteration_1000x5", "pymdptoolbox, dense numpy P", t, detail))
    psparse = [sp.csr_matrix(p[a]) for a in range(5)]
    try:
        vis = run_vi(psparse)
        t = median_time(5, lambda: run_vi(psparse))
        rows.append(("value_iteration_1000x5", "pymdptoolbox, scipy CSR P", t,
                     f"iter={vis.iter} max_iter={vis.max_iter} sumV={sum(vis.V):.6f} sumPolicy={sum(vis.policy)}"))
    except Exception as e:  # pymdptoolbox 4.0b3 may not handle every sparse type
        rows.append(("value_iteration_1000x5", f"pymdptoolbox, scipy CSR P (failed: {type(e).__name__})", float("nan"), ""))

    print(f"{'problem':<30} {'python side':<40} {'python s':>10} {'rust s':>10} {'py/rust':>8}")
    for name, side, tp, detail in rows:
        tr, rdetail = rust.get(name, (float("nan"), ""))
        print(f"{name:<30} {side:<40} {tp:>10.4f} {tr:>10.4f} {tp / tr:>8.1f}")
        print(f"{'':<30}   python: {detail}")
        print(f"{'':<30}   rust:   {rdetail}")


if __name__ == "__main__":
    main()
