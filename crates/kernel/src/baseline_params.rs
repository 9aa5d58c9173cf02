//! The baseline model's parameter tables: the servo-valves, the actuators, the platen, the
//! friction and the controller, each field with its unit, default, valid range and source
//! ([paper] = published value of the LHPOST virtual model, [chosen] = not published; the value
//! and the reason are given here and in docs/model.md §1). [`crate::params::ModelParams`] holds
//! them with the effects' and the ground motion's tables.

use crate::param_table::{params, Range};

/// Default orifice coefficient K_v = Q_r / (w3 · x_max · √(ΔP_r/2)) in m/(s·√Pa), with the rated
/// flow Q_r = 10 000 L/min per valve at ΔP_r = 6.895 MPa valve drop (two lands) and full spool
/// x_max = 19.05 mm [chosen; docs/model.md §1]. Evaluates to 0.018551.
pub const KV_DEFAULT: f64 = (10_000.0e-3 / 60.0) / (0.254 * 19.05e-3 * 1_856.744_462_762_714_2);
// 1856.744… = √(6.895e6 / 2); `sqrt` is not const, the test below checks the constant.

params! {
    /// Servo-valve (four-port, square-root orifice flow), docs/model.md §3.
    pub struct ValveParams {
        p_s: "Pa", "pa", 20.7e6, Range::gt(0.0), Paper,
            "Supply pressure P_S.";
        p_r: "Pa", "pa", 0.35e6, Range::ge(0.0), Paper,
            "Return pressure P_R (must be below P_S).";
        w3: "m", "m", 0.254, Range::gt(0.0), Paper,
            "Widest port window w3 (cap side to return).";
        r1: "-", "", 0.8, Range::gt(0.0), Paper,
            "Port ratio w1/w3 (supply to cap side), eq. (3) of the paper.";
        r2: "-", "", 0.512, Range::gt(0.0), Paper,
            "Port ratio w2/w3 (rod side to return), eq. (3) of the paper.";
        r4: "-", "", 0.64, Range::gt(0.0), Paper,
            "Port ratio w4/w3 (supply to rod side), eq. (3) of the paper.";
        k_sp: "m/V", "m_per_v", 1.905e-3, Range::gt(0.0), Paper,
            "Spool displacement per volt of valve command (19.05 mm / 10 V).";
        u_lim: "V", "v", 10.0, Range::gt(0.0), Chosen,
            "Valve command limit ±u_lim [chosen: full scale of a ±10 V servo-valve driver].";
        kv: "m/(s·√Pa)", "m_per_s_sqrt_pa", KV_DEFAULT, Range::gt(0.0), Chosen,
            "Orifice flow coefficient K_v [chosen: rated 10 000 L/min per valve at 6.895 MPa valve drop, full spool 19.05 mm].";
        p_tr: "Pa", "pa", 0.1e6, Range::gt(0.0), Chosen,
            "Orifice regularisation pressure: sq(Δp) = Δp/(Δp²+p_tr²)^¼ [chosen: smooth below 0.5 % of P_S].";
        n_val: "-", "", 2.0, Range::closed(1.0, 16.0), Paper,
            "Servo-valves per actuator (whole number).";
    }
}

params! {
    /// Single-ended actuator with stroke-dependent chamber volumes, docs/model.md §3.
    pub struct ActuatorParams {
        beta: "Pa", "pa", 689.5e6, Range::gt(0.0), Paper,
            "Oil bulk modulus β.";
        a1: "m²", "m2", 0.2027, Range::gt(0.0), Paper,
            "Cap-side piston area A1 (chamber 1).";
        a2: "m²", "m2", 0.1297, Range::gt(0.0), Paper,
            "Rod-side piston area A2 (chamber 2).";
        l: "m", "m", 0.75, Range::gt(0.0), Paper,
            "Half stroke L: chamber length at centre; the stroke limit is ±L.";
        vd1: "m³", "m3", 0.0, Range::ge(0.0), Chosen,
            "Dead volume of chamber 1 (hoses, manifold) [chosen: 0, the paper has none].";
        vd2: "m³", "m3", 0.0, Range::ge(0.0), Chosen,
            "Dead volume of chamber 2 [chosen: 0, the paper has none].";
    }
}

params! {
    /// Rigid platen with hold-down stiffness and dissipation, docs/model.md §3.
    pub struct PlatenParams {
        m: "kg", "kg", 144_000.0, Range::gt(0.0), Paper,
            "Effective platen mass M.";
        k: "N/m", "n_per_m", 1.266e6, Range::ge(0.0), Paper,
            "Effective horizontal stiffness K (hold-down struts).";
        c: "N·(s/m)^α", "n_s_per_m_alpha", 0.041e6, Range::ge(0.0), Paper,
            "Viscous coefficient C of the dissipative force C|v|^α·z.";
        alpha: "-", "", 0.5, Range::closed(0.0, 2.0), Paper,
            "Viscous exponent α.";
        mu_coef: "-", "", 0.00538, Range::ge(0.0), Paper,
            "Coulomb friction coefficient: μ = mu_coef·F_V with F_V = M·g [F_V = M·g chosen: the paper does not state F_V; μ = 7 597 N by default].";
    }
}

params! {
    /// Viscoplastic friction law dz/dt = (v/Y)(1 − z²[κ + (1−κ) sign(z v)]), docs/model.md §3.
    pub struct FrictionParams {
        y_yield: "m", "m", 0.2e-3, Range::gt(0.0), Paper,
            "Yield displacement Y of the friction law.";
        kappa: "-", "", 0.5, Range::closed(0.0, 1.0), Paper,
            "Shape parameter κ of the friction law.";
    }
}

params! {
    /// Three-variable controller (TVC) replica, docs/model.md §2.
    pub struct ControllerParams {
        f_s: "Hz", "hz", 1024.0, Range::closed(64.0, 65536.0), Chosen,
            "Controller sample rate f_s [chosen: MTS 469D class]. Batch-uniform: every lane of a batch shares it.";
        d_max: "m", "m", 0.75, Range::gt(0.0), Paper,
            "Displacement normalisation D_max (table limit).";
        v_max: "m/s", "m_per_s", 1.8, Range::gt(0.0), Paper,
            "Velocity normalisation V_max (table limit).";
        a_max: "m/s²", "mps2", 17.4, Range::gt(0.0), Chosen,
            "Acceleration normalisation A_max [chosen: published gains then track 3 Hz, 1.73 g with unit ratio, ~0° phase].";
        j_max: "m/s³", "mps3", 2200.0, Range::gt(0.0), Chosen,
            "Jerk normalisation J_max [chosen, as A_max].";
        f_max: "N", "n", 6.8e6, Range::gt(0.0), Paper,
            "Force normalisation F_max (table limit).";
        g_d: "-", "", 1.5, Range::any(), Paper,
            "Displacement (feedback) gain G_d.";
        l_d: "-", "", 0.0, Range::any(), Paper,
            "Displacement feedforward lead L_d.";
        l_v: "-", "", 0.38, Range::any(), Paper,
            "Velocity feedforward lead L_v.";
        l_a: "-", "", 0.52, Range::any(), Paper,
            "Acceleration feedforward lead L_a.";
        l_j: "-", "", 0.005, Range::any(), Paper,
            "Jerk feedforward lead L_j.";
        g_f: "-", "", -1.5, Range::any(), Paper,
            "Dynamic force gain G_f (on the high-passed actuator force).";
        f_hp: "Hz", "hz", 1.0, Range::gt(0.0), Chosen,
            "Corner of the force high-pass s/(s+ω_hp) [chosen].";
        notch1_f0: "Hz", "hz", 10.0, Range::gt(0.0), Chosen,
            "Notch 1 centre frequency [chosen placeholder: notches are off by default, depth 0].";
        notch1_bw: "Hz", "hz", 2.0, Range::gt(0.0), Chosen,
            "Notch 1 3 dB bandwidth [chosen placeholder].";
        notch1_depth: "dB", "db", 0.0, Range::closed(0.0, 120.0), Chosen,
            "Notch 1 depth; 0 dB = off [paper has five notches, values not published].";
        notch2_f0: "Hz", "hz", 20.0, Range::gt(0.0), Chosen,
            "Notch 2 centre frequency [chosen placeholder].";
        notch2_bw: "Hz", "hz", 4.0, Range::gt(0.0), Chosen,
            "Notch 2 3 dB bandwidth [chosen placeholder].";
        notch2_depth: "dB", "db", 0.0, Range::closed(0.0, 120.0), Chosen,
            "Notch 2 depth; 0 dB = off.";
        notch3_f0: "Hz", "hz", 40.0, Range::gt(0.0), Chosen,
            "Notch 3 centre frequency [chosen placeholder].";
        notch3_bw: "Hz", "hz", 8.0, Range::gt(0.0), Chosen,
            "Notch 3 3 dB bandwidth [chosen placeholder].";
        notch3_depth: "dB", "db", 0.0, Range::closed(0.0, 120.0), Chosen,
            "Notch 3 depth; 0 dB = off.";
        notch4_f0: "Hz", "hz", 80.0, Range::gt(0.0), Chosen,
            "Notch 4 centre frequency [chosen placeholder].";
        notch4_bw: "Hz", "hz", 16.0, Range::gt(0.0), Chosen,
            "Notch 4 3 dB bandwidth [chosen placeholder].";
        notch4_depth: "dB", "db", 0.0, Range::closed(0.0, 120.0), Chosen,
            "Notch 4 depth; 0 dB = off.";
        notch5_f0: "Hz", "hz", 160.0, Range::gt(0.0), Chosen,
            "Notch 5 centre frequency [chosen placeholder].";
        notch5_bw: "Hz", "hz", 32.0, Range::gt(0.0), Chosen,
            "Notch 5 3 dB bandwidth [chosen placeholder].";
        notch5_depth: "dB", "db", 0.0, Range::closed(0.0, 120.0), Chosen,
            "Notch 5 depth; 0 dB = off.";
    }
}

/// Which flow law the servo-valves follow (a structural choice, decided once per batch).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ValveLaw {
    /// Four-port square-root orifice law (docs/model.md §3), the baseline.
    #[default]
    Orifice,
    /// The published linear counter-example: q = K_q·x, no pressure dependence (docs/model.md §5).
    Linear,
}

impl ControllerParams {
    /// The five notch filters as (f0 Hz, bandwidth Hz, depth dB).
    pub fn notches(&self) -> [(f64, f64, f64); 5] {
        [
            (self.notch1_f0, self.notch1_bw, self.notch1_depth),
            (self.notch2_f0, self.notch2_bw, self.notch2_depth),
            (self.notch3_f0, self.notch3_bw, self.notch3_depth),
            (self.notch4_f0, self.notch4_bw, self.notch4_depth),
            (self.notch5_f0, self.notch5_bw, self.notch5_depth),
        ]
    }

    /// The TVC's gains folded with the 10 V scale and the normalisations (docs/model.md §2):
    /// [10·G_d/D_max (V/m), 10·L_d/D_max (V/m), 10·L_v/V_max (V/(m/s)), 10·L_a/A_max
    /// (V/(m/s²)), 10·L_j/J_max (V/(m/s³)), 10·G_f/F_max (V/N)].
    pub fn gains(&self) -> [f64; 6] {
        [
            10.0 * self.g_d / self.d_max,
            10.0 * self.l_d / self.d_max,
            10.0 * self.l_v / self.v_max,
            10.0 * self.l_a / self.a_max,
            10.0 * self.l_j / self.j_max,
            10.0 * self.g_f / self.f_max,
        ]
    }
}

impl ActuatorParams {
    /// No-load pressures (P1, P2) of the port-width design criterion (docs/model.md §3) with the
    /// supply `p_s` and return `p_r` (Pa): P1 = (P_S + P_R)/(1 + A1/A2), P2 = P1·A1/A2.
    pub fn no_load_pressures(&self, p_s: f64, p_r: f64) -> (f64, f64) {
        let r = self.a1 / self.a2;
        let p1 = (p_s + p_r) / (1.0 + r);
        (p1, p1 * r)
    }
}
