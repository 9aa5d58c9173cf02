#!/usr/bin/env python3
"""vshake against its peers on the same work, in one run.

The work: `--samples` random gain sets (the gains sweep's six gains and ranges), each a 3 Hz,
1.73 g sine of 3 s (1 s taper, metrics over the last 4 cycles), RK4 with `--substeps` steps per
controller tick (a list runs each). For each substep count:

1. `study run` on a study file written for the work (wall time including start-up, every thread
   of the machine, and the Parquet write);
2. the NumPy peer and the JAX peer (numpy_peer.py, jax_peer.py: the same baseline model) on the
   gain sets that `study run` drew (read back from its table), one process per core, each with a
   contiguous share. JAX's compile time is excluded (each process compiles, then all start
   together); NumPy needs none;
3. every peer's metrics against `study`'s on `--check` random gain sets: the largest difference
   over every metric, relative to max(|value|, 1) (a phase in degrees, a ratio); more than 1e-9
   fails the run (exit 1).

Prints simulated seconds per wall second for each. Usage (from the repository root):

    python3 benches/peers/run.py                        # 4096 sets, substeps 4 and 8, NumPy + JAX
    python3 benches/peers/run.py --samples 256 --peers numpy --substeps 4   # what CI runs

Needs numpy and pyarrow; jax for the JAX peer (`pip install jax`), skipped with a note if absent.
"""

import argparse
import multiprocessing as mp
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

# The peers are CPU programs: JAX is kept off a GPU that the machine may have.
os.environ.setdefault("JAX_PLATFORMS", "cpu")

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import model  # noqa: E402

RANGES = dict(g_d=(1.1, 1.9), l_v=(0.29, 0.47), l_a=(0.39, 0.65), l_j=(0.0, 0.01), g_f=(-1.9, -1.1), l_d=(0.0, 0.1))
WORK = dict(freq_hz=3.0, amp_g=1.73, taper_s=1.0, duration_s=3.0, window_cycles=4)


def study_toml(samples, substeps):
    variables = "".join(
        f'[[variables]]\nname = "controller.{g}"\ndistribution = "uniform"\nlow = {lo}\nhigh = {hi}\n\n'
        for g, (lo, hi) in RANGES.items())
    return (f'[study]\nname = "peers"\nseed = 7\nsamples = {samples}\n\n[method]\nsampling = "monte_carlo"\n\n'
            f'{variables}[[excitations]]\nname = "sine_3hz_1p73g"\nkind = "sine"\n'
            + "".join(f"{k} = {v}\n" for k, v in WORK.items())
            + f"\n[solver]\nsubsteps = {substeps}\nchunk = 64\n")


def run_study(binary, samples, substeps, tmp, backend="cpu"):
    """`study run` on the work: (wall seconds, gains dict, metrics dict, ok mask)."""
    import pyarrow.parquet as pq
    toml = os.path.join(tmp, f"peers_{substeps}.toml")
    out = os.path.join(tmp, f"peers_{substeps}.parquet")
    with open(toml, "w") as f:
        f.write(study_toml(samples, substeps))
    t0 = time.perf_counter()
    subprocess.run([binary, "run", toml, "--out", out, "-q", "--backend", backend], check=True,
                   stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    t = pq.read_table(out)
    gains = {g: t.column(g).to_numpy() for g in RANGES}
    metrics = {k: t.column(k).to_numpy() for k in model.METRICS}
    ok = np.array([s == "ok" for s in t.column("status").to_pylist()])
    return wall, gains, metrics, ok


def _share(gains, i, procs):
    n = len(next(iter(gains.values())))
    lo, hi = i * n // procs, (i + 1) * n // procs
    return {k: v[lo:hi] for k, v in gains.items()}


def _numpy_worker(args):
    gains, substeps = args
    import numpy_peer
    ref = model.sine_reference(**WORK)
    return numpy_peer.simulate(gains, ref, substeps)


def _jax_worker(args):
    gains, substeps, barrier = args
    import jax_peer
    ref = model.sine_reference(**WORK)
    fn = jax_peer.compiled(len(gains["g_d"]), ref, substeps)
    barrier.wait()  # every process compiled: start together
    t0 = time.perf_counter()
    out = jax_peer.simulate(fn, gains, ref)
    return out, time.perf_counter() - t0


def _joined(parts):
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def run_numpy(gains, substeps, procs):
    t0 = time.perf_counter()
    with mp.get_context("fork").Pool(procs) as pool:
        parts = pool.map(_numpy_worker, [(_share(gains, i, procs), substeps) for i in range(procs)])
    return time.perf_counter() - t0, _joined(parts)


def run_jax(gains, substeps, procs):
    ctx = mp.get_context("spawn")
    with ctx.Manager() as manager:
        barrier = manager.Barrier(procs)
        with ctx.Pool(procs) as pool:
            done = pool.map(_jax_worker, [(_share(gains, i, procs), substeps, barrier) for i in range(procs)])
    return max(t for _, t in done), _joined([o for o, _ in done])


def deviation(peer, study, rows):
    """Largest |peer − study| / max(|study|, 1) over every metric on `rows`."""
    worst = 0.0
    for k in model.METRICS:
        a, b = peer[k][rows], study[k][rows]
        worst = max(worst, float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1.0))))
    return worst


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--study", default="target/release/study", help="the study binary")
    ap.add_argument("--samples", type=int, default=4096)
    ap.add_argument("--substeps", default="4,8", help="comma-separated RK4 substeps per tick")
    ap.add_argument("--peers", default="numpy,jax", help="comma-separated: numpy, jax")
    ap.add_argument("--procs", type=int, default=os.cpu_count(), help="peer processes (one per core)")
    ap.add_argument("--check", type=int, default=64, help="gain sets checked against study")
    ap.add_argument("--backend", default="cpu", help="study's --backend (cpu: the peers' own ground)")
    a = ap.parse_args()
    peers = [p for p in a.peers.split(",") if p]
    if "jax" in peers:
        try:
            import jax  # noqa: F401
        except ImportError:
            print("jax is not installed (pip install jax): the JAX peer is skipped", file=sys.stderr)
            peers.remove("jax")
    sim_s = a.samples * WORK["duration_s"]
    print(f"work: {a.samples} gain sets x {WORK['duration_s']:g} s (3 Hz, 1.73 g) = {sim_s:g} simulated s; "
          f"{os.cpu_count()} cores; peers with {a.procs} processes")
    print(f"{'engine':<8} {'substeps':>8} {'wall s':>9} {'sim-s/s':>10} {'vs vshake':>10} {'max dev':>9}")
    rng = np.random.default_rng(1)
    failed = False
    with tempfile.TemporaryDirectory() as tmp:
        for substeps in [int(s) for s in a.substeps.split(",")]:
            wall, gains, metrics, ok = run_study(a.study, a.samples, substeps, tmp, a.backend)
            rate = sim_s / wall
            print(f"{'vshake':<8} {substeps:>8} {wall:>9.2f} {rate:>10.0f} {1.0:>10.2f} {'-':>9}", flush=True)
            rows = rng.choice(np.flatnonzero(ok), size=min(a.check, int(ok.sum())), replace=False)
            for peer in peers:
                w, out = (run_numpy if peer == "numpy" else run_jax)(gains, substeps, a.procs)
                dev = deviation(out, metrics, rows)
                failed |= not dev <= 1e-9
                print(f"{peer:<8} {substeps:>8} {w:>9.2f} {sim_s / w:>10.0f} {(sim_s / w) / rate:>10.3f} {dev:>9.1e}", flush=True)
    if failed:
        print("a peer differs from study by more than 1e-9 (relative to max(|value|, 1))", file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
