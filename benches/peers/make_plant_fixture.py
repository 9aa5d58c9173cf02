#!/usr/bin/env python3
"""Writes tests/fixtures/numpy_peer_plant.csv: the NumPy peer's metrics (numpy_peer.py) for 24
random sets of every plant and controller-scaling constant the peer models, at 0.5 and 1.73 g of
the 3 Hz reference sine (3 s, 1 s taper, the last 4 cycles), RK4 with 4 substeps, default gains.
`cargo test` (crates/kernel/tests/peers.rs) runs the same cases through the kernel and holds every
metric to 1e-9 of these values, relative to max(|value|, 1).

numpy_peer_metrics.csv varies the gains only, so a term of the plant that vanishes at the
defaults (the dead volumes are 0) or whose constant is only ever seen at its default would not be
pinned; here each constant is drawn uniformly over about ±20 % of its default (the dead volumes
over 0-0.04 m³, the valve count over 1-3, the command limit over 1-8 V, so that some sets
clamp the command), one set per sample, seed 2028. A set the peer stops has every metric `nan`,
and the kernel must stop it too.

    python3 benches/peers/make_plant_fixture.py [--out tests/fixtures/numpy_peer_plant.csv]

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

AMPLITUDES_G = [0.5, 1.73]
SETS = 24
SUBSTEPS = 4

# The peer's constant, its path in vshake, and the range drawn from.
RANGES = [
    ("p_s", "servovalve.p_s", 16.5e6, 24.8e6),
    ("p_r", "servovalve.p_r", 0.2e6, 0.5e6),
    ("w3", "servovalve.w3", 0.2, 0.3),
    ("r1", "servovalve.r1", 0.64, 0.96),
    ("r2", "servovalve.r2", 0.41, 0.61),
    ("r4", "servovalve.r4", 0.51, 0.77),
    ("k_sp", "servovalve.k_sp", 1.52e-3, 2.29e-3),
    ("u_lim", "servovalve.u_lim", 1.0, 8.0),
    ("kv", "servovalve.kv", 0.0148, 0.0223),
    ("p_tr", "servovalve.p_tr", 0.05e6, 0.2e6),
    ("beta", "actuator.beta", 552e6, 827e6),
    ("a1", "actuator.a1", 0.162, 0.243),
    ("a2", "actuator.a2", 0.104, 0.156),
    ("l", "actuator.l", 0.6, 0.9),
    ("vd1", "actuator.vd1", 0.0, 0.04),
    ("vd2", "actuator.vd2", 0.0, 0.04),
    ("m", "platen.m", 115e3, 173e3),
    ("k", "platen.k", 1.01e6, 1.52e6),
    ("c", "platen.c", 32.8e3, 49.2e3),
    ("mu_coef", "platen.mu_coef", 0.0043, 0.0065),
    ("y_yield", "friction.y_yield", 1.6e-4, 2.4e-4),
    ("kappa", "friction.kappa", 0.2, 0.8),
    ("d_max", "controller.d_max", 0.6, 0.9),
    ("v_max", "controller.v_max", 1.44, 2.16),
    ("a_max", "controller.a_max", 13.9, 20.9),
    ("j_max", "controller.j_max", 1760.0, 2640.0),
    ("f_max", "controller.f_max", 5.44e6, 8.16e6),
    ("f_hp", "controller.f_hp", 0.5, 2.0),
]


def plant_sets():
    rng = np.random.default_rng(2028)
    sets = {key: rng.uniform(lo, hi, SETS) for key, _, lo, hi in RANGES}
    sets["n_val"] = rng.integers(1, 4, SETS).astype(float)
    return sets


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=os.path.join(HERE, "..", "..", "tests", "fixtures", "numpy_peer_plant.csv"))
    a = ap.parse_args()
    sets = plant_sets()
    columns = [(key, path) for key, path, _, _ in RANGES] + [("n_val", "servovalve.n_val")]
    model.set_plant(sets)
    gains = {g: np.full(SETS, model.GAIN_DEFAULTS[g]) for g in model.GAINS}
    rows = []
    for amp in AMPLITUDES_G:
        ref = model.sine_reference(freq_hz=3.0, amp_g=amp, taper_s=1.0, duration_s=3.0, window_cycles=4)
        out = numpy_peer.simulate(gains, ref, SUBSTEPS)
        for i in range(SETS):
            rows.append([amp] + [sets[key][i] for key, _ in columns] + [out[k][i] for k in model.METRICS])
    with open(a.out, "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["amp_g"] + [path for _, path in columns] + model.METRICS)
        for r in rows:
            w.writerow([repr(float(x)) for x in r])
    failed = sum(np.isnan(r[-1]) for r in rows)
    print(f"{len(rows)} rows ({SETS} plant sets x {len(AMPLITUDES_G)} amplitudes, {failed} stopped) -> {os.path.normpath(a.out)}")


if __name__ == "__main__":
    main()
