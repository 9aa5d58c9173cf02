"""Peak memory of `study run` at 1 000 and 100 000 samples (acceptance: within 2x).

Runs target/release/study on benches/memory_study.toml (1.5 s sine per sample) under GNU time
(`/usr/bin/time -f %M`: the peak resident set size of the study process itself; Debian package
`time`, which .ci/run installs) and compares. Exits 1 when the ratio exceeds the limit.

usage: python3 benches/peak_memory.py [--limit 2.0]
"""
import os
import subprocess
import sys
import tempfile

limit = float(sys.argv[sys.argv.index("--limit") + 1]) if "--limit" in sys.argv else 2.0
root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
study = os.path.join(root, "target", "release", "study")
peaks = {}
with tempfile.TemporaryDirectory() as d:
    for n in (1000, 100000):
        out = os.path.join(d, f"mem_{n}.parquet")
        rss = os.path.join(d, f"rss_{n}.txt")
        cmd = ["/usr/bin/time", "-f", "%M", "-o", rss, study, "run", os.path.join(root, "benches", "memory_study.toml"),
               "--samples", str(n), "--out", out, "--quiet"]
        if subprocess.run(cmd, stdout=subprocess.DEVNULL).returncode != 0 or not os.path.exists(out):
            sys.exit(f"study run --samples {n} failed")
        peaks[n] = int(open(rss).read().split()[-1])  # KiB
        print(f"{n:>7} samples: peak RSS {peaks[n] / 1024:.1f} MiB, results {os.path.getsize(out) / 1e6:.1f} MB")
ratio = peaks[100000] / peaks[1000]
print(f"ratio 100 000 / 1 000 samples: {ratio:.2f} (limit {limit})")
sys.exit(0 if ratio <= limit else 1)
