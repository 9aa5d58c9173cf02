#!/usr/bin/env python3
"""The cost of a tuning run with the yielding building against the bare table's (issue 50).

Runs `study tune` on studies/building/tune_building.toml (a robust tuning of the TVC's leads with
the 3-storey bilinear building, 12 generations x 8 draws) and on the same file with the building
taken off and six plant and controller parameters as its uncertain ones instead (the platen's m,
k, c and Coulomb coefficient, G_f, G_d), and with a one-mode 90 t, 2 Hz specimen in place of the
building. Both files make the same number of runs (the same search, the same draws), so the ratio
of their wall times is the ratio of their cost per run. Each variant runs `--rounds` times,
alternating, and the best of each is kept (other load only slows a run down).

    python3 benches/tune_cost.py [--study target/release/study] [--rounds 3] [--max-ratio 2]

Prints each variant's wall time, its CPU time over the wall time (2.0: both cores busy) and its
ratio to the bare table's; with --max-ratio, exits 1 where the building's ratio is above it.
"""

import argparse
import os
import pathlib
import re
import resource
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
BUILDING = ROOT / "studies" / "building" / "tune_building.toml"

# The bare table's uncertain parameters (instead of the storeys'): +-20 % of each published value.
BARE_UNCERTAIN = [
    ("platen.m", 1.44e5),
    ("platen.k", 1.266e6),
    ("platen.c", 4.1e4),
    ("platen.mu_coef", 5.38e-3),
    ("controller.g_f", -1.5),
    ("controller.g_d", 1.5),
]

SPECIMEN = """[model.specimen]
m1 = 9.0e4
f1 = 2.0
"""


def variants():
    """The three tuning files' texts: the building's as committed, the bare table's and the
    one-mode specimen's."""
    text = BUILDING.read_text()
    head, rest = text.split("[model.building]", 1)
    robust = rest[rest.index("[robust]") : rest.index("[[uncertain]]")]
    spectrum = rest[rest.index("[spectrum]") :]
    uncertain = ""
    for name, value in BARE_UNCERTAIN:
        low, high = sorted((0.8 * value, 1.2 * value))
        uncertain += (
            f'[[uncertain]]\nname = "{name}"\ndistribution = "uniform"\n'
            f"low = {low!r}\nhigh = {high!r}\n\n"
        )
    bare = head + robust + uncertain + spectrum
    specimen = head + SPECIMEN + "\n" + robust + uncertain + spectrum
    return {"bare": bare, "specimen": specimen, "building": text}


def run(study, path, out):
    """One tuning: its wall time and the CPU time of the process over it."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(
        [study, "tune", str(path), "--out", str(out), "--force"],
        capture_output=True,
        text=True,
    )
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        sys.exit(f"study tune {path} failed ({proc.returncode}):\n{proc.stderr}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    runs = re.search(r"(\d+) runs", proc.stdout + proc.stderr)
    return wall, cpu / wall, int(runs.group(1)) if runs else None


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--study", default=str(ROOT / "target" / "release" / "study"))
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--max-ratio", type=float)
    args = ap.parse_args()
    best = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        files = {}
        for name, text in variants().items():
            files[name] = tmp / f"{name}.toml"
            files[name].write_text(text)
        for r in range(args.rounds):
            for name, path in files.items():
                wall, busy, runs = run(args.study, path, tmp / f"out_{name}")
                print(f"round {r + 1}: {name:9} {wall:6.2f} s, cpu/wall {busy:.2f}, runs {runs}")
                if name not in best or wall < best[name][0]:
                    best[name] = (wall, busy, runs)
    bare = best["bare"][0]
    print(f"\nbest of {args.rounds} on {os.cpu_count()} cores:")
    for name, (wall, busy, runs) in best.items():
        per = f", {1e3 * wall / runs:.2f} ms a run" if runs else ""
        print(f"  {name:9} {wall:6.2f} s{per}, cpu/wall {busy:.2f}, {wall / bare:.2f}x the bare table")
    ratio = best["building"][0] / bare
    if args.max_ratio is not None and ratio > args.max_ratio:
        sys.exit(f"the building's tuning costs {ratio:.2f}x the bare table's (most {args.max_ratio})")


if __name__ == "__main__":
    main()
