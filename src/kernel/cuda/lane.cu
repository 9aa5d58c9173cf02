// vshake's lane kernel in CUDA C++: one thread integrates one parameter set (a lane) of the
// baseline model of docs/model.md, with the library's stateless effects (gpu_lanes.rs:
// EFFECT_BITS), float64, the whole run in registers, and accumulates the metrics online, so that
// only the sums of `src/kernel/metrics.rs` come back.
//
// It transcribes `src/kernel/simulate.rs` (the tick, RK4 substeps, the §3 guard) and the parts it
// calls (controller.rs, servovalve.rs, actuator.rs, platen.rs, friction.rs, metrics.rs and
// spectrum.rs's oscillators) operation for operation, in the same order, so that the host build
// of this file gives the Rust kernel's numbers to rounding (`tests/cuda_host.rs` checks 1e-12).
// The two actuators are identical (no covered effect tells them apart), so one stands for both,
// as the Rust kernel's equivalent actuator does (A = 1: force and flows doubled, bit for bit).
//
// Compiled two ways:
// - at run time by NVRTC for the GPU (`src/shell/gpu.rs`; `__CUDACC_RTC__` defined);
// - for the host by a C++ compiler in `cargo test` (`tests/cuda_host.rs`), the CUDA qualifiers
//   defined away; `vs_lane` is then called in a loop over lanes.
//
// Layouts (all float64, field-major: field f of lane l at [f * lanes + l]) are written by
// `src/kernel/gpu_lanes.rs`, whose constants must match the VS_* ones below.

#ifdef __CUDACC_RTC__
#define VS_FN __device__ __forceinline__
typedef unsigned long long vs_u64;
VS_FN double vs_from_bits(vs_u64 b) { return __longlong_as_double((long long)b); }
VS_FN vs_u64 vs_to_bits(double x) { return (vs_u64)__double_as_longlong(x); }
#else
#include <cmath>
#include <cstring>
#define VS_FN static inline
typedef unsigned long long vs_u64;
VS_FN double vs_from_bits(vs_u64 b) { double x; std::memcpy(&x, &b, 8); return x; }
VS_FN vs_u64 vs_to_bits(double x) { vs_u64 b; std::memcpy(&b, &x, 8); return b; }
using std::fabs;
using std::fmax;
using std::pow;
using std::sqrt;
#endif

// Lane parameter record (gpu_lanes.rs: LANE_FIELDS).
enum {
  VS_KW1, VS_KW2, VS_KW3, VS_KW4, VS_P_R, VS_P_TR2, VS_KQ1, VS_KQ2,
  VS_P_S,
  VS_BETA, VS_A1, VS_A2, VS_L, VS_VD1, VS_VD2,
  VS_INV_M, VS_K, VS_C, VS_ALPHA, VS_MU,
  VS_INV_Y, VS_KAPPA, VS_KAPPA_NEG,
  VS_C_FB, VS_C_D, VS_C_V, VS_C_A, VS_C_J, VS_C_F, VS_HP_B, VS_HP_A,
  VS_NOTCH,                      // 5 biquads × [b0, b1, b2, a1, a2]
  VS_U_LIM = VS_NOTCH + 25, VS_K_SP, VS_P0_1, VS_P0_2,
  // Library effects (coefficients from each effect's `lane`, off lanes neutral):
  VS_FSAT,                       // flow_saturation: on, x_sat, 1/x_sat
  VS_FGAIN = VS_FSAT + 3,        // flow_gain: g at the 5 knots, 1/x_ref
  VS_LEAK = VS_FGAIN + 6,        // leakage: c_int, c_ext
  VS_SEAL = VS_LEAK + 2,         // seal_friction: f_c, f_s − f_c, 1/v_s, sigma, 1/v_eps
  VS_COMP = VS_SEAL + 5,         // compressibility: on, beta, 1/beta_e, air·p_atm, dead volume
  VS_BULK = VS_COMP + 5,         // bulk_curve: gain at the 3 knots, 1/P_S
  VS_HOLD = VS_BULK + 4,         // hold_down: k3
  VS_LANE_FIELDS
};

// Which effects a launch applies (gpu_lanes.rs: EFFECT_BITS), in registry order where they act
// on the same quantity.
enum {
  VS_E_FSAT = 1, VS_E_FGAIN = 2, VS_E_LEAK = 4, VS_E_SEAL = 8, VS_E_COMP = 16, VS_E_BULK = 32,
  VS_E_HOLD = 64
};

// Output record (gpu_lanes.rs: OUT_*). Status: 0 ok, 1 non-finite, 2 stroke, 3 pressure.
enum {
  VS_STATUS, VS_FAIL_TICK, VS_FAIL_VALUE, VS_FAIL_CHAMBER, VS_N_WINDOW, VS_MAX_U,
  VS_ERR_A2, VS_ERR_X2, VS_PEAK_ERR_A, VS_PEAK_ERR_X,
  VS_PEAK, VS_PEAK_R = VS_PEAK + 3,
  VS_AR_RE = VS_PEAK_R + 3, VS_AR_IM, VS_XR_RE, VS_XR_IM, VS_AR2, VS_XR2, VS_X_RE, VS_X_IM,
  VS_A_RE, VS_A_IM = VS_A_RE + 9,
  VS_OSC_PEAK = VS_A_IM + 9,     // one per oscillator of the response spectrum
};

// The run shared by every lane (gpu_lanes.rs: Shared).
struct VsRun {
  long long ticks, substeps, w0, w1;
  long long has_basis;           // harmonic basis per window tick (a sine's fundamental)
  long long drive;               // 0 closed loop, 1 valve command (V), 2 spool position (m)
  long long linear_valve;        // 0 orifice law, 1 linear law
  long long n_osc;               // response-spectrum oscillators (0: none)
  long long ref_stride;          // 0: one reference for every lane; else lane l's at l × stride
  long long effects;             // VS_E_* bits
  double f_s;
  const double *x, *v, *a, *j;   // reference per tick
  const double *drive_signal;    // per tick (drive 1 or 2)
  const double *basis;           // (w1 − w0) × [cos 1..9, sin 1..9]
  const double *osc;             // n_osc × [a00, a01, a10, a11, b00, b01, b10, b11]
};

#define VS_MAX_OSC 128

struct VsState { double p1, p2, y, v, z; };

// servovalve.rs: the regularised square root, Newton for s^(−1/4) from a bit-trick seed.
VS_FN double vs_inv_fourth_root(double s) {
  double y = vs_from_bits(0x4feb0c0bba5e3540ULL - (vs_to_bits(s) >> 2));
  for (int i = 0; i < 4; ++i) {
    double y2 = y * y;
    y *= 1.25 - 0.25 * s * (y2 * y2);
  }
  return y;
}

VS_FN double vs_sq(double dp, double p_tr2) { return dp * vs_inv_fourth_root(dp * dp + p_tr2); }

VS_FN bool vs_finite(double x) { return x - x == 0.0; }

#define F(i) P[(i) * n + l]

// effects/flow_saturation.rs and flow_gain.rs `opening`: the command through the metering.
VS_FN double vs_opening(const double *P, long long n, long long l, long long e, double x) {
  if (e & VS_E_FSAT) x = x + F(VS_FSAT) * (F(VS_FSAT + 1) * tanh(x * F(VS_FSAT + 2)) - x);
  if (e & VS_E_FGAIN) {
    const double knots[5] = {0.0, 0.05, 0.15, 0.35, 0.7};
    double r = fabs(x) * F(VS_FGAIN + 5), g = F(VS_FGAIN + 4);
    for (int k = 3; k >= 0; --k) {
      double w = (r - knots[k]) / (knots[k + 1] - knots[k]);
      if (r < knots[k + 1]) g = F(VS_FGAIN + k) + w * (F(VS_FGAIN + k + 1) - F(VS_FGAIN + k));
    }
    x = x * g;
  }
  return x;
}

// effects/compressibility.rs `one`: a chamber's β/V with dead volume and entrained air.
VS_FN double vs_compress(const double *P, long long n, long long l, double b, double p) {
  double pa = fmax(p + 101325.0, 0.1 * 101325.0);
  double beta_e = 1.0 / (F(VS_COMP + 2) + F(VS_COMP + 3) / (pa * pa));
  double volume = F(VS_COMP + 1) / b + F(VS_COMP + 4);
  return b + F(VS_COMP) * (beta_e / volume - b);
}

// effects/bulk_curve.rs `gain`: the bulk modulus's gain at gauge pressure p.
VS_FN double vs_bulk_gain(const double *P, long long n, long long l, double p) {
  const double knots[3] = {0.0, 0.5, 1.0};
  double r = p * F(VS_BULK + 3);
  double g = r < 0.0 ? F(VS_BULK) : F(VS_BULK + 2);
  for (int k = 1; k >= 0; --k) {
    double w = (r - knots[k]) / (knots[k + 1] - knots[k]);
    if (r >= knots[k] && r < knots[k + 1]) g = F(VS_BULK + k) + w * (F(VS_BULK + k + 1) - F(VS_BULK + k));
  }
  return g;
}

// effects/seal_friction.rs and hold_down.rs `extra_force`.
VS_FN double vs_extra_force(const double *P, long long n, long long l, long long e, double y,
                            double v) {
  double fe = 0.0;
  if (e & VS_E_SEAL) {
    double r = v * F(VS_SEAL + 2);
    fe = fe + (-tanh(v * F(VS_SEAL + 4)) * (F(VS_SEAL) + F(VS_SEAL + 1) * exp(-r * r)) -
               F(VS_SEAL + 3) * v);
  }
  if (e & VS_E_HOLD) fe = fe + -F(VS_HOLD) * y * y * y;
  return fe;
}

#undef F

// simulate.rs `rhs` with the baseline effect and one actuator standing for two.
VS_FN void vs_rhs(const double *P, long long n, long long l, bool linear, long long e,
                  double x_c, const VsState &s, VsState &d) {
#define F(i) P[(i) * n + l]
  double ps = F(VS_P_S);
  double b1 = F(VS_BETA) / (F(VS_A1) * (F(VS_L) + s.y) + F(VS_VD1));
  double b2 = F(VS_BETA) / (F(VS_A2) * (F(VS_L) - s.y) + F(VS_VD2));
  x_c = vs_opening(P, n, l, e, x_c);
  double q1, q2;
  if (linear) {
    q1 = F(VS_KQ1) * x_c;
    q2 = F(VS_KQ2) * x_c;
  } else {
    bool pos = x_c > 0.0;
    double dp1 = pos ? ps - s.p1 : s.p1 - F(VS_P_R);
    double k1 = pos ? F(VS_KW1) : F(VS_KW3);
    double dp2 = pos ? s.p2 - F(VS_P_R) : ps - s.p2;
    double k2 = pos ? F(VS_KW2) : F(VS_KW4);
    q1 = k1 * x_c * vs_sq(dp1, F(VS_P_TR2));
    q2 = k2 * x_c * vs_sq(dp2, F(VS_P_TR2));
  }
  if (e & VS_E_LEAK) {
    double cross = F(VS_LEAK) * (s.p1 - s.p2);
    q1 = q1 - cross - F(VS_LEAK + 1) * s.p1;
    q2 = q2 - cross + F(VS_LEAK + 1) * s.p2;
  }
  if (e & VS_E_COMP) {
    b1 = vs_compress(P, n, l, b1, s.p1);
    b2 = vs_compress(P, n, l, b2, s.p2);
  }
  if (e & VS_E_BULK) {
    b1 = b1 * vs_bulk_gain(P, n, l, s.p1);
    b2 = b2 * vs_bulk_gain(P, n, l, s.p2);
  }
  d.p1 = b1 * (q1 - F(VS_A1) * s.v);
  d.p2 = b2 * (F(VS_A2) * s.v - q2);
  double f = s.p1 * F(VS_A1) - s.p2 * F(VS_A2);
  f = f + f;
  double alpha = F(VS_ALPHA), va = fabs(s.v);
  double damp = alpha == 0.5 ? sqrt(va) : pow(va, alpha);
  double fe = vs_extra_force(P, n, l, e, s.y, s.v);
  d.v = (f + fe - F(VS_K) * s.y - (F(VS_C) * damp + F(VS_MU)) * s.z) * F(VS_INV_M);
  d.y = s.v;
  double zv = s.z * s.v;
  double bracket = zv > 0.0 ? 1.0 : (zv < 0.0 ? F(VS_KAPPA_NEG) : F(VS_KAPPA));
  d.z = s.v * F(VS_INV_Y) * (1.0 - s.z * s.z * bracket);
#undef F
}

VS_FN void vs_axpy(VsState &o, const VsState &b, double h, const VsState &k) {
  o.p1 = b.p1 + h * k.p1;
  o.p2 = b.p2 + h * k.p2;
  o.y = b.y + h * k.y;
  o.v = b.v + h * k.v;
  o.z = b.z + h * k.z;
}

VS_FN double vs_rk4(double s, double h6, double k1, double k2, double k3, double k4) {
  return s + h6 * (k1 + 2.0 * (k2 + k3) + k4);
}

// controller.rs `tick`: the force high-pass, the gains, five notches, the clamp.
struct VsCtrl { double f_prev, f_hp, notch[5][2]; };

VS_FN double vs_tick(const double *P, long long n, long long l, VsCtrl &m, double xr, double vr,
                     double ar, double jr, double x, double f) {
#define F(i) P[(i) * n + l]
  m.f_hp = F(VS_HP_B) * (f - m.f_prev) + F(VS_HP_A) * m.f_hp;
  m.f_prev = f;
  double u = F(VS_C_FB) * (xr - x) + F(VS_C_D) * xr + F(VS_C_V) * vr + F(VS_C_A) * ar +
             F(VS_C_J) * jr + F(VS_C_F) * m.f_hp;
  for (int i = 0; i < 5; ++i) {
    const long long q = VS_NOTCH + 5 * i;
    double y = F(q) * u + m.notch[i][0];
    m.notch[i][0] = F(q + 1) * u - F(q + 3) * y + m.notch[i][1];
    m.notch[i][1] = F(q + 2) * u - F(q + 4) * y;
    u = y;
  }
  double lim = F(VS_U_LIM);
  return u < -lim ? -lim : (u > lim ? lim : u);
#undef F
}

// simulate.rs `check_lane`: 0 alive, else the status code, with the value and the chamber.
VS_FN int vs_guard(const double *P, long long n, long long l, const VsState &s, double &value,
                   double &chamber) {
  if (!(vs_finite(s.p1) && vs_finite(s.p2) && vs_finite(s.y) && vs_finite(s.v) &&
        vs_finite(s.z)))
    return 1;
  if (fabs(s.y) >= P[VS_L * n + l]) {
    value = s.y;
    return 2;
  }
  double hi = 2.0 * P[VS_P_S * n + l];
  if (!(s.p1 >= -1.0e6 && s.p1 <= hi)) {
    value = s.p1;
    chamber = 1.0;
    return 3;
  }
  if (!(s.p2 >= -1.0e6 && s.p2 <= hi)) {
    value = s.p2;
    chamber = 2.0;
    return 3;
  }
  return 0;
}

// metrics.rs `MetricsAcc`: the sums of one lane.
struct VsAcc {
  double n, max_u, err_a2, err_x2, peak_err_a, peak_err_x, peak[3], peak_r[3];
  double ar_re, ar_im, xr_re, xr_im, ar2, xr2, x_re, x_im, a_re[9], a_im[9];
  double osc_u[VS_MAX_OSC], osc_v[VS_MAX_OSC], osc_peak[VS_MAX_OSC], prev;
};

VS_FN void vs_window(const VsRun &r, long long k, long long at, VsAcc &c, double a, double v,
                     double x) {
  double a_r = r.a[at], v_r = r.v[at], x_r = r.x[at];
  c.n += 1.0;
  c.ar2 += a_r * a_r;
  c.xr2 += x_r * x_r;
  double ea = a - a_r, ex = x - x_r;
  c.err_a2 += ea * ea;
  c.err_x2 += ex * ex;
  c.peak_err_a = fmax(c.peak_err_a, fabs(ea));
  c.peak_err_x = fmax(c.peak_err_x, fabs(ex));
  const double got[3] = {a, v, x}, want[3] = {a_r, v_r, x_r};
  for (int i = 0; i < 3; ++i) {
    c.peak[i] = fmax(c.peak[i], fabs(got[i]));
    c.peak_r[i] = fmax(c.peak_r[i], fabs(want[i]));
  }
  if (r.n_osc > 0) {
    if (k > r.w0) {
      for (long long i = 0; i < r.n_osc; ++i) {
        const double *o = r.osc + 8 * i;
        double u = c.osc_u[i], w = c.osc_v[i];
        double un = o[0] * u + o[1] * w + o[4] * c.prev + o[5] * a;
        double vn = o[2] * u + o[3] * w + o[6] * c.prev + o[7] * a;
        c.osc_u[i] = un;
        c.osc_v[i] = vn;
        c.osc_peak[i] = fmax(c.osc_peak[i], fabs(un));
      }
    }
    c.prev = a;
  }
  if (r.has_basis) {
    const double *b = r.basis + 18 * (k - r.w0);
    c.ar_re += a_r * b[0];
    c.ar_im += a_r * b[9];
    c.xr_re += x_r * b[0];
    c.xr_im += x_r * b[9];
    for (int h = 0; h < 9; ++h) {
      c.a_re[h] += a * b[h];
      c.a_im[h] += a * b[9 + h];
    }
    c.x_re += x * b[0];
    c.x_im += x * b[9];
  }
}

VS_FN void vs_store(const VsRun &r, double *out, long long n, long long l, const VsAcc &c) {
#define O(i) out[(i) * n + l]
  O(VS_N_WINDOW) = c.n;
  O(VS_MAX_U) = c.max_u;
  O(VS_ERR_A2) = c.err_a2;
  O(VS_ERR_X2) = c.err_x2;
  O(VS_PEAK_ERR_A) = c.peak_err_a;
  O(VS_PEAK_ERR_X) = c.peak_err_x;
  for (int i = 0; i < 3; ++i) {
    O(VS_PEAK + i) = c.peak[i];
    O(VS_PEAK_R + i) = c.peak_r[i];
  }
  O(VS_AR_RE) = c.ar_re;
  O(VS_AR_IM) = c.ar_im;
  O(VS_XR_RE) = c.xr_re;
  O(VS_XR_IM) = c.xr_im;
  O(VS_AR2) = c.ar2;
  O(VS_XR2) = c.xr2;
  O(VS_X_RE) = c.x_re;
  O(VS_X_IM) = c.x_im;
  for (int h = 0; h < 9; ++h) {
    O(VS_A_RE + h) = c.a_re[h];
    O(VS_A_IM + h) = c.a_im[h];
  }
  for (long long i = 0; i < r.n_osc; ++i) O(VS_OSC_PEAK + i) = c.osc_peak[i];
#undef O
}

// The spool command held over tick k (simulate.rs `integrate`, the drive match).
VS_FN double vs_command(const double *P, long long n, long long l, const VsRun &r, long long k,
                        VsCtrl &m, const VsState &s, double f, double &u) {
  double k_sp = P[VS_K_SP * n + l];
  if (r.drive == 0) {
    long long at = l * r.ref_stride + k;
    u = vs_tick(P, n, l, m, r.x[at], r.v[at], r.a[at], r.j[at], s.y, f);
    return k_sp * u;
  }
  if (r.drive == 1) {
    double lim = P[VS_U_LIM * n + l], c = r.drive_signal[k];
    u = c < -lim ? -lim : (c > lim ? lim : c);
    return k_sp * u;
  }
  long long next = k + 1 < r.ticks ? k + 1 : r.ticks - 1;
  double x_c = 0.5 * (r.drive_signal[k] + r.drive_signal[next]);
  u = x_c / k_sp;
  return x_c;
}

// One controller tick's RK4 substeps with the command held.
VS_FN void vs_substeps(const double *P, long long n, long long l, const VsRun &r, double x_c,
                       VsState &s, VsState &k1) {
  bool linear = r.linear_valve != 0;
  double h = 1.0 / (r.f_s * (double)r.substeps);
  VsState k2, k3, k4, t;
  for (long long sub = 0; sub < r.substeps; ++sub) {
    if (sub > 0) vs_rhs(P, n, l, linear, r.effects, x_c, s, k1);
    vs_axpy(t, s, 0.5 * h, k1);
    vs_rhs(P, n, l, linear, r.effects, x_c, t, k2);
    vs_axpy(t, s, 0.5 * h, k2);
    vs_rhs(P, n, l, linear, r.effects, x_c, t, k3);
    vs_axpy(t, s, h, k3);
    vs_rhs(P, n, l, linear, r.effects, x_c, t, k4);
    double h6 = h / 6.0;
    s.p1 = vs_rk4(s.p1, h6, k1.p1, k2.p1, k3.p1, k4.p1);
    s.p2 = vs_rk4(s.p2, h6, k1.p2, k2.p2, k3.p2, k4.p2);
    s.y = vs_rk4(s.y, h6, k1.y, k2.y, k3.y, k4.y);
    s.v = vs_rk4(s.v, h6, k1.v, k2.v, k3.v, k4.v);
    s.z = vs_rk4(s.z, h6, k1.z, k2.z, k3.z, k4.z);
  }
}

// The whole run of lane l: params P (n lanes), results to out (n lanes).
VS_FN void vs_lane(const VsRun &r, const double *P, double *out, long long n, long long l) {
  VsState s = {P[VS_P0_1 * n + l], P[VS_P0_2 * n + l], 0.0, 0.0, 0.0}, k1;
  VsCtrl m = {};
  VsAcc c = {};
  double a1 = P[VS_A1 * n + l], a2 = P[VS_A2 * n + l];
  m.f_prev = 2.0 * (s.p1 * a1 - s.p2 * a2);
  double status = 0.0, fail_tick = 0.0, value = 0.0, chamber = 0.0;
  bool linear = r.linear_valve != 0;
  for (long long k = 0; k < r.ticks; ++k) {
    double f0 = s.p1 * a1 - s.p2 * a2, u = 0.0;
    double x_c = vs_command(P, n, l, r, k, m, s, f0 + f0, u);
    vs_rhs(P, n, l, linear, r.effects, x_c, s, k1);
    c.max_u = fmax(c.max_u, fabs(u));
    if (k >= r.w0 && k < r.w1) vs_window(r, k, l * r.ref_stride + k, c, k1.v, s.v, s.y);
    vs_substeps(P, n, l, r, x_c, s, k1);
    int why = vs_guard(P, n, l, s, value, chamber);
    if (why != 0) {
      status = (double)why;
      fail_tick = (double)(k + 1);
      break;
    }
  }
  out[VS_STATUS * n + l] = status;
  out[VS_FAIL_TICK * n + l] = fail_tick;
  out[VS_FAIL_VALUE * n + l] = value;
  out[VS_FAIL_CHAMBER * n + l] = chamber;
  vs_store(r, out, n, l, c);
}

#ifdef __CUDACC_RTC__
// The launch: the run's integers in the order of gpu_lanes.rs `Shared::ints`, then its arrays.
extern "C" __global__ void vs_lanes(long long ticks, long long substeps, long long w0,
                                    long long w1, long long has_basis, long long drive,
                                    long long linear_valve, long long n_osc,
                                    long long ref_stride, long long effects, double f_s,
                                    const double *x, const double *v, const double *a,
                                    const double *j, const double *drive_signal,
                                    const double *basis, const double *osc, const double *P,
                                    double *out, long long n) {
  long long l = (long long)blockIdx.x * blockDim.x + threadIdx.x;
  VsRun r = {ticks, substeps, w0, w1, has_basis, drive, linear_valve, n_osc, ref_stride, effects, f_s,
             x, v, a, j, drive_signal, basis, osc};
  if (l < n) vs_lane(r, P, out, n, l);
}
#endif
