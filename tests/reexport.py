#!/usr/bin/env python3
"""Re-export a campaign's measured files the way data-acquisition systems do, to try the readers
on files that vshake did not write: decimated to a lower rate, a pre-trigger of rest (sensor noise
around the first samples' level) and extra rows after the test, time printed with few significant
digits, columns reordered and extra ones added, CSV with another separator.

    python3 tests/reexport.py CAMPAIGN.toml OUT_DIR [--every 4] [--pre 0.5] [--post 0.0]
        [--time-digits 6] [--value-digits 0] [--sep ,] [--shuffle] [--extra]

Only the Python standard library and pyarrow (for Parquet inputs) are used. The campaign file is
copied with each test's `data` pointing at the new CSV file.
"""
import argparse
import csv
import math
import os
import random
import re
import sys


def read_table(path):
    if path.endswith(".parquet") or path.endswith(".pq"):
        import pyarrow.parquet as pq

        t = pq.read_table(path)
        return {name: [float(v) for v in t.column(name).to_pylist()] for name in t.column_names}
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header = rows[0]
    return {h: [float(r[i]) for r in rows[1:]] for i, h in enumerate(header)}


def third_difference_sigma(x):
    d = [x[i + 3] - 3 * x[i + 2] + 3 * x[i + 1] - x[i] for i in range(len(x) - 3)]
    return math.sqrt(sum(v * v for v in d) / max(len(d), 1) / 20.0)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("campaign")
    ap.add_argument("out")
    ap.add_argument("--every", type=int, default=1, help="keep every N-th row (decimation)")
    ap.add_argument("--pre", type=float, default=0.0, help="seconds of rest prepended")
    ap.add_argument("--post", type=float, default=0.0, help="seconds of rest appended (reference back at 0)")
    ap.add_argument("--time-digits", type=int, default=0, help="significant digits of time_s (0: full)")
    ap.add_argument("--value-digits", type=int, default=0, help="significant digits of the other columns (0: full)")
    ap.add_argument("--sep", default=",", help="field separator: , ; or tab")
    ap.add_argument("--shuffle", action="store_true", help="reorder the columns")
    ap.add_argument("--extra", action="store_true", help="add columns vshake does not read")
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    sep = "\t" if a.sep in ("tab", "\\t") else a.sep
    rng = random.Random(a.seed)
    base = os.path.dirname(os.path.abspath(a.campaign))
    os.makedirs(a.out, exist_ok=True)
    text = open(a.campaign).read()

    def fmt(v, digits):
        return repr(v) if digits == 0 else "%.*g" % (digits, v)

    def redo(m):
        data = m.group(2)
        src = os.path.join(base, data)
        t = read_table(src)
        names = list(t.keys())
        n = len(t["time_s"])
        keep = list(range(0, n, a.every))
        cols = {k: [v[i] for i in keep] for k, v in t.items()}
        dt = (t["time_s"][1] - t["time_s"][0]) * a.every
        n_pre, n_post = int(round(a.pre / dt)), int(round(a.post / dt))
        rest = {}
        for k, v in cols.items():
            if k in ("time_s",):
                continue
            if k in ("ref_disp_m", "valve_cmd_v", "spool_m"):
                rest[k] = (0.0, 0.0)
            else:
                head = v[: max(8, int(0.1 / dt))]
                rest[k] = (sum(head[:4]) / 4.0, third_difference_sigma(head))
        out = {}
        t0 = cols["time_s"][0]
        total = n_pre + len(keep) + n_post
        out["time_s"] = [t0 + i * dt for i in range(total)]
        for k, v in cols.items():
            if k == "time_s":
                continue
            mean, sd = rest[k]
            pre = [mean + rng.gauss(0.0, sd) if sd > 0 else mean for _ in range(n_pre)]
            post = [mean + rng.gauss(0.0, sd) if sd > 0 else mean for _ in range(n_post)]
            out[k] = pre + v + post
        order = names[:]
        if a.shuffle:
            rng.shuffle(order)
        if a.extra:
            out["temperature_c"] = [21.5 + 0.001 * i for i in range(total)]
            out["channel_17_raw"] = [float(i % 4096) for i in range(total)]
            order = order[:2] + ["temperature_c"] + order[2:] + ["channel_17_raw"]
        new = os.path.splitext(os.path.basename(data))[0] + ".csv"
        with open(os.path.join(a.out, new), "w", newline="") as f:
            w = csv.writer(f, delimiter=sep)
            w.writerow(order)
            for i in range(total):
                w.writerow([fmt(out[k][i], a.time_digits if k == "time_s" else a.value_digits) for k in order])
        return m.group(1) + new + m.group(3)

    text = re.sub(r'(data\s*=\s*")([^"]+)(")', redo, text)
    with open(os.path.join(a.out, os.path.basename(a.campaign)), "w") as f:
        f.write(text)


if __name__ == "__main__":
    sys.exit(main())
