"""Draws docs/guide.md's record-sweep figures as plain SVG (no plotting library needed).

usage (from the repository root, after the commands in docs/guide.md "Earthquakes"):
  python3 docs/figures/make_figures.py firm_published_spectrum.parquet firm_tuned_spectrum.parquet \
      record_sweep_sensitivity.parquet docs/figures
"""
import math
import sys

import pyarrow.parquet as pq

published, tuned, sensitivity, out = sys.argv[1:5]
W, H, L, R, T, B = 640, 360, 70, 20, 30, 50


def axes(title, xlabel, ylabel, xticks, yticks, xmap, ymap):
    s = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" font-family="sans-serif" font-size="12">',
         f'<rect width="{W}" height="{H}" fill="white"/>',
         f'<text x="{W / 2}" y="18" text-anchor="middle" font-size="14">{title}</text>',
         f'<text x="{W / 2}" y="{H - 10}" text-anchor="middle">{xlabel}</text>',
         f'<text x="16" y="{H / 2}" text-anchor="middle" transform="rotate(-90 16 {H / 2})">{ylabel}</text>',
         f'<rect x="{L}" y="{T}" width="{W - L - R}" height="{H - T - B}" fill="none" stroke="black"/>']
    for v, label in xticks:
        x = xmap(v)
        s.append(f'<line x1="{x}" y1="{H - B}" x2="{x}" y2="{H - B + 5}" stroke="black"/><text x="{x}" y="{H - B + 18}" text-anchor="middle">{label}</text>')
    for v, label in yticks:
        y = ymap(v)
        s.append(f'<line x1="{L - 5}" y1="{y}" x2="{W - R}" y2="{y}" stroke="#ddd"/><text x="{L - 8}" y="{y + 4}" text-anchor="end">{label}</text>')
    return s


def spectra():
    p, t = pq.read_table(published).to_pydict(), pq.read_table(tuned).to_pydict()
    periods = p["period_s"]
    top = 1.1 * max(max(p["psa_target_g"]), max(p["psa_g"]), max(t["psa_g"]))
    xmap = lambda v: L + (math.log(v) - math.log(periods[0])) / (math.log(periods[-1]) - math.log(periods[0])) * (W - L - R)
    ymap = lambda v: H - B - v / top * (H - T - B)
    xt = [(v, f"{v:g}") for v in [0.05, 0.1, 0.2, 0.5, 1, 2, 4]]
    yt = [(v / 10 * round(top * 10) / 5, f"{v / 10 * round(top * 10) / 5:.2f}") for v in range(0, 6)]
    s = axes("5 %-damped response spectra, firm_0p5g", "period (s)", "PSA (g)", xt, yt, xmap, ymap)
    for ys, colour, label in [(p["psa_target_g"], "black", "target"), (p["psa_g"], "#d62728", "achieved, published gains"), (t["psa_g"], "#1f77b4", "achieved, best gains of the sweep")]:
        pts = " ".join(f"{xmap(x):.1f},{ymap(y):.1f}" for x, y in zip(periods, ys))
        s.append(f'<polyline points="{pts}" fill="none" stroke="{colour}" stroke-width="2"/>')
    for i, (colour, label) in enumerate([("black", "target"), ("#d62728", "achieved, published gains"), ("#1f77b4", "achieved, best gains of the sweep")]):
        y = T + 18 + 16 * i
        s.append(f'<line x1="{W - 250}" y1="{y}" x2="{W - 225}" y2="{y}" stroke="{colour}" stroke-width="2"/><text x="{W - 220}" y="{y + 4}">{label}</text>')
    return s + ["</svg>"]


def indices():
    d = pq.read_table(sensitivity).to_pydict()
    rows = [(m, e, p, st) for m, e, p, st in zip(d["metric"], d["excitation"], d["parameter"], d["st"]) if m == "spectral_err_mean"]
    motions = sorted({r[1] for r in rows})
    params = sorted({r[2] for r in rows})
    xmap = lambda i: L + (i + 0.5) / len(params) * (W - L - R)
    ymap = lambda v: H - B - min(max(v, 0), 1) * (H - T - B)
    s = axes("total Sobol' index of spectral_err_mean", "", "S_T", [(i, params[i].split(".")[-1]) for i in range(len(params))], [(v / 5, f"{v / 5:.1f}") for v in range(6)], xmap, ymap)
    colours = ["#1f77b4", "#ff7f0e", "#2ca02c"]
    bw = (W - L - R) / len(params) / (len(motions) + 1)
    for j, m in enumerate(motions):
        for m_, e, p, st in rows:
            if e == m:
                x = xmap(params.index(p)) - bw * len(motions) / 2 + j * bw
                s.append(f'<rect x="{x:.1f}" y="{ymap(st):.1f}" width="{bw:.1f}" height="{ymap(0) - ymap(st):.1f}" fill="{colours[j]}"/>')
        s.append(f'<rect x="{W - 130}" y="{T + 10 + 16 * j}" width="10" height="10" fill="{colours[j]}"/><text x="{W - 115}" y="{T + 19 + 16 * j}">{m}</text>')
    return s + ["</svg>"]


for name, svg in [("record_sweep_spectra.svg", spectra()), ("record_sweep_sobol.svg", indices())]:
    with open(f"{out}/{name}", "w") as f:
        f.write("\n".join(svg) + "\n")
    print(f"wrote {out}/{name}")
