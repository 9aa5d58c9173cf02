"""Opens an earthquake study's results with DuckDB and checks its spectral-error columns.

usage: check_spectral.py FILE ROWS
Exits non-zero with a message on the first mismatch; prints the per-motion summary.
"""
import sys

import duckdb

path, rows = sys.argv[1], int(sys.argv[2])
con = duckdb.connect()
n, ok = con.execute(f"select count(*), count(*) filter (where status = 'ok') from '{path}'").fetchone()
assert n == rows, f"duckdb: {n} rows, expected {rows}"
assert ok == rows, f"{rows - ok} runs did not succeed"
bad = con.execute(
    f"""select count(*) from '{path}'
        where spectral_err_mean is null or isnan(spectral_err_mean) or spectral_err_mean < 0
           or spectral_err_max < spectral_err_mean or isnan(pga_ratio) or isnan(pgv_ratio) or isnan(pgd_ratio)"""
).fetchone()[0]
assert bad == 0, f"{bad} rows with a missing or inconsistent spectral error or peak ratio"
for exc, mean, worst, pga in con.execute(
    f"select excitation, avg(spectral_err_mean), max(spectral_err_max), avg(pga_ratio) from '{path}' group by excitation order by excitation"
).fetchall():
    print(f"{exc}: mean spectral error {mean:.4f}, worst {worst:.4f}, PGA ratio {pga:.4f}")
