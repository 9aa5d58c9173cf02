#!/usr/bin/env python3
"""Writes tests/fixtures/numpy_peer_effects.csv: the NumPy peer's metrics with one library effect
switched on (effects.py, a transcription of docs/model.md §7's laws and the effects' documented
laws, sharing no code with vshake), 50 random parameter sets per effect, every library effect, drawn away from the defaults and across each range
(seed 2027), on the 3 Hz reference sine at 1.73 g (3 s, 1 s taper, the last 4 cycles), default
gains, RK4 with 4 substeps. `cargo test` (crates/kernel/tests/peers.rs) runs the same cases through the
kernel and holds every metric to 1e-9 of these values, relative to max(|value|, 1).

One row per case: the effect, the amplitude, its parameters as `path=value` joined by `;`, then
the metrics, the recorded actuator force's projections on the reference's acceleration and
velocity over the window (`force_a_kg`, `force_v_n_s_per_m`: the force sensor changes only those) and the building's metrics (empty for the other effects); values with 17
significant digits. A run the peer stops has every metric `nan`.
Each effect's last row has no parameters: the peer runs the documented defaults (`DEFAULTS`), the
kernel its own, so that a default changed in either fails the test.

    python3 benches/peers/make_effects_fixture.py [--out tests/fixtures/numpy_peer_effects.csv]

Needs numpy. Regenerate only when docs/model.md changes; the file is committed.
"""

import argparse
import csv
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import effects  # noqa: E402
import model  # noqa: E402

SETS = 50
SUBSTEPS = 4
AMP_G = 1.73


def draws(name, rng):
    """SETS parameter sets of effect `name`: each parameter over a range around (not at) its
    default, in its own units."""
    u = lambda lo, hi: rng.uniform(lo, hi, SETS)  # noqa: E731
    if name == "specimen":
        on2, on3 = rng.uniform(size=SETS) < 0.6, rng.uniform(size=SETS) < 0.3
        f1 = u(1.0, 10.0)
        return dict(m1=u(5e3, 150e3), f1=f1, zeta1=u(0.005, 0.1),
                    m2=np.where(on2, u(2e3, 60e3), 0.0), f2=f1 * u(2.0, 4.0), zeta2=u(0.005, 0.1),
                    m3=np.where(on3, u(1e3, 30e3), 0.0), f3=f1 * u(4.5, 7.0), zeta3=u(0.005, 0.1))
    if name == "hold_down":
        return dict(k3=u(-1e9, 5e9))
    if name == "seal_friction":
        f_c = u(1e3, 4e4)
        return dict(f_c=f_c, f_s=f_c * u(1.0, 2.5), v_s=u(0.002, 0.05), sigma=u(0.0, 2e5),
                    v_eps=u(2e-4, 5e-3))
    if name == "spool_dynamics":
        return dict(freq_hz=u(40.0, 300.0), zeta=u(0.3, 1.5))
    if name == "flow_saturation":
        return dict(x_sat=u(0.004, 0.03))
    if name == "leakage":
        return dict(c_int=u(0.0, 2e-10), c_ext=u(0.0, 2e-11))
    if name == "transport_delay":
        return dict(tau=u(0.5e-3, 0.01))
    if name == "flow_gain":
        return dict(g0=u(0.5, 1.5), g1=u(0.5, 1.5), g2=u(0.5, 1.5), g3=u(0.5, 1.5), g4=u(0.5, 1.5),
                    x_ref=u(0.012, 0.03))
    if name == "asymmetry":
        return dict(extend_gain=u(0.85, 1.2), act2_gain=u(0.8, 1.2))
    if name == "supply":
        return dict(q_pump=u(0.05, 0.4), c_acc=u(1e-8, 1e-7), dp_band=u(2e5, 3e6))
    if name == "compressibility":
        return dict(dead_volume=u(0.0, 0.05), beta_ratio=u(0.3, 1.0), air_fraction=u(0.0, 0.05))
    if name == "bulk_curve":
        return dict(b0=u(0.3, 2.0), b1=u(0.3, 2.0), b2=u(0.3, 2.0))
    if name == "reaction_mass":
        return dict(m_r=u(2e5, 5e6), f_r=u(5.0, 40.0), zeta_r=u(0.02, 0.5))
    if name == "building":
        sets = dict(storeys=rng.integers(1, 11, SETS).astype(float), law=rng.integers(0, 3, SETS).astype(float),
                    alpha=u(0.0, 0.2), zeta=u(0.005, 0.05), height=u(2.5, 4.0), bw_a=u(0.9, 1.1),
                    bw_beta=u(0.3, 0.7), bw_gamma=u(0.3, 0.7), bw_n=u(1.5, 8.0))
        for i in range(1, 11):
            sets[f"m{i}"], sets[f"k{i}"], sets[f"fy{i}"] = u(5e3, 40e3), u(10e6, 60e6), u(50e3, 400e3)
        return sets
    if name in ("accel_sensor", "disp_sensor", "force_sensor"):
        # Both realisations of the delay: its Taylor series below 0.5 ms, the Padé states above.
        short = rng.uniform(size=SETS) < 0.3
        return dict(f_c=u(20.0, 300.0), zeta=u(0.3, 1.5),
                    delay=np.where(short, u(0.0, 0.5e-3), u(0.5e-3, 5e-3)))
    if name == "valve_compensator":
        return dict(g_min=u(0.05, 1.0))
    if name in ("amplitude_phase", "harmonic_cancellation"):
        # Half adapt to the end (freeze_s = 0), half are frozen within the run.
        frozen = rng.uniform(size=SETS) < 0.5
        # AHC's band below the harmonics' spacing (6 Hz at 3 Hz): wider, its cancellers take in
        # their neighbours and the loop goes unstable, which would compare failures only.
        apc = name == "amplitude_phase"
        return dict(gain=u(0.5, 10.0), band_hz=u(0.5, 10.0) if apc else u(0.2, 1.0),
                    delay_s=u(0.0, 6e-3), authority=u(0.002, 2.0 if apc else 0.2),
                    freeze_s=np.where(frozen, u(1.2, 2.9), 0.0))
    if name == "adaptive_inverse":
        # Half weighted, half not (weight_hz = 0); half following the fit within the run (a copy
        # of 10-40 s: with one of 1-8 s the fit's first ticks, the table barely moving and P at
        # 1e6, amplify rounding 5e5-fold, and two correct implementations part by 1e-9; a third
        # frozen; taps at the start near the identity.
        sets = dict(memory_s=u(0.5, 60.0), corner_hz=u(0.3, 30.0), anticipation_s=u(0.0, 0.0156),
                    weight_hz=np.where(rng.uniform(size=SETS) < 0.5, u(0.5, 20.0), 0.0),
                    copy_s=np.where(rng.uniform(size=SETS) < 0.5, u(10.0, 40.0), 0.0),
                    freeze_s=np.where(rng.uniform(size=SETS) < 0.33, u(1.0, 2.9), 0.0))
        sets["w_0"] = u(0.8, 1.2)
        for i in range(1, 16):
            sets[f"w_{i}"] = u(-0.05, 0.05)
        return sets
    raise KeyError(name)


# Each effect's defaults, as docs/model.md §7's table and `study params NAME` give them: one more
# row per effect, whose parameters the kernel leaves at its own defaults (an empty `params`), so
# that a changed default fails the test.
DEFAULTS = {
    "specimen": dict(m1=20e3, f1=3.0, zeta1=0.03, m2=0.0, f2=9.0, zeta2=0.03, m3=0.0, f3=15.0, zeta3=0.03),
    "hold_down": dict(k3=1e8),
    "seal_friction": dict(f_c=5e3, f_s=8e3, v_s=0.01, sigma=0.0, v_eps=1e-3),
    "spool_dynamics": dict(freq_hz=80.0, zeta=0.7),
    "transport_delay": dict(tau=2e-3),
    "flow_saturation": dict(x_sat=0.012),
    "flow_gain": dict(g0=1.0, g1=1.0, g2=1.0, g3=1.0, g4=1.0, x_ref=0.01905),
    "asymmetry": dict(extend_gain=1.05, act2_gain=1.0),
    "leakage": dict(c_int=2e-11, c_ext=0.0),
    "supply": dict(q_pump=0.2, c_acc=3.5e-8, dp_band=1e6),
    "compressibility": dict(dead_volume=0.02, beta_ratio=1.0, air_fraction=0.01),
    "bulk_curve": dict(b0=1.0, b1=1.0, b2=1.0),
    "reaction_mass": dict(m_r=2e6, f_r=12.0, zeta_r=0.1),
    "accel_sensor": dict(f_c=80.0, zeta=2.0 ** -0.5, delay=1e-3),
    "disp_sensor": dict(f_c=100.0, zeta=2.0 ** -0.5, delay=1e-3),
    "force_sensor": dict(f_c=100.0, zeta=2.0 ** -0.5, delay=1e-3),
    "building": dict(storeys=3.0, law=1.0, alpha=0.05, zeta=0.02, height=3.0, bw_a=1.0, bw_beta=0.5,
                     bw_gamma=0.5, bw_n=2.0,
                     **{f"m{i}": 30e3 for i in range(1, 11)}, **{f"k{i}": 24e6 for i in range(1, 11)},
                     **{f"fy{i}": 250e3 for i in range(1, 11)}),
    "valve_compensator": dict(g_min=0.2),
    "amplitude_phase": dict(gain=2.0, band_hz=5.0, delay_s=2.8e-3, authority=1.0, freeze_s=0.0),
    "harmonic_cancellation": dict(gain=2.0, band_hz=0.5, delay_s=2.8e-3, authority=0.05, freeze_s=0.0),
    "adaptive_inverse": dict(memory_s=30.0, corner_hz=2.0, anticipation_s=2.8e-3, weight_hz=5.0, copy_s=0.0,
                             freeze_s=0.0, w_0=1.0, **{f"w_{i}": 0.0 for i in range(1, 16)}),
}
# Columns beyond model.METRICS: the recorded force's projections over the window, and the building's
# metrics (empty in the other effects' rows).
EXTRA = ["force_a_kg", "force_v_n_s_per_m", "peak_drift_ratio", "peak_base_shear_n", "ductility_demand", "hysteretic_energy_j"]


def cells(out, i):
    """Row i's metrics as text; empty where the effect has none."""
    return [repr(float(out[k][i])) if k in out else "" for k in model.METRICS + EXTRA]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=os.path.join(HERE, "..", "..", "tests", "fixtures", "numpy_peer_effects.csv"))
    a = ap.parse_args()
    rng = np.random.default_rng(2027)
    ref = model.sine_reference(freq_hz=3.0, amp_g=AMP_G, taper_s=1.0, duration_s=3.0, window_cycles=4)
    rows = []
    for name, cls in effects.EFFECTS.items():
        params = draws(name, rng)
        assert sorted(params) == sorted(cls.names), name
        # The defaults as one more sample of the same run (samples are independent).
        batch = {k: np.append(v, DEFAULTS[name][k]) for k, v in params.items()}
        out = effects.simulate(name, batch, ref, SUBSTEPS)
        for i in range(SETS):
            set_ = ";".join(f"{name}.{k}={float(params[k][i])!r}" for k in cls.names)
            rows.append([name, repr(AMP_G), set_] + cells(out, i))
        rows.append([name, repr(AMP_G), ""] + cells(out, SETS))
        failed = int(np.isnan(out["amp_ratio"][:SETS]).sum())
        print(f"{name}: {SETS} sets, {failed} stopped by the guard")
    with open(a.out, "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["effect", "amp_g", "params"] + model.METRICS + EXTRA)
        w.writerows(rows)
    print(f"{len(rows)} rows -> {os.path.normpath(a.out)}")


if __name__ == "__main__":
    main()
