"""Library effects for the NumPy peer, written from docs/model.md §7's table (the laws, the
parameter names of `study params NAME`), not from vshake's Rust: each is a few hooks on the
peer's plant (model.py), vectorised over samples.

An effect is an object with
* `names`: its parameters, in the order `params` holds them (arrays, one value per sample);
* `n`: its extra states per sample;
* `opening(x, es)`: the valve opening from the spool command (identity unless it changes it);
* `flows(q1, q2, p1, p2, x, act, p_s, es)`: the net flows into chamber 1 and out of chamber 2 of
  one actuator (p_s: the supply pressure the valves see);
* `force(y, v, es)`: its force on the platen, N;
* `derivs(x_c, a, y, v, es)`: the derivatives of its states (a: the platen's acceleration);
* `command(u, r, x, t, s)`: a compensator's valve command from the TVC's sum at a tick.

`simulate(name, params, ref, substeps)` runs the baseline with one effect switched on and returns
the metrics of model.py.
"""

import math

import numpy as np

import model as m


class Effect:
    n = 0

    def __init__(self, params):
        self.p = {k: np.asarray(v, dtype=float) for k, v in params.items()}

    def initial(self, n_s):
        """The states at t = 0: zeros."""
        return tuple(np.zeros(n_s) for _ in range(self.n))

    def supply(self, es):
        """The supply pressure the valves see, Pa."""
        return m.P["p_s"]

    def stroke(self, y, v, es):
        """The actuators' stroke and its rate (chambers, LVDT) from the platen's motion."""
        return y, v

    def opening(self, x, es):
        return x

    def flows(self, q1, q2, p1, p2, x, act, p_s, es):
        """The net flows into chamber 1 and out of chamber 2 of actuator `act` (0, 1); `p_s`: the
        supply pressure the valves see."""
        return q1, q2

    def stiffness(self, v1, v2, p1, p2):
        """β/V of the two chambers of volumes v1, v2 at pressures p1, p2."""
        return m.P["beta"] / v1, m.P["beta"] / v2

    def force(self, y, v, es):
        return 0.0

    def derivs(self, plant, es):
        """The derivatives of the states; `plant`: x_c, a (the platen's acceleration), y, v,
        q_supply (the valves' draw), f_act (the actuators' force), stroke."""
        return ()

    def recorded(self, a, x, f, es, plant):
        """The acceleration, displacement and actuator force as recorded at a tick (the plant's
        unless a measurement chain changes them)."""
        return a, x, f

    def watch(self, es):
        """Once per controller tick, at the tick's states (a specimen's peaks)."""

    def command(self, u, r, x, t, s):
        """The valve command (V) from the TVC's sum `u` at a tick, before the notches and the
        clamp (docs/model.md §2): a compensator's hook. `r`: the reference's x, v, a, j; `x`: the
        displacement feedback; `t`: the tick's time; `s`: the plant's states (P1, P2 of each
        actuator at s[3:7])."""
        return u

    def specimen_metrics(self):
        """A building's metrics over the run, or none."""
        return {}


class Specimen(Effect):
    """Up to three modes on the platen in relative coordinates u_i:
    ü_i = −ω_i² u_i − 2ζ_iω_i u̇_i − a; the platen receives Σ m_i(ω_i² u_i + 2ζ_iω_i u̇_i)."""

    names = ["m1", "f1", "zeta1", "m2", "f2", "zeta2", "m3", "f3", "zeta3"]
    n = 6

    def _modes(self):
        for i in (1, 2, 3):
            w = 2.0 * math.pi * self.p[f"f{i}"]
            yield i - 1, self.p[f"m{i}"], w * w, 2.0 * self.p[f"zeta{i}"] * w

    def force(self, y, v, es):
        total = 0.0
        for i, mass, w2, c in self._modes():
            total = total + np.where(mass > 0.0, mass * (w2 * es[2 * i] + c * es[2 * i + 1]), 0.0)
        return total

    def derivs(self, plant, es):
        out = []
        for i, mass, w2, c in self._modes():
            u, ud = es[2 * i], es[2 * i + 1]
            on = mass > 0.0
            out += [np.where(on, ud, 0.0), np.where(on, -w2 * u - c * ud - plant["a"], 0.0)]
        return tuple(out)


class HoldDown(Effect):
    """Extra strut force −k3·y³."""

    names = ["k3"]

    def force(self, y, v, es):
        return -self.p["k3"] * y ** 3


class SealFriction(Effect):
    """F = −tanh(v/v_eps)(f_c + (f_s − f_c) e^{−(v/v_s)²}) − σ v, all actuators together."""

    names = ["f_c", "f_s", "v_s", "sigma", "v_eps"]

    def force(self, y, v, es):
        p = self.p
        stribeck = p["f_c"] + (p["f_s"] - p["f_c"]) * np.exp(-((v / p["v_s"]) ** 2))
        return -np.tanh(v / p["v_eps"]) * stribeck - p["sigma"] * v


class SpoolDynamics(Effect):
    """The spool follows the command: ẍ_s = ω²(x_c − x_s) − 2ζω ẋ_s; the valves open x_s."""

    names = ["freq_hz", "zeta"]
    n = 2

    def opening(self, x, es):
        return es[0]

    def derivs(self, plant, es):
        w = 2.0 * math.pi * self.p["freq_hz"]
        return es[1], w * w * (plant["x_c"] - es[0]) - 2.0 * self.p["zeta"] * w * es[1]


class TransportDelay(Effect):
    """A delay τ between the command and the spool as four equal first-order lags of τ/4."""

    names = ["tau"]
    n = 4

    def opening(self, x, es):
        return es[3]

    def derivs(self, plant, es):
        rate = 4.0 / self.p["tau"]
        inputs = (plant["x_c"], es[0], es[1], es[2])
        return tuple(rate * (u - x) for u, x in zip(inputs, es))


class FlowSaturation(Effect):
    """Metering opening x_eff = x_sat·tanh(x/x_sat)."""

    names = ["x_sat"]

    def opening(self, x, es):
        return self.p["x_sat"] * np.tanh(x / self.p["x_sat"])


class FlowGain(Effect):
    """x_eff = x·g(|x|/x_ref), g piecewise linear through (0, g0), (0.05, g1), (0.15, g2),
    (0.35, g3), (0.7, g4), constant beyond 0.7."""

    names = ["g0", "g1", "g2", "g3", "g4", "x_ref"]
    KNOTS = (0.0, 0.05, 0.15, 0.35, 0.7)

    def opening(self, x, es):
        r = np.abs(x) / self.p["x_ref"]
        g = [self.p[f"g{i}"] for i in range(5)]
        gain = np.where(r >= 0.7, g[4], 0.0)
        for i in range(4):
            lo, hi = self.KNOTS[i], self.KNOTS[i + 1]
            inside = (r >= lo) & (r < hi)
            gain = np.where(inside, g[i] + (g[i + 1] - g[i]) * (r - lo) / (hi - lo), gain)
        return x * gain


class Asymmetry(Effect):
    """Extension flows (x > 0) × extend_gain; actuator 2's valves × act2_gain."""

    names = ["extend_gain", "act2_gain"]

    def flows(self, q1, q2, p1, p2, x, act, p_s, es):
        gain = np.where(x > 0.0, self.p["extend_gain"], 1.0)
        if act == 1:
            gain = gain * self.p["act2_gain"]
        return q1 * gain, q2 * gain


class Leakage(Effect):
    """Across the piston q_i = c_int (P1 − P2), chamber 1 to chamber 2; to drain c_ext·P from
    each chamber."""

    names = ["c_int", "c_ext"]

    def flows(self, q1, q2, p1, p2, x, act, p_s, es):
        qi = self.p["c_int"] * (p1 - p2)
        return q1 - qi - self.p["c_ext"] * p1, q2 - qi + self.p["c_ext"] * p2


class Supply(Effect):
    """Pump Q_p = q_pump·clamp((P_S − P_s)/dp_band, 0, 1) into an accumulator,
    c_acc dP_s/dt = Q_p − Q; the valves see P_s (P_S: the nominal supply pressure)."""

    names = ["q_pump", "c_acc", "dp_band"]
    n = 1

    def initial(self, n_s):
        return (np.full(n_s, m.P["p_s"]),)

    def supply(self, es):
        return es[0]

    def derivs(self, plant, es):
        p = self.p
        pump = p["q_pump"] * np.clip((m.P["p_s"] - es[0]) / p["dp_band"], 0.0, 1.0)
        return ((pump - plant["q_supply"]) / p["c_acc"],)


class Compressibility(Effect):
    """Dead volume V_x per chamber; 1/β_e(p) = 1/(beta_ratio·β) + ε·p_atm/p², p the absolute
    chamber pressure, floored at p_atm/10."""

    names = ["dead_volume", "beta_ratio", "air_fraction"]
    P_ATM = 101_325.0

    def stiffness(self, v1, v2, p1, p2):
        p = self.p

        def b(vol, gauge):
            pa = np.maximum(gauge + self.P_ATM, 0.1 * self.P_ATM)
            inv = 1.0 / (p["beta_ratio"] * m.P["beta"]) + p["air_fraction"] * self.P_ATM / pa**2
            return 1.0 / inv / (vol + p["dead_volume"])

        return b(v1, p1), b(v2, p2)


class BulkCurve(Effect):
    """β_e(p) = β·b(p/P_S), b piecewise linear through (0, b0), (0.5, b1), (1, b2), constant
    outside [0, 1]; p the chamber's gauge pressure."""

    names = ["b0", "b1", "b2"]

    def stiffness(self, v1, v2, p1, p2):
        b0, b1, b2 = self.p["b0"], self.p["b1"], self.p["b2"]

        def gain(pr):
            r = np.clip(pr / m.P["p_s"], 0.0, 1.0)
            return np.where(r < 0.5, b0 + (b1 - b0) * r / 0.5, b1 + (b2 - b1) * (r - 0.5) / 0.5)

        return m.P["beta"] * gain(p1) / v1, m.P["beta"] * gain(p2) / v2


class ReactionMass(Effect):
    """m_r ÿ_r = −F − k_r y_r − c_r ẏ_r (F: the actuators' force); the stroke, the chambers and
    the LVDT follow y − y_r; k_r = m_r(2π f_r)², c_r = 2ζ_r m_r 2π f_r."""

    names = ["m_r", "f_r", "zeta_r"]
    n = 2

    def stroke(self, y, v, es):
        return y - es[0], v - es[1]

    def derivs(self, plant, es):
        p = self.p
        w = 2.0 * math.pi * p["f_r"]
        acc = (-plant["f_act"] - p["m_r"] * w * w * es[0] - 2.0 * p["zeta_r"] * p["m_r"] * w * es[1]) / p["m_r"]
        return es[1], acc


class Sensor(Effect):
    """A recorded channel through ÿ = ω_c²(u − y) − 2ζω_c ẏ, then delayed by τ: its (2,2) Padé
    all-pass for τ ≥ 0.5 ms (τ²/12·z̈ + τ/2·ż + z = y, recorded y − τż), its Taylor series
    y − τẏ + τ²ÿ/2 below."""

    names = ["f_c", "zeta", "delay"]
    n = 4
    channel = None

    def _input(self, plant):
        return plant[{"a": "a", "x": "stroke", "f": "f_act"}[self.channel]]

    def derivs(self, plant, es):
        p = self.p
        w = 2.0 * math.pi * p["f_c"]
        y, yd, z, zd = es
        ydd = w * w * (self._input(plant) - y) - 2.0 * p["zeta"] * w * yd
        tau = p["delay"]
        pade = tau >= 0.5e-3
        t = np.where(pade, tau, 1.0)
        zdd = np.where(pade, 12.0 / (t * t) * (y - z - 0.5 * t * zd), 0.0)
        return yd, ydd, np.where(pade, zd, 0.0), zdd

    def recorded(self, a, x, f, es, plant):
        p = self.p
        w = 2.0 * math.pi * p["f_c"]
        y, yd, z, zd = es
        tau = p["delay"]
        ydd = w * w * (self._input(plant) - y) - 2.0 * p["zeta"] * w * yd
        out = np.where(tau >= 0.5e-3, y - tau * zd, y - tau * yd + 0.5 * tau * tau * ydd)
        return (out if self.channel == "a" else a, out if self.channel == "x" else x,
                out if self.channel == "f" else f)


class AccelSensor(Sensor):
    channel = "a"


class DispSensor(Sensor):
    channel = "x"


class ForceSensor(Sensor):
    channel = "f"


STOREYS = 10


class Building(Effect):
    """A shear building of 1-10 storeys on the platen (docs/model.md, "The building"): floor i of
    mass m_i, storey i of stiffness k_i and yield force F_y,i; u_i relative to the platen,
    d_i = u_i − u_{i−1}, m_i (ü_i + a) = −V_i + V_{i+1}, V_i = R_i + c_i ḋ_i,
    R_i = α k_i d_i + (1 − α) r_i (r clamped to ±F_y for the bilinear law), ṙ_i = k_i ḋ_i g_i;
    c_i = (2ζ/ω_1) k_i, ω_1 the elastic building's first mode; the platen receives V_1. Its
    states are four arrays of storeys × samples: u, u̇, r and the storey's work w (ẇ = R ḋ)."""

    names = (["storeys", "law", "alpha", "zeta", "height", "bw_a", "bw_beta", "bw_gamma", "bw_n"]
             + [f"m{i}" for i in range(1, STOREYS + 1)] + [f"k{i}" for i in range(1, STOREYS + 1)]
             + [f"fy{i}" for i in range(1, STOREYS + 1)])
    n = 4

    def __init__(self, params):
        super().__init__(params)
        p = self.p
        n_s = len(p["storeys"])
        self.on = np.arange(STOREYS)[:, None] < p["storeys"][None, :]
        self.m = np.array([p[f"m{i + 1}"] for i in range(STOREYS)])
        self.k = np.array([p[f"k{i + 1}"] for i in range(STOREYS)])
        self.fy = np.array([p[f"fy{i + 1}"] for i in range(STOREYS)])
        w1 = np.empty(n_s)
        for j in range(n_s):
            n = int(p["storeys"][j])
            k = list(self.k[:n, j]) + [0.0]
            stiff = np.zeros((n, n))
            for i in range(n):
                stiff[i, i] = k[i] + k[i + 1]
                if i + 1 < n:
                    stiff[i, i + 1] = stiff[i + 1, i] = -k[i + 1]
            s = 1.0 / np.sqrt(self.m[:n, j])
            w1[j] = math.sqrt(np.linalg.eigvalsh(stiff * np.outer(s, s))[0])
        self.c = 2.0 * p["zeta"] / w1 * self.k
        self.row0 = np.zeros((1, n_s))
        self.peak_drift = np.zeros(n_s)
        self.peak_shear = np.zeros(n_s)
        self.ductility = np.zeros(n_s)
        self.energy = np.zeros(n_s)

    def initial(self, n_s):
        return tuple(np.zeros((STOREYS, n_s)) for _ in range(self.n))

    def _storeys(self, es):
        """Drift, drift rate, restoring force R and shear V of every storey (0 above the
        building), and the hysteretic force as R takes it; kept for the same states (the force,
        then the derivatives, of one evaluation)."""
        if getattr(self, "_last", (None,))[0] is es:
            return self._last[1]
        p = self.p
        u, v, r, _ = es
        d = u - np.vstack([self.row0, u[:-1]])
        dd = v - np.vstack([self.row0, v[:-1]])
        held = np.where(p["law"] == 1, np.clip(r, -self.fy, self.fy), r)
        restoring = p["alpha"] * self.k * d + (1.0 - p["alpha"]) * held
        out = tuple(np.where(self.on, x, 0.0) for x in (d, dd, restoring, restoring + self.c * dd))
        self._last = (es, out + (held,))
        return self._last[1]

    def force(self, y, v, es):
        return self._storeys(es)[3][0]

    def derivs(self, plant, es):
        p = self.p
        d, dd, restoring, shear, _ = self._storeys(es)
        above = np.vstack([shear[1:], self.row0])
        r = es[2]
        out_ward = ((r >= self.fy) & (dd > 0.0)) | ((r <= -self.fy) & (dd < 0.0))
        z = r / self.fy
        bouc_wen = p["bw_a"] - np.abs(z) ** p["bw_n"] * (p["bw_beta"] + p["bw_gamma"] * np.sign(dd * z))
        g = np.select([p["law"] == 0, p["law"] == 1], [1.0, np.where(out_ward, 0.0, 1.0)], bouc_wen)
        on = self.on
        return (np.where(on, es[1], 0.0), np.where(on, (above - shear) / self.m - plant["a"], 0.0),
                np.where(on, self.k * dd * g, 0.0), np.where(on, restoring * dd, 0.0))

    def watch(self, es):
        p = self.p
        d, _, _, shear, held = self._storeys(es)
        self.peak_drift = np.maximum(self.peak_drift, np.max(np.abs(d), axis=0) / p["height"])
        self.ductility = np.maximum(self.ductility, np.max(np.abs(d) * self.k / self.fy, axis=0))
        stored = 0.5 * p["alpha"] * self.k * d * d + 0.5 * (1.0 - p["alpha"]) * held * held / self.k
        self.energy = np.sum(np.where(self.on, es[3] - stored, 0.0), axis=0)
        self.peak_shear = np.maximum(self.peak_shear, np.abs(shear[0]))

    def specimen_metrics(self):
        return dict(peak_drift_ratio=self.peak_drift, peak_base_shear_n=self.peak_shear,
                    ductility_demand=np.where(self.p["law"] == 0, np.nan, self.ductility),
                    hysteretic_energy_j=self.energy)


class ValveCompensator(Effect):
    """docs/model.md §7, `valve_compensator`: u / max(g, g_min), g the mean over the actuators of
    ½(√(Δp_a/Δp_a0) + √(Δp_b/Δp_b0)) for the two ports u's sign opens (u ≥ 0: P_S − P1 and
    P2 − P_R; u < 0: P1 − P_R and P_S − P2), over their no-load drops; a negative drop counts 0."""

    names = ["g_min"]

    def command(self, u, r, x, t, s):
        p_s, p_r, p1_0, p2_0 = m.P["p_s"], m.P["p_r"], m.P1_0, m.P2_0
        g = 0.0
        for act in (0, 1):
            p1, p2 = s[3 + 2 * act], s[4 + 2 * act]
            a = np.where(u >= 0.0, (p_s - p1) / (p_s - p1_0), (p1 - p_r) / (p1_0 - p_r))
            b = np.where(u >= 0.0, (p2 - p_r) / (p2_0 - p_r), (p_s - p2) / (p_s - p2_0))
            g = g + 0.5 * (np.sqrt(np.maximum(a, 0.0)) + np.sqrt(np.maximum(b, 0.0)))
        return u / np.maximum(g / 2.0, self.p["g_min"])


def reference_phase(r):
    """docs/model.md §7 (`amplitude_phase`): the frequency ω, amplitude A and phase θ of a sine
    read from its states, ω² = (a² − v·j)/(v² − x·a), (cos θ, sin θ) ∝ (v, ω·x); None where they
    are not a sine's."""
    x, v, a, j = r
    with np.errstate(divide="ignore", invalid="ignore"):
        w2 = (a * a - v * j) / (v * v - x * a)
    if not (np.isfinite(w2) and w2 > 0.0):
        return None
    w = math.sqrt(w2)
    n = math.hypot(v, w * x)
    if not n > 0.0:
        return None
    return w, n / w, math.atan2(w * x, v)


class Canceller(Effect):
    """docs/model.md §7 (`amplitude_phase`, `harmonic_cancellation`): per harmonic k, with the
    displacement error e = x_r − x, Ω = kω, E ← E + λ(2e·e^{−jkθ} − E), then (unless frozen,
    t ≥ freeze_s > 0) D ← D + μ·e^{jΩτ}·E capped at |D| ≤ authority·A, and the command gains
    Re{F(jΩ)·D·e^{jkθ}}, F(s) = c_fb + c_d + c_v s + c_a s² + c_j s³ (μ = gain/f_s,
    λ = 1 − exp(−2π·band/f_s))."""

    names = ["gain", "band_hz", "delay_s", "authority", "freeze_s"]
    harmonics = ()

    def initial(self, n_s):
        self.d = np.zeros((len(self.harmonics), n_s), complex)
        self.e = np.zeros((len(self.harmonics), n_s), complex)
        return ()

    def command(self, u, r, x, t, s):
        ph = reference_phase(r)
        if ph is None:
            return u
        w, amp, theta = ph
        p, f_s, c = self.p, m.P["f_s"], m.coefficients({})
        mu, lam = p["gain"] / f_s, 1.0 - np.exp(-2.0 * math.pi * p["band_hz"] / f_s)
        adapting = ~((p["freeze_s"] > 0.0) & (t >= p["freeze_s"]))
        e = r[0] - x
        total = 0.0
        for i, k in enumerate(self.harmonics):
            big = k * w
            turn = np.exp(1j * k * theta)
            self.e[i] = self.e[i] + lam * (2.0 * e * np.conj(turn) - self.e[i])
            d = self.d[i] + mu * np.exp(1j * big * p["delay_s"]) * self.e[i]
            cap = p["authority"] * amp
            d = np.where(np.abs(d) > cap, d * cap / np.abs(d), d)
            self.d[i] = np.where(adapting, d, self.d[i])
            f = (c["c_fb"] + c["c_d"] - c["c_a"] * big**2) + 1j * big * (c["c_v"] - c["c_j"] * big**2)
            total = total + np.real(f * self.d[i] * turn)
        return u + total


class AmplitudePhase(Canceller):
    harmonics = (1,)


class HarmonicCancellation(Canceller):
    harmonics = (3, 5, 7, 9)



def dot(a, b):
    """Σ_i a[:, i]·b[:, i], summed in the order of i (the least squares' sums are ill-conditioned
    in its first ticks: a fixed order keeps the peer's rounding the same on every machine)."""
    total = a[:, 0] * b[:, 0]
    for i in range(1, a.shape[1]):
        total = total + a[:, i] * b[:, i]
    return total


class AdaptiveInverse(Effect):
    """docs/model.md §7, `adaptive_inverse`: a 16-tap Laguerre network (pole a = exp(−2π·corner/f_s),
    s = √(1 − a²); L_1[n] = a·L_1[n−1] + s·in[n−1], L_i[n] = a·L_i[n−1] + L_{i−1}[n−1] − a·L_{i−1}[n],
    tap 0 the input) fitted by recursive least squares (λ = 1 − 1/(memory_s·f_s), P = 10⁶·I at the
    start) from the weighted displacement feedback to the weighted displacement sent D ticks
    earlier (D = round(anticipation·f_s) in 1..16), both through two high-pass stages
    y[n] = α·(y[n−1] + in[n] − in[n−1]) with α = 1/(1 + 2π·weight_hz/f_s) (none where weight_hz
    = 0), unless frozen; the inverse in use v ← v + (w − v)/(copy_s·f_s) (held at copy_s = 0),
    starting at the taps w_i; the reference's states read D/f_s ahead by their Taylor series
    (the jerk held) pass through two more networks, the displacement's (the sent displacement
    Σ vᵢ·Lᵢ) and F's (F·r = (c_fb + c_d)·x + c_v·v + c_a·a + c_j·j), and the command gains
    Σ vᵢ·Lᵢ(F·r̂) − F·r."""

    TAPS = 16
    names = ["memory_s", "corner_hz", "anticipation_s", "weight_hz", "copy_s", "freeze_s"] + [
        f"w_{i}" for i in range(16)]

    def initial(self, n_s):
        p, f_s, t = self.p, m.P["f_s"], self.TAPS
        self.lam = 1.0 - 1.0 / (p["memory_s"] * f_s)
        self.a = np.exp(-2.0 * math.pi * p["corner_hz"] / f_s)
        self.s = np.sqrt(1.0 - self.a**2)
        self.d = np.clip(np.round(p["anticipation_s"] * f_s), 1, 16).astype(int)
        self.alpha = 1.0 / (1.0 + 2.0 * math.pi * p["weight_hz"] / f_s)
        self.beta = np.where(p["copy_s"] > 0.0, 1.0 / (np.maximum(p["copy_s"], 1e-300) * f_s), 0.0)
        start = np.stack([p[f"w_{i}"] * np.ones(n_s) for i in range(t)], axis=1)
        self.w, self.v = start.copy(), start.copy()
        self.pm = np.tile(1e6 * np.eye(t), (n_s, 1, 1))
        self.nets = {k: np.zeros((n_s, t)) for k in ("x", "r", "g")}
        self.sent = np.zeros((n_s, 16))
        self.hp = {k: np.zeros((n_s, 4)) for k in ("x", "y")}
        return ()

    def network(self, key, u):
        """The network's taps at this tick for input `u` (tap 0: u itself)."""
        st = self.nets[key]
        taps = np.empty_like(st)
        taps[:, 0] = u
        new = np.empty_like(st)
        new[:, 0] = u
        new[:, 1] = self.a * st[:, 1] + self.s * st[:, 0]
        for i in range(2, self.TAPS):
            new[:, i] = self.a * st[:, i] + st[:, i - 1] - self.a * new[:, i - 1]
        taps[:, 1:] = new[:, 1:]
        self.nets[key] = new
        return taps

    def weigh(self, key, x):
        st = self.hp[key]
        out = x
        for k in (0, 2):
            st[:, k + 1] = self.alpha * (st[:, k + 1] + out - st[:, k])
            st[:, k] = out
            out = st[:, k + 1].copy()
        return np.where(self.alpha == 1.0, x, out)

    def command(self, u, r, x, t, s):
        p = self.p
        psi = self.network("x", self.weigh("x", x * np.ones(len(self.d))))
        y = self.weigh("y", self.sent[np.arange(len(self.d)), self.d - 1])
        adapting = ~((p["freeze_s"] > 0.0) & (t >= p["freeze_s"]))
        pp = np.stack([dot(self.pm[:, i, :], psi) for i in range(self.TAPS)], axis=1)
        den = self.lam + dot(psi, pp)
        k = pp / den[:, None]
        err = y - dot(self.w, psi)
        w = self.w + k * err[:, None]
        pm = (self.pm - k[:, :, None] * pp[:, None, :]) / self.lam[:, None, None]
        self.w = np.where(adapting[:, None], w, self.w)
        self.pm = np.where(adapting[:, None, None], pm, self.pm)
        self.v = self.v + self.beta[:, None] * (self.w - self.v)
        dt = self.d / m.P["f_s"]
        xr, vr, ar, jr = r
        r_hat = (xr + dt * (vr + 0.5 * dt * (ar + dt * jr / 3.0)), vr + dt * (ar + 0.5 * dt * jr),
                 ar + dt * jr, jr)
        c = m.coefficients({})
        f = (c["c_fb"] + c["c_d"], c["c_v"], c["c_a"], c["c_j"])
        path = lambda q: f[0] * q[0] + f[1] * q[1] + f[2] * q[2] + f[3] * q[3]  # noqa: E731
        rho = self.network("r", r_hat[0])
        phi = self.network("g", path(r_hat))
        self.sent = np.roll(self.sent, 1, axis=1)
        self.sent[:, 0] = dot(self.v, rho)
        return u + (dot(self.v, phi) - path(r))


# The expression language of docs/formats.md ("Expressions") in NumPy: each function as the
# table defines it, over arrays of samples.
FUNCTIONS = dict(
    sin=np.sin, cos=np.cos, tan=np.tan, exp=np.exp, ln=np.log, log10=np.log10, sqrt=np.sqrt,
    abs=np.abs, sign=np.sign, tanh=np.tanh, atan=np.arctan,
    step=lambda x: np.where(x >= 0.0, 1.0, 0.0),
    min=np.minimum, max=np.maximum, pow=np.power, atan2=np.arctan2,
    clamp=lambda x, lo, hi: np.minimum(np.maximum(x, lo), hi),
    pi=math.pi,
)


def translate(source):
    """An expression of the documented language as Python source: the same grammar but `^`
    (power, right to left, above unary minus: Python's `**`)."""
    assert "**" not in source, source
    return source.replace("^", "**")


class Expression(Effect):
    """Effect `expression` (docs/formats.md, "Expressions"): each hook given an expression of its
    quantities, `t` (the time since the start of the run, its one state) and named parameters;
    a hook without one is left alone. `hooks`: the model file's keys and their sources."""

    n = 1

    def __init__(self, params, hooks):
        super().__init__(params)
        self.names = list(params)
        self.code = {k: compile(translate(src), k, "eval") for k, src in hooks.items()}

    def _run(self, hook, **quantities):
        code = self.code.get(hook)
        if code is None:
            return None
        return eval(code, {"__builtins__": {}}, {**FUNCTIONS, **self.p, **quantities})

    def _or(self, value, default):
        return default if value is None else value

    def supply(self, es):
        return self._or(self._run("supply", ps=m.P["p_s"], t=es[0]), m.P["p_s"])

    def opening(self, x, es):
        return self._or(self._run("opening", x=x, t=es[0]), x)

    def flows(self, q1, q2, p1, p2, x, act, p_s, es):
        q = dict(p1=p1, p2=p2, ps=p_s, t=es[0])
        into_1 = self._or(self._run("flow_1", **q), 0.0)
        into_2 = self._or(self._run("flow_2", **q), 0.0)
        # Net flows into chamber 1 and out of chamber 2: a flow into 2 lessens what leaves it.
        return q1 + into_1, q2 - into_2

    def force(self, y, v, es):
        return self._or(self._run("force", y=y, v=v, t=es[0]), 0.0)

    def derivs(self, plant, es):
        return (np.ones_like(es[0]),)

    def recorded(self, a, x, f, es, plant):
        q = dict(a=a, d=x, f=f, t=es[0])
        return (self._or(self._run("accel_channel", **q), a),
                self._or(self._run("disp_channel", **q), x),
                self._or(self._run("force_channel", **q), f))


EFFECTS = {
    "specimen": Specimen,
    "hold_down": HoldDown,
    "seal_friction": SealFriction,
    "spool_dynamics": SpoolDynamics,
    "transport_delay": TransportDelay,
    "flow_saturation": FlowSaturation,
    "flow_gain": FlowGain,
    "asymmetry": Asymmetry,
    "leakage": Leakage,
    "supply": Supply,
    "compressibility": Compressibility,
    "bulk_curve": BulkCurve,
    "reaction_mass": ReactionMass,
    "accel_sensor": AccelSensor,
    "disp_sensor": DispSensor,
    "force_sensor": ForceSensor,
    "building": Building,
    "valve_compensator": ValveCompensator,
    "amplitude_phase": AmplitudePhase,
    "harmonic_cancellation": HarmonicCancellation,
    "adaptive_inverse": AdaptiveInverse,
}


def rhs(fx, x_c, s, es, plant=None):
    """The plant's derivatives (model.rhs's, with the effect's hooks, both actuators: s = y, v,
    z, then P1 and P2 of each) and the effect's; `plant` (a dict) receives what the effect's
    derivatives and the recording read."""
    y, v, z = s[:3]
    p_s = fx.supply(es)
    ys, vs = fx.stroke(y, v, es)
    x = fx.opening(x_c, es)
    pos = x > 0.0
    vol1 = m.P["a1"] * (m.P["l"] + ys) + m.P["vd1"]
    vol2 = m.P["a2"] * (m.P["l"] - ys) + m.P["vd2"]
    dps, q_supply, f_act = [], 0.0, 0.0
    for act in (0, 1):
        p1, p2 = s[3 + 2 * act], s[4 + 2 * act]
        dp1 = np.where(pos, p_s - p1, p1 - m.P["p_r"])
        dp2 = np.where(pos, p2 - m.P["p_r"], p_s - p2)
        k1 = np.where(pos, m.KW1, m.KW3)
        k2 = np.where(pos, m.KW2, m.KW4)
        q1 = k1 * x * dp1 * (dp1 * dp1 + m.P_TR2) ** -0.25
        q2 = k2 * x * dp2 * (dp2 * dp2 + m.P_TR2) ** -0.25
        q_supply = q_supply + np.where(pos, q1, -q2)
        q1, q2 = fx.flows(q1, q2, p1, p2, x, act, p_s, es)
        b1, b2 = fx.stiffness(vol1, vol2, p1, p2)
        dps += [b1 * (q1 - m.P["a1"] * vs), b2 * (m.P["a2"] * vs - q2)]
        f_act = f_act + (p1 * m.P["a1"] - p2 * m.P["a2"])
    f = f_act + fx.force(y, v, es)
    dv = (f - m.P["k"] * y - (m.P["c"] * np.sqrt(np.abs(v)) + m.MU) * z) / m.P["m"]
    zv = z * v
    bracket = np.where(zv > 0.0, 1.0, np.where(zv < 0.0, m.KAPPA_NEG, m.P["kappa"]))
    dz = v / m.P["y_yield"] * (1.0 - z * z * bracket)
    view = dict(x_c=x_c, a=dv, y=y, v=v, q_supply=q_supply, f_act=f_act, stroke=ys)
    if plant is not None:
        plant.update(view)
    return (v, dv, dz, *dps), tuple(fx.derivs(view, es))


def rk4_tick(fx, x_c, s, es, substeps):
    """One controller tick: `substeps` RK4 steps of the plant and the effect's states together."""
    h = 1.0 / (m.P["f_s"] * substeps)

    def axpy(a, b, k):
        return tuple(x + k * d for x, d in zip(a, b))

    for _ in range(substeps):
        k1 = rhs(fx, x_c, s, es)
        k2 = rhs(fx, x_c, axpy(s, k1[0], 0.5 * h), axpy(es, k1[1], 0.5 * h))
        k3 = rhs(fx, x_c, axpy(s, k2[0], 0.5 * h), axpy(es, k2[1], 0.5 * h))
        k4 = rhs(fx, x_c, axpy(s, k3[0], h), axpy(es, k3[1], h))

        def combine(x, j):
            return tuple(a + h / 6.0 * (b1 + 2.0 * (b2 + b3) + b4)
                         for a, b1, b2, b3, b4 in zip(x, k1[j], k2[j], k3[j], k4[j]))

        s, es = combine(s, 0), combine(es, 1)
    return s, es


def actuators_force(s):
    """The two actuators' force on the platen, N."""
    return (s[3] * m.P["a1"] - s[4] * m.P["a2"]) + (s[5] * m.P["a1"] - s[6] * m.P["a2"])


def failed(fx, s, es):
    """The guard (model.failed) on the stroke and on both actuators' pressures."""
    y, v, z = s[:3]
    ys = fx.stroke(y, v, es)[0]
    bad = np.zeros(np.shape(y), bool)
    for act in (0, 1):
        bad |= m.failed(np, (ys, v, z, s[3 + 2 * act], s[4 + 2 * act]))
    return bad | ~np.isfinite(y)


def simulate(name, params, ref, substeps, hooks=None):
    """Metrics per sample (model.py's) of the baseline with effect `name` on, its parameters
    `params` (dict of equal-length arrays, every one of the effect's names), default gains;
    `hooks`: the expressions of effect `expression` (its named parameters in `params`)."""
    fx = Expression(params, hooks) if name == "expression" else EFFECTS[name](params)
    c = m.coefficients({})
    n_s = len(next(iter(params.values()))) if params else 1
    zeros = np.zeros(n_s)
    p1, p2 = np.full(n_s, m.P1_0), np.full(n_s, m.P2_0)
    s = (zeros, zeros, zeros, p1, p2, p1, p2)
    es = fx.initial(n_s)
    f_prev = actuators_force(s)
    f_hp = zeros
    acc = dict(a_re=np.zeros((m.N_HARM, n_s)), a_im=np.zeros((m.N_HARM, n_s)), x_re=zeros, x_im=zeros,
               err_a2=zeros, err_x2=zeros, peak_err_a=zeros, max_u=zeros, failed=np.zeros(n_s, bool),
               fa=zeros, fv=zeros)
    rx, rv, ra, rj, win, cos, sin = ref["x"], ref["v"], ref["a"], ref["j"], ref["win"], ref["cos"], ref["sin"]
    for k in range(len(rx)):
        f = actuators_force(s)
        f_hp = m.HP_B * (f - f_prev) + m.HP_A * f_hp
        f_prev = f
        x = fx.stroke(s[0], s[1], es)[0]
        r = (rx[k], rv[k], ra[k], rj[k])
        u = c["c_fb"] * (r[0] - x) + c["c_d"] * r[0] + c["c_v"] * r[1] + c["c_a"] * r[2] + c["c_j"] * r[3] + c["c_f"] * f_hp
        u = np.clip(fx.command(u, r, x, k / m.P["f_s"], s), -m.P["u_lim"], m.P["u_lim"])
        x_c = m.P["k_sp"] * u
        plant = {}
        a = rhs(fx, x_c, s, es, plant)[0][1]
        a, x, f_rec = fx.recorded(a, x, f, es, plant)
        fx.watch(es)
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
            acc["fa"] = acc["fa"] + f_rec * ra[k]
            acc["fv"] = acc["fv"] + f_rec * rv[k]
        s, es = rk4_tick(fx, x_c, s, es, substeps)
        acc["failed"] |= failed(fx, s, es)
    out = m.finish(acc, m.reference_sums(ref))
    # The recorded actuator force's projections on the reference's acceleration and velocity
    # over the window (no metric reads the force; the test takes them from the kernel's ticks).
    w = ref["win"] > 0
    out["force_a_kg"] = np.where(acc["failed"], np.nan, acc["fa"] / np.sum(ra[w] ** 2))
    out["force_v_n_s_per_m"] = np.where(acc["failed"], np.nan, acc["fv"] / np.sum(rv[w] ** 2))
    for k, v in fx.specimen_metrics().items():
        out[k] = np.where(acc["failed"], np.nan, v)
    return out
