#!/usr/bin/env python3
"""Writes tests/fixtures/numpy_peer_metrics.csv: the NumPy peer's metrics (numpy_peer.py, an
independent transcription of docs/model.md) for 16 gain sets at three amplitudes of the 3 Hz
reference sine (3 s, 1 s taper, the last 4 cycles), RK4 with 4 substeps per tick. `cargo test`
(crates/kernel/tests/peers.rs) runs the same cases through the kernel and holds every metric to 1e-9
of these values, relative to max(|value|, 1).

The first set is the default gains (the docs/model.md §5 reference cases at 1.73 g and 3.20 g);
the other 15 are drawn uniformly over the gains sweep's ranges (seed 2026). Values are written
with 17 significant digits, so they read back to the same double. A run the peer stops (a
state out of bounds: one set at 3.20 g) has every metric `nan`, and the kernel must fail it too.

    python3 benches/peers/make_fixture.py [--out tests/fixtures/numpy_peer_metrics.csv]

Needs numpy. Regenerate only when docs/model.md changes; the file is committed.
"""

import argparse
import csv
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import model  # noqa: E402
import numpy_peer  # noqa: E402
from run import RANGES  # noqa: E402

AMPLITUDES_G = [0.5, 1.73, 3.20]
SETS = 16
SUBSTEPS = 4


def gain_sets():
    rng = np.random.default_rng(2026)
    sets = {g: [model.GAIN_DEFAULTS[g]] for g in RANGES}
    for g, (lo, hi) in RANGES.items():
        sets[g].extend(rng.uniform(lo, hi, SETS - 1))
    return {g: np.array(v) for g, v in sets.items()}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=os.path.join(HERE, "..", "..", "tests", "fixtures", "numpy_peer_metrics.csv"))
    a = ap.parse_args()
    gains = gain_sets()
    rows = []
    for amp in AMPLITUDES_G:
        ref = model.sine_reference(freq_hz=3.0, amp_g=amp, taper_s=1.0, duration_s=3.0, window_cycles=4)
        out = numpy_peer.simulate(gains, ref, SUBSTEPS)
        for i in range(SETS):
            rows.append([amp] + [gains[g][i] for g in RANGES] + [out[k][i] for k in model.METRICS])
    with open(a.out, "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["amp_g"] + [f"controller.{g}" for g in RANGES] + model.METRICS)
        for r in rows:
            w.writerow([repr(float(x)) for x in r])
    print(f"{len(rows)} rows ({SETS} gain sets x {len(AMPLITUDES_G)} amplitudes) -> {os.path.normpath(a.out)}")


if __name__ == "__main__":
    main()
