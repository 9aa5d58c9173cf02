"""Opens a vshake results file with real readers (pyarrow and DuckDB) and checks it.

usage: check_results.py FILE ROWS COLUMN[,COLUMN...]
Exits non-zero with a message on the first mismatch.
"""
import sys

import duckdb
import pyarrow.parquet as pq

path, rows, columns = sys.argv[1], int(sys.argv[2]), sys.argv[3].split(",")

table = pq.read_table(path)
assert table.num_rows == rows, f"pyarrow: {table.num_rows} rows, expected {rows}"
missing = [c for c in columns if c not in table.column_names]
assert not missing, f"pyarrow: columns {missing} missing from {table.column_names}"
meta = {k.decode(): v.decode() for k, v in (table.schema.metadata or {}).items()}
for key in ["vshake.study", "vshake.seed", "vshake.version", "vshake.schema_version", "vshake.kind"]:
    assert key in meta, f"metadata key {key} missing: {sorted(meta)}"
assert meta["vshake.kind"] == "study_results", meta["vshake.kind"]
assert "[study]" in meta["vshake.study"], "the resolved study is TOML with a [study] block"

con = duckdb.connect()
n, distinct, ok = con.execute(
    f"select count(*), count(distinct (sample_id, excitation_id)), count(*) filter (where status = 'ok') from '{path}'"
).fetchone()
assert n == rows and distinct == rows, f"duckdb: {n} rows, {distinct} distinct (sample, excitation), expected {rows}"
assert ok > 0, "no run succeeded"
bad = con.execute(f"select count(*) from '{path}' where status = 'ok' and (amp_ratio is null or isnan(amp_ratio))").fetchone()[0]
assert bad == 0, f"{bad} ok rows without an amplitude ratio"
print(f"{path}: {n} rows, {len(table.column_names)} columns, metadata ok (pyarrow {pq.__name__}, duckdb {duckdb.__version__})")
