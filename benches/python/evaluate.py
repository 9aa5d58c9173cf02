"""Throughput of vshake.evaluate against `study run` on the same parameter sets.

The binary runs studies/gains_sweep.toml (8 192 Saltelli samples x 2 sines of 3 s, RK4 at 4
substeps, the study's own settings); vshake.evaluate then runs the same 8 192 sets, read from the
binary's table, against the same study's excitations. Each side is timed end to end (the
binary's process; the Python call, its Parquet round trip included), best of --repeat, the two
alternating. Prints simulated seconds per wall second for both and their ratio; --gate R exits 1
when evaluate's throughput is below R times the binary's.

    python benches/python/evaluate.py [--binary target/release/study] [--repeat 3] [--gate 0.9]
"""

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pyarrow.parquet as pq

import vshake

ROOT = Path(__file__).resolve().parents[2]
STUDY = ROOT / "studies" / "gains_sweep.toml"


def binary_run(binary: Path, out: Path) -> float:
    t0 = time.perf_counter()
    subprocess.run([str(binary), "run", str(STUDY), "--out", str(out), "-q"], check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--binary", type=Path, default=ROOT / "target" / "release" / "study")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--gate", type=float, default=None)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "gains_sweep.parquet"
        binary_run(a.binary, out)  # warm: the page cache, the table whose sets evaluate runs
        t = pq.read_table(out).to_pandas()
        first = t[t.excitation_id == 0].sort_values("sample_id")
        columns = pq.read_metadata(out).metadata[b"vshake.parameter_columns"].decode()
        sets = first[[c.strip() for c in columns.split(",")]].reset_index(drop=True)
        runs = 2 * len(sets)
        sim_s = runs * 3.0
        best_bin, best_py = float("inf"), float("inf")
        for _ in range(a.repeat):
            best_bin = min(best_bin, binary_run(a.binary, out))
            t0 = time.perf_counter()
            df = vshake.evaluate(sets, STUDY)
            best_py = min(best_py, time.perf_counter() - t0)
            assert len(df) == runs, len(df)
    ratio = best_bin / best_py
    print(f"{len(sets)} parameter sets x 2 excitations = {runs} runs of 3 s, RK4 h = 1/(1024 Hz x 4), best of {a.repeat}")
    print(f"  study run       {best_bin:6.2f} s wall  {sim_s / best_bin:9.0f} simulated s per wall s")
    print(f"  vshake.evaluate {best_py:6.2f} s wall  {sim_s / best_py:9.0f} simulated s per wall s  ({100 * ratio:.0f} % of study run)")
    if a.gate is not None and ratio < a.gate:
        print(f"GATE: vshake.evaluate's throughput is {ratio:.2f} x study run's, below {a.gate}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
