"""Compares two vshake results files row by row: the same rows, the same statuses, and every
float column within a relative tolerance (the GPU backend against the CPU backend).

usage: agree.py A.parquet B.parquet [RTOL]   (RTOL defaults to 1e-9)
Prints each float column's largest relative difference; exits 1 when any exceeds RTOL or the
files differ otherwise.
"""
import sys

import numpy as np
import pyarrow.parquet as pq

a_path, b_path = sys.argv[1], sys.argv[2]
rtol = float(sys.argv[3]) if len(sys.argv) > 3 else 1e-9
a, b = pq.read_table(a_path), pq.read_table(b_path)
keys = ["sample_id", "excitation_id"]
a = a.sort_by([(k, "ascending") for k in keys])
b = b.sort_by([(k, "ascending") for k in keys])
fail = []
if a.num_rows != b.num_rows or a.column_names != b.column_names:
    sys.exit(f"{a_path} and {b_path} differ in shape: {a.num_rows} vs {b.num_rows} rows")
worst_all = 0.0
for name in a.column_names:
    x, y = a.column(name).to_numpy(zero_copy_only=False), b.column(name).to_numpy(zero_copy_only=False)
    if x.dtype.kind != "f":
        if not all(p == q for p, q in zip(x, y)):
            fail.append(f"{name}: values differ")
        continue
    both = ~np.isnan(x) & ~np.isnan(y)
    if (np.isnan(x) != np.isnan(y)).any():
        fail.append(f"{name}: NaN in different rows")
    scale = np.maximum(np.maximum(np.abs(x[both]), np.abs(y[both])), 1e-300)
    rel = np.abs(x[both] - y[both]) / scale
    worst = float(rel.max()) if rel.size else 0.0
    worst_all = max(worst_all, worst)
    print(f"  {name:28s} largest relative difference {worst:.2e} over {both.sum()} rows")
    if worst > rtol:
        fail.append(f"{name}: {worst:.2e} > {rtol:g}")
print(f"{a_path} vs {b_path}: {a.num_rows} rows, largest relative difference {worst_all:.2e} (tolerance {rtol:g})")
if fail:
    sys.exit("DISAGREE: " + "; ".join(fail))
