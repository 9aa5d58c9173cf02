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
# A run that did not end has null metrics (not NaN): aggregates over the column are numbers.
failed = con.execute(f"select count(*) from '{path}' where status <> 'ok'").fetchone()[0]
nan_failed = con.execute(
    f"select count(*) from '{path}' where status <> 'ok' and amp_ratio is not null"
).fetchone()[0]
assert nan_failed == 0, f"{nan_failed} rows of runs that did not end carry a metric value"
top = con.execute(f"select max(thd_odd_ratio), avg(amp_ratio) from '{path}'").fetchone()
assert all(v is not None and v == v for v in top), f"duckdb max/avg over the metrics: {top}"
# fail_reason is a fixed category to group on; its value and words are in their own columns.
groups = con.execute(
    f"select fail_reason, count(*) from '{path}' where status <> 'ok' group by fail_reason"
).fetchall()
known = {"diverged", "stroke_limit", "pressure_limit", "invalid_parameters", "invalid_motion", "invalid_setup"}
assert all(g in known for g, _ in groups), f"fail_reason categories {groups}"
assert sum(c for _, c in groups) == failed, f"{groups} do not count the {failed} failed rows"
print(f"{path}: {n} rows ({failed} failed: {dict(groups)}), {len(table.column_names)} columns, metadata ok (pyarrow {pq.__name__}, duckdb {duckdb.__version__})")
