"""The baseline model in NumPy, vectorised over samples: every array holds one value per gain
set, and the time loop runs in Python (one tick = `substeps` RK4 steps of whole arrays)."""

import numpy as np

import model as m


def simulate(gains, ref, substeps):
    """Metrics per sample (dict of arrays) for the gain sets `gains` (dict of equal-length arrays)
    driven by `ref` (model.sine_reference)."""
    c = m.coefficients(gains)
    n_s = len(c["c_fb"])
    zeros = np.zeros(n_s)
    s = (zeros, zeros, zeros, np.full(n_s, m.P1_0), np.full(n_s, m.P2_0))
    f_prev = m.force(s[3], s[4])
    f_hp = zeros
    acc = dict(a_re=np.zeros((m.N_HARM, n_s)), a_im=np.zeros((m.N_HARM, n_s)), x_re=zeros, x_im=zeros,
               err_a2=zeros, err_x2=zeros, peak_err_a=zeros, max_u=zeros, failed=np.zeros(n_s, bool))
    rx, rv, ra, rj, win, cos, sin = ref["x"], ref["v"], ref["a"], ref["j"], ref["win"], ref["cos"], ref["sin"]
    for k in range(len(rx)):
        f = m.force(s[3], s[4])
        f_hp = m.HP_B * (f - f_prev) + m.HP_A * f_hp
        f_prev = f
        x = s[0]
        u = m.command(np, c, (rx[k], rv[k], ra[k], rj[k]), x, f_hp)
        x_c = m.P["k_sp"] * u
        a = m.rhs(np, x_c, *s)[1]
        acc["max_u"] = np.maximum(acc["max_u"], np.abs(u))
        if win[k]:
            ea, ex = a - ra[k], x - rx[k]
            acc["err_a2"] = acc["err_a2"] + ea * ea
            acc["err_x2"] = acc["err_x2"] + ex * ex
            acc["peak_err_a"] = np.maximum(acc["peak_err_a"], np.abs(ea))
            acc["a_re"] += np.outer(cos[:, k], a)
            acc["a_im"] += np.outer(sin[:, k], a)
            acc["x_re"] = acc["x_re"] + x * cos[0, k]
            acc["x_im"] = acc["x_im"] + x * sin[0, k]
        s = m.rk4_tick(np, x_c, s, substeps)
        acc["failed"] |= m.failed(np, s)
    return m.finish(acc, m.reference_sums(ref))
