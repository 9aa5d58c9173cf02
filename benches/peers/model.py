"""The baseline model of docs/model.md, written once more for the peers: NumPy and JAX.

Everything here is a pure function of arrays whose leading axis is the sample (gain set), written
against an array module `xp` (numpy or jax.numpy), so both peers run the same arithmetic. It is an
independent transcription of the documented model, not a binding to vshake:

* reference: the tapered sine and its exact derivatives (docs/model.md §4);
* controller tick: force high-pass (Tustin), the three-variable command, clamp, spool command
  (the five notches are off by default, depth 0, so they are the identity and left out);
* plant right-hand side: orifice valves with sq(dp) = dp/(dp² + p_tr²)^¼, chambers whose volumes
  follow the stroke, platen with stiffness, viscous C|v|^½ and Coulomb dissipation through the
  friction variable z;
* RK4 with the spool command held over the tick, `substeps` steps per tick;
* metrics over the window (harmonics 1..9 of the acceleration, the displacement's fundamental,
  tracking errors, peak valve command), accumulated online.

The two actuators are identical in the baseline, so one is integrated and its force doubled (as
vshake does; the same numbers).
"""

import math

import numpy as np

G = 9.80665
N_HARM = 9

# Defaults (docs/model.md §1; `study params` prints them with their sources).
P = dict(
    p_s=20.7e6, p_r=0.35e6, w3=0.254, r1=0.8, r2=0.512, r4=0.64, k_sp=19.05e-3 / 10.0, u_lim=10.0,
    kv=(10_000.0e-3 / 60.0) / (0.254 * 19.05e-3 * math.sqrt(6.895e6 / 2.0)), p_tr=1e5, n_val=2.0,
    beta=689.5e6, a1=0.2027, a2=0.1297, l=0.75, vd1=0.0, vd2=0.0,
    m=144_000.0, k=1.266e6, c=41_000.0, mu_coef=0.00538, y_yield=2e-4, kappa=0.5,
    f_s=1024.0, d_max=0.75, v_max=1.8, a_max=17.4, j_max=2200.0, f_max=6.8e6, f_hp=1.0,
)

# The gains a study varies (columns of `study run`'s table) and their defaults.
GAINS = ["g_d", "l_d", "l_v", "l_a", "l_j", "g_f"]
GAIN_DEFAULTS = dict(g_d=1.5, l_d=0.0, l_v=0.38, l_a=0.52, l_j=0.005, g_f=-1.5)

METRICS = ["amp_ratio", "phase_err_deg"] + [f"h{k}_ratio" for k in range(2, 10)] + [
    "thd_odd_ratio", "thd_even_ratio", "rms_err_accel_ratio", "rms_err_disp_ratio",
    "peak_err_accel_mps2", "max_abs_valve_cmd_v", "disp_amp_ratio", "disp_phase_err_deg"]


def sine_reference(freq_hz, amp_g, taper_s, duration_s, window_cycles, f_s=P["f_s"]):
    """Per tick: x_r, v_r, a_r, j_r (exact derivatives of the tapered sine), the window mask and
    the harmonic basis cos/sin(2π h f t_k), h = 1..9 (zero outside the window)."""
    n = int(round(duration_s * f_s))
    t = np.arange(n) / f_s
    w = 2.0 * math.pi * freq_hz
    amp = amp_g * G / w**2
    s, c = np.sin(w * t), np.cos(w * t)
    sd = [s, w * c, -w * w * s, -w * w * w * c]
    p = math.pi / taper_s
    ps, pc = np.sin(p * t), np.cos(p * t)
    inside = t < taper_s
    ed = [np.where(inside, 0.5 * (1.0 - pc), 1.0), np.where(inside, 0.5 * p * ps, 0.0),
          np.where(inside, 0.5 * p * p * pc, 0.0), np.where(inside, -0.5 * p**3 * ps, 0.0)]
    x = amp * ed[0] * sd[0]
    v = amp * (ed[1] * sd[0] + ed[0] * sd[1])
    a = amp * (ed[2] * sd[0] + 2.0 * ed[1] * sd[1] + ed[0] * sd[2])
    j = amp * (ed[3] * sd[0] + 3.0 * ed[2] * sd[1] + 3.0 * ed[1] * sd[2] + ed[0] * sd[3])
    length = int(round(window_cycles * f_s / freq_hz))
    win = np.zeros(n)
    win[n - length:] = 1.0
    cycles = freq_hz * np.arange(n) / f_s
    phase = 2.0 * math.pi * (cycles - np.floor(cycles))
    h = np.arange(1, N_HARM + 1)[:, None]
    cos = np.cos(h * phase) * win
    sin = np.sin(h * phase) * win
    return dict(x=x, v=v, a=a, j=j, win=win, cos=cos, sin=sin)


def coefficients(gains):
    """Per-sample controller coefficients from a dict of gain arrays (missing gains: defaults)."""
    g = {k: np.asarray(gains.get(k, GAIN_DEFAULTS[k]), dtype=float) for k in GAINS}
    return dict(c_fb=10.0 * g["g_d"] / P["d_max"], c_d=10.0 * g["l_d"] / P["d_max"],
                c_v=10.0 * g["l_v"] / P["v_max"], c_a=10.0 * g["l_a"] / P["a_max"],
                c_j=10.0 * g["l_j"] / P["j_max"], c_f=10.0 * g["g_f"] / P["f_max"])


# Derived constants of the plant (module globals, read by the functions below at each call).
def derive():
    """Sets the constants derived from P; again after `set_plant` changes P."""
    global _K, KW1, KW2, KW3, KW4, P_TR2, MU, KAPPA_NEG, TWO_FS, W_HP, HP_B, HP_A, _R, P1_0, P2_0
    _K = P["n_val"] * P["kv"] * P["w3"]
    KW1, KW2, KW3, KW4 = _K * P["r1"], _K * P["r2"], _K, _K * P["r4"]
    P_TR2 = P["p_tr"] ** 2
    MU = P["mu_coef"] * P["m"] * G
    KAPPA_NEG = 2.0 * P["kappa"] - 1.0
    TWO_FS = 2.0 * P["f_s"]
    W_HP = 2.0 * math.pi * P["f_hp"]
    HP_B = TWO_FS / (TWO_FS + W_HP)
    HP_A = (TWO_FS - W_HP) / (TWO_FS + W_HP)
    _R = P["a1"] / P["a2"]
    P1_0 = (P["p_s"] + P["p_r"]) / (1.0 + _R)
    P2_0 = P1_0 * _R


def set_plant(values):
    """Replaces entries of P (a scalar, or an array with one value per sample: the plant then
    differs from sample to sample) and derives the constants again. f_s stays a scalar."""
    P.update(values)
    derive()


derive()


def force(p1, p2):
    """Total actuator force: two identical actuators."""
    f = p1 * P["a1"] - p2 * P["a2"]
    return f + f


def inv_fourth_root(xp, s):
    """s^(−1/4): NumPy's power; in JAX an inverse square root of a square root, which XLA's CPU
    backend runs about twice as fast as its power function (measured)."""
    if xp is np:
        return s ** -0.25
    from jax import lax
    return lax.rsqrt(xp.sqrt(s))


def rhs(xp, x_c, y, v, z, p1, p2):
    """Derivatives (dy, dv, dz, dp1, dp2) of one actuator's chambers and the platen."""
    pos = x_c > 0.0
    dp1 = xp.where(pos, P["p_s"] - p1, p1 - P["p_r"])
    dp2 = xp.where(pos, p2 - P["p_r"], P["p_s"] - p2)
    k1 = xp.where(pos, KW1, KW3)
    k2 = xp.where(pos, KW2, KW4)
    q1 = k1 * x_c * dp1 * inv_fourth_root(xp, dp1 * dp1 + P_TR2)
    q2 = k2 * x_c * dp2 * inv_fourth_root(xp, dp2 * dp2 + P_TR2)
    b1 = P["beta"] / (P["a1"] * (P["l"] + y) + P["vd1"])
    b2 = P["beta"] / (P["a2"] * (P["l"] - y) + P["vd2"])
    dp1dt = b1 * (q1 - P["a1"] * v)
    dp2dt = b2 * (P["a2"] * v - q2)
    f = force(p1, p2)
    dv = (f - P["k"] * y - (P["c"] * xp.sqrt(xp.abs(v)) + MU) * z) / P["m"]
    zv = z * v
    bracket = xp.where(zv > 0.0, 1.0, xp.where(zv < 0.0, KAPPA_NEG, P["kappa"]))
    dz = v / P["y_yield"] * (1.0 - z * z * bracket)
    return v, dv, dz, dp1dt, dp2dt


def rk4_step(xp, x_c, s, h):
    """One RK4 step of length h with the spool command x_c held."""
    k1 = rhs(xp, x_c, *s)
    k2 = rhs(xp, x_c, *[a + 0.5 * h * b for a, b in zip(s, k1)])
    k3 = rhs(xp, x_c, *[a + 0.5 * h * b for a, b in zip(s, k2)])
    k4 = rhs(xp, x_c, *[a + h * b for a, b in zip(s, k3)])
    return tuple(a + h / 6.0 * (b1 + 2.0 * (b2 + b3) + b4) for a, b1, b2, b3, b4 in zip(s, k1, k2, k3, k4))


def rk4_tick(xp, x_c, s, substeps):
    """One controller tick of the plant: `substeps` RK4 steps. In JAX a `fori_loop`: unrolled, XLA
    fuses the steps into kernels that recompute shared stages (measured 1.8x slower)."""
    h = 1.0 / (P["f_s"] * substeps)
    if xp is np:
        for _ in range(substeps):
            s = rk4_step(xp, x_c, s, h)
        return s
    from jax import lax
    return lax.fori_loop(0, substeps, lambda _, s: rk4_step(xp, x_c, s, h), s)


def command(xp, c, r, x, f_hp):
    """The three-variable controller's valve command (volts, clamped) for reference states r."""
    u = c["c_fb"] * (r[0] - x) + c["c_d"] * r[0] + c["c_v"] * r[1] + c["c_a"] * r[2] + c["c_j"] * r[3] + c["c_f"] * f_hp
    return xp.clip(u, -P["u_lim"], P["u_lim"])


def failed(xp, s):
    """The guard: non-finite state, stroke limit reached, or a pressure outside [−1 MPa, 2 P_S]."""
    y, v, z, p1, p2 = s
    finite = xp.isfinite(y) & xp.isfinite(v) & xp.isfinite(z) & xp.isfinite(p1) & xp.isfinite(p2)
    ok = finite & (xp.abs(y) < P["l"])
    for p in (p1, p2):
        ok = ok & (p >= -1.0e6) & (p <= 2.0 * P["p_s"])
    return ~ok


def finish(acc, ref_acc):
    """Metrics (numpy arrays per sample) from the accumulated sums; NaN where `acc['failed']`."""
    a_re, a_im = acc["a_re"], acc["a_im"]
    ar_re, ar_im, xr_re, xr_im, ar2, xr2 = ref_acc

    def wrap(rad):
        d = np.degrees(rad) % 360.0
        return np.where(d > 180.0, d - 360.0, d)

    h1 = np.hypot(a_re[0], a_im[0])
    out = dict(
        amp_ratio=h1 / math.hypot(ar_re, ar_im),
        phase_err_deg=wrap(np.arctan2(-a_im[0], a_re[0]) - math.atan2(-ar_im, ar_re)),
    )
    h = [np.hypot(a_re[k - 1], a_im[k - 1]) / h1 for k in range(2, N_HARM + 1)]
    for k in range(2, N_HARM + 1):
        out[f"h{k}_ratio"] = h[k - 2]
    out["thd_odd_ratio"] = np.sqrt(sum(h[k - 2] ** 2 for k in (3, 5, 7, 9)))
    out["thd_even_ratio"] = np.sqrt(sum(h[k - 2] ** 2 for k in (2, 4, 6, 8)))
    out["rms_err_accel_ratio"] = np.sqrt(acc["err_a2"] / ar2)
    out["rms_err_disp_ratio"] = np.sqrt(acc["err_x2"] / xr2)
    out["peak_err_accel_mps2"] = acc["peak_err_a"]
    out["max_abs_valve_cmd_v"] = acc["max_u"]
    out["disp_amp_ratio"] = np.hypot(acc["x_re"], acc["x_im"]) / math.hypot(xr_re, xr_im)
    out["disp_phase_err_deg"] = wrap(np.arctan2(-acc["x_im"], acc["x_re"]) - math.atan2(-xr_im, xr_re))
    bad = acc["failed"]
    return {k: np.where(bad, np.nan, np.asarray(val, dtype=float)) for k, val in out.items()}


def reference_sums(ref):
    """The reference's own sums over the window (shared by every sample)."""
    w = ref["win"]
    return (float(np.sum(ref["a"] * ref["cos"][0])), float(np.sum(ref["a"] * ref["sin"][0])),
            float(np.sum(ref["x"] * ref["cos"][0])), float(np.sum(ref["x"] * ref["sin"][0])),
            float(np.sum(w * ref["a"] ** 2)), float(np.sum(w * ref["x"] ** 2)))
