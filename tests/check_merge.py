"""Checks a merged sharded table against the single-process run: same columns, same values
(NaN equal to NaN), same vshake.* metadata.

usage: check_merge.py SINGLE.parquet MERGED.parquet
"""
import sys

import pyarrow.parquet as pq

a, b = pq.read_table(sys.argv[1]), pq.read_table(sys.argv[2])
assert a.schema.names == b.schema.names, f"columns differ: {a.schema.names} vs {b.schema.names}"
assert a.num_rows == b.num_rows, f"{a.num_rows} vs {b.num_rows} rows"
for name in a.schema.names:
    x, y = a.column(name).to_pylist(), b.column(name).to_pylist()
    same = all(u == v or (u != u and v != v) for u, v in zip(x, y))
    assert same, f"column {name} differs"
meta = lambda t: {k: v for k, v in t.schema.metadata.items() if k.startswith(b"vshake.")}
assert meta(a) == meta(b), "metadata differs"
print(f"{sys.argv[2]}: {b.num_rows} rows x {len(b.schema.names)} columns, identical to the single-process run")
