#!/usr/bin/env python3
"""Writes the NumPy peer's metrics for effect `expression` (physics written in a model file,
docs/formats.md "Expressions"): tests/fixtures/numpy_peer_expressions.csv and, beside it, the
expressions themselves (numpy_peer_expressions.tsv: scenario, hook, source; tab-separated, since
an expression holds commas).

Each scenario gives some hooks an expression that reads every quantity of its hook, the time t
and named parameters, and together they use every function of the language. The peer
(effects.Expression) evaluates the documented language with NumPy's functions under Python's
grammar (`^` read as `**`): no code shared with vshake's parser or interpreter. 50 random
parameter sets per scenario (seed 2028), on the 3 Hz reference sine at 1.73 g (3 s, 1 s taper,
the last 4 cycles), default gains, RK4 with 4 substeps, as make_effects_fixture.py; and one row
of the effect switched on with no expression (neutral: the baseline). `cargo test`
(crates/kernel/tests/peers.rs) runs the same cases and holds every metric to 1e-9.

Columns: the effect (`expression:SCENARIO`), the amplitude, the parameters as
`expression.NAME=value` joined by `;`, then make_effects_fixture.py's metrics.

    python3 benches/peers/make_expression_fixture.py [--out tests/fixtures/numpy_peer_expressions.csv]

Needs numpy. The files are committed; regenerate when docs/formats.md's language changes.
"""

import argparse
import csv
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import effects  # noqa: E402
import make_effects_fixture as fixture  # noqa: E402
import model  # noqa: E402

# Each scenario: its hooks' sources, and each named parameter's range (its own units).
SCENARIOS = {
    # A quadratic damper, a cubic spring, a smoothed friction and a shaker on the platen, N.
    "force": (
        dict(force="-c2*v*abs(v) - k3*y^3 - fc*tanh(v/ve) + f0*sin(2*pi*fh*t)"),
        dict(c2=(0.0, 3e5), k3=(-2e9, 8e9), fc=(0.0, 3e4), ve=(1e-3, 2e-2), f0=(0.0, 3e4),
             fh=(5.0, 40.0)),
    ),
    # Flows across the piston, to drain with a pulsing gain, from the supply, into each chamber.
    "flows": (
        dict(flow_1="cl*(p2 - p1) - ce*p1*(1 + cos(2*pi*ft*t))/2 + cs*(ps - p1)*step(ps - p1)",
             flow_2="cl*(p1 - p2) - ce2*sqrt(abs(p2))"),
        dict(cl=(0.0, 2e-10), ce=(0.0, 2e-11), ft=(1.0, 20.0), cs=(0.0, 5e-12), ce2=(0.0, 1e-8)),
    ),
    # Overlapping lands (a dead band) and a flow gain that grows with the opening.
    "opening": (
        dict(opening="sign(x)*max(abs(x) - delta, 0)*(1 + g2*(x/xr)^2)"),
        dict(delta=(0.0, 1e-3), g2=(-0.3, 0.3), xr=(0.01, 0.03)),
    ),
    # A supply that sags and ripples.
    "supply": (
        dict(supply="ps - dp*ln(1 + t/ts) + a_s*cos(2*pi*fs*t)"),
        dict(dp=(0.0, 1.5e6), ts=(0.1, 3.0), a_s=(0.0, 5e5), fs=(1.0, 60.0)),
    ),
    # A measurement chain: gains, drifting and fixed offsets, saturations and soft limits.
    "channels": (
        dict(accel_channel="ga*a + a0*sqrt(1 + t) + aw*atan(a/aw)*exp(-t/te)",
             disp_channel="min(d + d0, dmax) + dl*atan2(d, dw)",
             force_channel="gf*f + cf*clamp(f/fw, -1, 1) + ch*log10(1 + abs(f)/fw) + fo*pow(tan(0.3*t), 2)"),
        dict(ga=(0.9, 1.1), a0=(-0.2, 0.2), aw=(5.0, 40.0), te=(0.2, 3.0), d0=(-2e-3, 2e-3),
             dmax=(0.02, 0.045), dl=(-2e-3, 2e-3), dw=(0.01, 0.05), gf=(0.9, 1.1), cf=(-2e4, 2e4),
             fw=(2e5, 2e6), ch=(-5e3, 5e3), fo=(-1e4, 1e4)),
    ),
}


def draws(ranges, rng):
    """fixture.SETS sets, each parameter uniform over its range."""
    return {k: rng.uniform(lo, hi, fixture.SETS) for k, (lo, hi) in ranges.items()}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=os.path.join(HERE, "..", "..", "tests", "fixtures", "numpy_peer_expressions.csv"))
    a = ap.parse_args()
    rng = np.random.default_rng(2028)
    ref = model.sine_reference(freq_hz=3.0, amp_g=fixture.AMP_G, taper_s=1.0, duration_s=3.0, window_cycles=4)
    rows, sources = [], []
    for scenario, (hooks, ranges) in SCENARIOS.items():
        params = draws(ranges, rng)
        out = effects.simulate("expression", params, ref, fixture.SUBSTEPS, hooks)
        name = f"expression:{scenario}"
        for i in range(fixture.SETS):
            set_ = ";".join(f"expression.{k}={float(params[k][i])!r}" for k in ranges)
            rows.append([name, repr(fixture.AMP_G), set_] + fixture.cells(out, i))
        sources += [[scenario, hook, src] for hook, src in hooks.items()]
        failed = int(np.isnan(out["amp_ratio"]).sum())
        print(f"{name}: {fixture.SETS} sets, {failed} stopped by the guard")
    # The effect on with no expression: neutral.
    out = effects.simulate("expression", {}, ref, fixture.SUBSTEPS, {})
    rows.append(["expression:none", repr(fixture.AMP_G), ""] + fixture.cells(out, 0))
    with open(a.out, "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["effect", "amp_g", "params"] + model.METRICS + fixture.EXTRA)
        w.writerows(rows)
    tsv = os.path.splitext(a.out)[0] + ".tsv"
    with open(tsv, "w") as f:
        f.write("".join("\t".join(r) + "\n" for r in sources))
    print(f"{len(rows)} rows -> {os.path.normpath(a.out)}; the expressions -> {os.path.normpath(tsv)}")


if __name__ == "__main__":
    main()
