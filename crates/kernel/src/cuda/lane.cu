// vshake's lane kernel in CUDA C++: one thread integrates one parameter set (a lane) of the
// model of docs/model.md with any of the library's effects (gpu_lanes.rs: EFFECT_BITS), float64,
// the whole run in registers, and accumulates the metrics online, so that only the sums of
// `crates/kernel/src/metrics.rs` come back.
//
// It transcribes `crates/kernel/src/simulate.rs` (the tick, RK4 substeps, the §3 guard) and the parts it
// calls (controller.rs, servovalve.rs, actuator.rs, platen.rs, friction.rs, metrics.rs,
// spectrum.rs's oscillators and each effect's hooks, composed in registry order as the Rust
// effect set composes them) operation for operation, in the same order, so that the host build
// of this file gives the Rust kernel's numbers to rounding (`tests/cuda_host.rs` checks 1e-12).
// Unless an effect tells the two actuators apart (asymmetry's actuator-2 gain: VS_E_TWO), one
// stands for both, as the Rust kernel's equivalent actuator does (force and flows doubled, bit
// for bit the same as two identical actuators).
//
// Compiled two ways:
// - at run time by NVRTC for the GPU (`src/shell/gpu.rs`; `__CUDACC_RTC__` defined);
// - for the host by a C++ compiler in `cargo test` (`tests/cuda_host.rs`), the CUDA qualifiers
//   defined away; `vs_lane` is then called in a loop over lanes.
//
// Layouts (all float64, field-major: field f of lane l at [f * lanes + l]) are written by
// `crates/kernel/src/gpu_lanes.rs`, whose constants must match the VS_* ones below.

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
using std::fmin;
using std::pow;
using std::sqrt;
using std::cos;
using std::sin;
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
  // Library effects, in registry order (coefficients from each effect's `lane`, off lanes
  // neutral):
  VS_DELAY,                      // transport_delay: on, 4/tau
  VS_SPOOL = VS_DELAY + 2,       // spool_dynamics: on, ω², 2ζω
  VS_FSAT = VS_SPOOL + 3,        // flow_saturation: on, x_sat, 1/x_sat
  VS_FGAIN = VS_FSAT + 3,        // flow_gain: g at the 5 knots, 1/x_ref
  VS_ASYM = VS_FGAIN + 6,        // asymmetry: extension gain, actuator 2's gain
  VS_LEAK = VS_ASYM + 2,         // leakage: c_int, c_ext
  VS_SUPPLY = VS_LEAK + 2,       // supply: on, P_S0, q_pump, 1/c_acc, 1/dp_band
  VS_SEAL = VS_SUPPLY + 5,       // seal_friction: f_c, f_s − f_c, 1/v_s, sigma, 1/v_eps
  VS_COMP = VS_SEAL + 5,         // compressibility: on, beta, 1/beta_e, air·p_atm, dead volume
  VS_BULK = VS_COMP + 5,         // bulk_curve: gain at the 3 knots, 1/P_S
  VS_RMASS = VS_BULK + 4,        // reaction_mass: 1/m_r (0 off), k_r, c_r
  VS_HOLD = VS_RMASS + 3,        // hold_down: k3
  VS_SPEC = VS_HOLD + 1,         // specimen: per mode m (0 off), ω², 2ζω
  VS_SENSOR = VS_SPEC + 9,       // accel, disp, force sensors: on, ω², 2ζω, τ, Padé, 12/τ², 6/τ
  VS_BLD = VS_SENSOR + 21,       // building: law (0 off), α, Bouc–Wen A, β, γ, n, then per
                                 // storey 1/m (0 absent), k, c, F_y, then 1/height
  VS_VCOMP = VS_BLD + 7 + 4 * 10, // valve_compensator: on, P_S, P_R, 1/Δp₀ of the 4 ports, g_min
  VS_APC = VS_VCOMP + 8,         // amplitude_phase: on, μ, λ, τ, authority, freeze time
  VS_AHC = VS_APC + 6,           // harmonic_cancellation: the same six
  VS_AIC = VS_AHC + 6,           // adaptive_inverse: on, λ, pole a, √(1−a²), D, D/f_s, α, freeze
                                 // time, the copy's step β, then the 16 taps at the start
  VS_LANE_FIELDS = VS_AIC + 25
};

// Which effects a build applies (gpu_lanes.rs: EFFECT_BITS), bit i = registry line i, and
// whether the two actuators differ (then both are integrated, else one stands for both).
enum {
  VS_E_DELAY = 1, VS_E_SPOOL = 2, VS_E_FSAT = 4, VS_E_FGAIN = 8, VS_E_ASYM = 16, VS_E_LEAK = 32,
  VS_E_SUPPLY = 64, VS_E_SEAL = 128, VS_E_COMP = 256, VS_E_BULK = 512, VS_E_RMASS = 1024,
  VS_E_HOLD = 2048, VS_E_SPEC = 4096, VS_E_ACCEL = 8192, VS_E_DISP = 16384, VS_E_FORCE = 32768,
  VS_E_BLD = 65536, VS_E_VCOMP = 131072, VS_E_APC = 262144, VS_E_AHC = 524288,
  VS_E_AIC = 1048576, VS_E_TWO = 2097152
};

// Output record (gpu_lanes.rs: OUT_*). Status: 0 ok, 1 non-finite, 2 stroke, 3 pressure.
enum {
  VS_STATUS, VS_FAIL_TICK, VS_FAIL_VALUE, VS_FAIL_CHAMBER, VS_N_WINDOW, VS_MAX_U,
  VS_ERR_A2, VS_ERR_X2, VS_PEAK_ERR_A, VS_PEAK_ERR_X,
  VS_PEAK, VS_PEAK_R = VS_PEAK + 3,
  VS_AR_RE = VS_PEAK_R + 3, VS_AR_IM, VS_XR_RE, VS_XR_IM, VS_AR2, VS_XR2, VS_X_RE, VS_X_IM,
  VS_A_RE, VS_A_IM = VS_A_RE + 9,
  VS_SPECIMEN = VS_A_IM + 9,     // the building's peak drift ratio, base shear, ductility, energy
  VS_OSC_PEAK = VS_SPECIMEN + 4,     // one per oscillator of the response spectrum
};

// The effects are fixed when the kernel is compiled (NVRTC: -DVS_EFFECTS=bits, one build per
// set of effects), so that a build carries only the states of its effects in registers. The
// host build reads them per run (`vs_effects`, set by the harness).
#ifndef VS_EFFECTS
#ifdef __CUDACC_RTC__
#error "the kernel is compiled with -DVS_EFFECTS=<bits>"
#else
static long long vs_effects = 0;
#define VS_EFFECTS vs_effects
#endif
#endif
#define VS_ON(bit) ((VS_EFFECTS & (bit)) != 0)
#define VS_NA (VS_ON(VS_E_TWO) ? 2 : 1)

// The effects' own states (gpu_lanes.rs: their order in the Rust effect set).
enum {
  VS_S_DELAY = 0,                // transport_delay: the 4 lags
  VS_S_SPOOL = 4,                // spool_dynamics: x, v of actuator 1, then of actuator 2
  VS_S_SUPPLY = 8,               // supply: the accumulator's pressure
  VS_S_RMASS = 9,                // reaction_mass: y_r, v_r
  VS_S_SPEC = 11,                // specimen: u, u' per mode
  VS_S_SENSOR = 17,              // per sensor (accel, disp, force): y, y', z, z'
  VS_S_BLD = 29,                 // building: per storey u, u', r, ∫R dd
  VS_NES = 69
};

// Whether extra state i is integrated in this build.
VS_FN bool vs_live(int i) {
  if (i < VS_S_SPOOL) return VS_ON(VS_E_DELAY);
  if (i < VS_S_SUPPLY) return VS_ON(VS_E_SPOOL) && (i < VS_S_SPOOL + 2 || VS_ON(VS_E_TWO));
  if (i < VS_S_RMASS) return VS_ON(VS_E_SUPPLY);
  if (i < VS_S_SPEC) return VS_ON(VS_E_RMASS);
  if (i < VS_S_SENSOR) return VS_ON(VS_E_SPEC);
  if (i < VS_S_BLD) return VS_ON(VS_E_ACCEL << ((i - VS_S_SENSOR) / 4));
  return VS_ON(VS_E_BLD);
}

// The run shared by every lane (gpu_lanes.rs: Shared).
struct VsRun {
  long long ticks, substeps, w0, w1;
  long long has_basis;           // harmonic basis per window tick (a sine's fundamental)
  long long drive;               // 0 closed loop, 1 valve command (V), 2 spool position (m)
  long long linear_valve;        // 0 orifice law, 1 linear law
  long long n_osc;               // response-spectrum oscillators (0: none)
  long long ref_stride;          // 0: one reference for every lane; else lane l's at l × stride
  long long effects;             // VS_E_* bits (the build's VS_EFFECTS)
  double f_s;
  const double *x, *v, *a, *j;   // reference per tick
  const double *drive_signal;    // per tick (drive 1 or 2)
  const double *basis;           // (w1 − w0) × [cos 1..9, sin 1..9]
  const double *osc;             // n_osc × [a00, a01, a10, a11, b00, b01, b10, b11]
};

#define VS_MAX_OSC 128

// The plant's states (both actuators' pressures; the second used when they differ), then the
// effects' own.
struct VsState { double p1[2], p2[2], y, v, z, e[VS_NES]; };

// Parameters that every lane of a launch shares (gpu_lanes.rs `Uniform`) are read from `vs_u`
// (on the GPU a constant-bank operand); P holds the records of the varying fields alone,
// field-major, in field order (lane l's value of the s-th varying field at P[s * n + l]). Which
// fields vary is fixed when the kernel is compiled (NVRTC: -DVS_VARY0..3, bit f of the 256-bit
// mask for field f), so that each read is resolved then; the host build reads the mask per run
// (`vs_vary`, set by the harness).
VS_FN constexpr int vs_popc(vs_u64 x) {
  x = x - ((x >> 1) & 0x5555555555555555ULL);
  x = (x & 0x3333333333333333ULL) + ((x >> 2) & 0x3333333333333333ULL);
  x = (x + (x >> 4)) & 0x0F0F0F0F0F0F0F0FULL;
  return (int)((x * 0x0101010101010101ULL) >> 56);
}

// Whether field i varies under the mask (m0, m1, m2, m3), and its row in P.
VS_FN constexpr bool vs_varies_in(vs_u64 m0, vs_u64 m1, vs_u64 m2, vs_u64 m3, int i) {
  return (((i < 64 ? m0 : (i < 128 ? m1 : (i < 192 ? m2 : m3))) >> (i & 63)) & 1ULL) != 0;
}
VS_FN constexpr int vs_row_in(vs_u64 m0, vs_u64 m1, vs_u64 m2, vs_u64 m3, int i) {
  return i < 64    ? vs_popc(m0 & ((1ULL << i) - 1))
         : i < 128 ? vs_popc(m0) + vs_popc(m1 & ((1ULL << (i - 64)) - 1))
         : i < 192 ? vs_popc(m0) + vs_popc(m1) + vs_popc(m2 & ((1ULL << (i - 128)) - 1))
                   : vs_popc(m0) + vs_popc(m1) + vs_popc(m2) + vs_popc(m3 & ((1ULL << (i - 192)) - 1));
}

#ifdef __CUDACC_RTC__
#if !defined(VS_VARY0) || !defined(VS_VARY1) || !defined(VS_VARY2) || !defined(VS_VARY3)
#error "the kernel is compiled with -DVS_VARY0=<mask> ... -DVS_VARY3=<mask>"
#endif
__constant__ double vs_u[VS_LANE_FIELDS];
#define VS_MASK VS_VARY0, VS_VARY1, VS_VARY2, VS_VARY3
#else
static double vs_u[VS_LANE_FIELDS];
static vs_u64 vs_vary[4] = {~0ULL, ~0ULL, ~0ULL, ~0ULL};
#define VS_MASK vs_vary[0], vs_vary[1], vs_vary[2], vs_vary[3]
#endif

// Field i of lane l's parameters (n lanes).
VS_FN double vs_p(const double *P, long long n, long long l, int i) {
  return vs_varies_in(VS_MASK, i) ? P[vs_row_in(VS_MASK, i) * n + l] : vs_u[i];
}

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

#define F(i) vs_p(P, n, l, (i))

// The command after transport_delay (its spool_position, which the spool's dynamics follow).
VS_FN double vs_delayed(const double *P, long long n, long long l, const VsState &s, double x) {
  if (VS_ON(VS_E_DELAY)) x = x + F(VS_DELAY) * (s.e[VS_S_DELAY + 3] - x);
  return x;
}

// The `opening` hooks in registry order: delay, spool dynamics, flow_saturation, flow_gain.
VS_FN double vs_opening(const double *P, long long n, long long l, int act, const VsState &s,
                        double x) {
  x = vs_delayed(P, n, l, s, x);
  if (VS_ON(VS_E_SPOOL)) x = x + F(VS_SPOOL) * (s.e[VS_S_SPOOL + 2 * act] - x);
  if (VS_ON(VS_E_FSAT)) x = x + F(VS_FSAT) * (F(VS_FSAT + 1) * tanh(x * F(VS_FSAT + 2)) - x);
  if (VS_ON(VS_E_FGAIN)) {
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

// The `flows` hooks in registry order: asymmetry, then leakage.
VS_FN void vs_flows(const double *P, long long n, long long l, int act, double p1, double p2,
                    double &q1, double &q2) {
  if (VS_ON(VS_E_ASYM)) {
    double g = (q1 > 0.0 ? F(VS_ASYM) : 1.0) * (act == 1 ? F(VS_ASYM + 1) : 1.0);
    q1 = g * q1;
    q2 = g * q2;
  }
  if (VS_ON(VS_E_LEAK)) {
    double cross = F(VS_LEAK) * (p1 - p2);
    q1 = q1 - cross - F(VS_LEAK + 1) * p1;
    q2 = q2 - cross + F(VS_LEAK + 1) * p2;
  }
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

// The `chamber_stiffness` hooks: compressibility, then bulk_curve.
VS_FN void vs_stiffness(const double *P, long long n, long long l, double p1, double p2,
                        double &b1, double &b2) {
  if (VS_ON(VS_E_COMP)) {
    b1 = vs_compress(P, n, l, b1, p1);
    b2 = vs_compress(P, n, l, b2, p2);
  }
  if (VS_ON(VS_E_BULK)) {
    b1 = b1 * vs_bulk_gain(P, n, l, p1);
    b2 = b2 * vs_bulk_gain(P, n, l, p2);
  }
}

// +inf (a bilinear cap that never holds).
VS_FN double vs_inf() { return vs_from_bits(0x7ff0000000000000ULL); }

// building.rs: storey i's drift and its rate.
VS_FN void vs_drift(const VsState &s, int i, double &d, double &dd) {
  const int u = VS_S_BLD + 4 * i;
  d = i == 0 ? s.e[u] : s.e[u] - s.e[u - 4];
  dd = i == 0 ? s.e[u + 1] : s.e[u + 1] - s.e[u - 3];
}

// building.rs `restoring`: α k d + (1 − α) r, r held at ±F_y by the bilinear law (law 1).
VS_FN double vs_restoring(const double *P, long long n, long long l, int i, double d, double r) {
  const long long q = VS_BLD + 6 + 4 * i;
  double cap = F(VS_BLD) == 1.0 && F(q) != 0.0 ? F(q + 3) : vs_inf();
  double held = fmin(fmax(r, -cap), cap);
  double a = F(VS_BLD + 1);
  return a * F(q + 1) * d + (1.0 - a) * held;
}

// building.rs: storey i's shear, R + c ḋ.
VS_FN double vs_shear(const double *P, long long n, long long l, int i, const VsState &s) {
  double d, dd;
  vs_drift(s, i, d, dd);
  return vs_restoring(P, n, l, i, d, s.e[VS_S_BLD + 4 * i + 2]) + F(VS_BLD + 6 + 4 * i + 2) * dd;
}

// building.rs `watch`, once per tick: the peaks of the drift ratio, the base shear and the
// ductility demand, and the energy the storeys dissipated (work less the elastic energy held).
VS_FN void vs_watch(const double *P, long long n, long long l, const VsState &s, double *spec) {
  if (F(VS_BLD + 6) == 0.0) return;
  double drift = 0.0, ductility = 0.0, energy = 0.0, a = F(VS_BLD + 1);
  for (int i = 0; i < 10 && F(VS_BLD + 6 + 4 * i) != 0.0; ++i) {
    const long long q = VS_BLD + 6 + 4 * i;
    const int u = VS_S_BLD + 4 * i;
    double d, dd, k = F(q + 1);
    vs_drift(s, i, d, dd);
    double cap = F(VS_BLD) == 1.0 ? F(q + 3) : vs_inf();
    double held = fmin(fmax(s.e[u + 2], -cap), cap);
    drift = fmax(drift, fabs(d));
    ductility = fmax(ductility, fabs(d) * k / F(q + 3));
    energy += s.e[u + 3] - 0.5 * a * k * d * d - 0.5 * (1.0 - a) * held * held / k;
  }
  spec[0] = fmax(spec[0], drift * F(VS_BLD + 6 + 4 * 10));
  spec[1] = fmax(spec[1], fabs(vs_shear(P, n, l, 0, s)));
  if (F(VS_BLD) > 0.0) spec[2] = fmax(spec[2], ductility);  // linear storeys: none (NaN)
  spec[3] = energy;
}

// The `extra_force` hooks, summed as the Rust effect set nests them:
// seal + (hold + (specimen + building)).
VS_FN double vs_extra_force(const double *P, long long n, long long l, const VsState &s) {
  double fe = 0.0;
  if (VS_ON(VS_E_BLD)) fe = vs_shear(P, n, l, 0, s) + 0.0;
  if (VS_ON(VS_E_SPEC)) {
    double sum = -0.0;
    for (int i = 0; i < 3; ++i) {
      const long long q = VS_SPEC + 3 * i;
      sum = sum + F(q) * (F(q + 1) * s.e[VS_S_SPEC + 2 * i] + F(q + 2) * s.e[VS_S_SPEC + 2 * i + 1]);
    }
    fe = sum + fe;
  }
  if (VS_ON(VS_E_HOLD)) fe = -F(VS_HOLD) * s.y * s.y * s.y + fe;
  if (VS_ON(VS_E_SEAL)) {
    double r = s.v * F(VS_SEAL + 2);
    fe = (-tanh(s.v * F(VS_SEAL + 4)) * (F(VS_SEAL) + F(VS_SEAL + 1) * exp(-r * r)) -
          F(VS_SEAL + 3) * s.v) + fe;
  }
  return fe;
}

// sensor_chain.rs `derivs`: sensor c's low-pass and Padé delay driven by u.
VS_FN void vs_sensor_derivs(const double *P, long long n, long long l, int c, double u,
                            const VsState &s, VsState &d) {
  const long long q = VS_SENSOR + 7 * c;
  const int i = VS_S_SENSOR + 4 * c;
  d.e[i] = s.e[i + 1];
  d.e[i + 1] = F(q + 1) * (u - s.e[i]) - F(q + 2) * s.e[i + 1];
  d.e[i + 2] = s.e[i + 3];
  d.e[i + 3] = F(q + 5) * (s.e[i] - s.e[i + 2]) - F(q + 6) * s.e[i + 3];
}

// sensor_chain.rs `recorded`: channel c (0 accel, 1 disp, 2 force) as recorded, from u.
VS_FN double vs_sensed(const double *P, long long n, long long l, int c, double u,
                       const VsState &s) {
  if (!VS_ON(VS_E_ACCEL << c)) return u;
  const long long q = VS_SENSOR + 7 * c;
  const int i = VS_S_SENSOR + 4 * c;
  double y = s.e[i], yd = s.e[i + 1], t = F(q + 3);
  double pade = y - t * s.e[i + 3];
  double ydd = F(q + 1) * (u - y) - F(q + 2) * yd;
  double taylor = y - t * yd + 0.5 * t * t * ydd;
  double chain = taylor + F(q + 4) * (pade - taylor);
  return u + F(q) * (chain - u);
}

// building.rs `derivs`: the floors from the top down (each storey's shear is the floor above's
// load), the hysteretic force by the storey's law, the storey's work.
VS_FN void vs_building_derivs(const double *P, long long n, long long l, double accel,
                              const VsState &s, VsState &d) {
  double above = 0.0, law = F(VS_BLD);
  for (int i = 9; i >= 0; --i) {
    const long long q = VS_BLD + 6 + 4 * i;
    const int u = VS_S_BLD + 4 * i;
    double dr, dd, r = s.e[u + 2], inv_m = F(q), k = F(q + 1), fy = F(q + 3);
    vs_drift(s, i, dr, dd);
    double restoring = vs_restoring(P, n, l, i, dr, r);
    double shear = restoring + F(q + 2) * dd;
    double g;
    if (law == 2.0) {
      double z = r / fy;
      double sign = dd * z > 0.0 ? 1.0 : (dd * z < 0.0 ? -1.0 : 0.0);
      g = F(VS_BLD + 2) - pow(fabs(z), F(VS_BLD + 5)) * (F(VS_BLD + 3) + F(VS_BLD + 4) * sign);
    } else {
      double cap = law == 1.0 && inv_m != 0.0 ? fy : vs_inf();
      g = (r >= cap && dd > 0.0) || (r <= -cap && dd < 0.0) ? 0.0 : 1.0;
    }
    d.e[u] = s.e[u + 1];
    d.e[u + 1] = (above - shear) * inv_m - accel * (inv_m != 0.0 ? 1.0 : 0.0);
    d.e[u + 2] = k * dd * g;
    d.e[u + 3] = restoring * dd;
    above = shear;
  }
}

// The `derivs` of the effects with states, in registry order, given the plant's quantities:
// the held command, the supply flow, the actuator force, the acceleration and the stroke.
VS_FN void vs_effect_derivs(const double *P, long long n, long long l, double x_c, double qs,
                            double f, double accel, double stroke, const VsState &s,
                            VsState &d) {
  if (VS_ON(VS_E_DELAY)) {
    double input = x_c;
    for (int k = 0; k < 4; ++k) {
      d.e[VS_S_DELAY + k] = F(VS_DELAY + 1) * (input - s.e[VS_S_DELAY + k]);
      input = s.e[VS_S_DELAY + k];
    }
  }
  if (VS_ON(VS_E_SPOOL)) {
    double xd = vs_delayed(P, n, l, s, x_c);
    for (int act = 0; act < VS_NA; ++act) {
      const int i = VS_S_SPOOL + 2 * act;
      d.e[i] = s.e[i + 1];
      d.e[i + 1] = F(VS_SPOOL + 1) * (xd - s.e[i]) - F(VS_SPOOL + 2) * s.e[i + 1];
    }
  }
  if (VS_ON(VS_E_SUPPLY)) {
    double r = (F(VS_SUPPLY + 1) - s.e[VS_S_SUPPLY]) * F(VS_SUPPLY + 4);
    double q_p = F(VS_SUPPLY + 2) * (r < 0.0 ? 0.0 : (r > 1.0 ? 1.0 : r));
    d.e[VS_S_SUPPLY] = F(VS_SUPPLY) * (q_p - qs) * F(VS_SUPPLY + 3);
  }
  if (VS_ON(VS_E_RMASS)) {
    d.e[VS_S_RMASS] = s.e[VS_S_RMASS + 1];
    d.e[VS_S_RMASS + 1] = F(VS_RMASS) * (-f - F(VS_RMASS + 1) * s.e[VS_S_RMASS] -
                                         F(VS_RMASS + 2) * s.e[VS_S_RMASS + 1]);
  }
  if (VS_ON(VS_E_SPEC)) {
    for (int i = 0; i < 3; ++i) {
      const long long q = VS_SPEC + 3 * i;
      const int u = VS_S_SPEC + 2 * i;
      d.e[u] = s.e[u + 1];
      d.e[u + 1] = -F(q + 1) * s.e[u] - F(q + 2) * s.e[u + 1] - accel;
    }
  }
  const double input[3] = {accel, stroke, f};
  for (int c = 0; c < 3; ++c)
    if (VS_ON(VS_E_ACCEL << c)) vs_sensor_derivs(P, n, l, c, input[c], s, d);
  if (VS_ON(VS_E_BLD)) vs_building_derivs(P, n, l, accel, s, d);
}

// The actuator stroke (what the chambers and the LVDT follow): reaction_mass's `stroke`.
VS_FN void vs_stroke(const VsState &s, double &y, double &v) {
  y = s.y;
  v = s.v;
  if (VS_ON(VS_E_RMASS)) {
    y = s.y - s.e[VS_S_RMASS];
    v = s.v - s.e[VS_S_RMASS + 1];
  }
}

// The flows of one actuator's valves (servovalve.rs `Orifice` or `Linear`).
VS_FN void vs_valve(const double *P, long long n, long long l, bool linear, double x, double p1,
                    double p2, double ps, double &q1, double &q2) {
  if (linear) {
    q1 = F(VS_KQ1) * x;
    q2 = F(VS_KQ2) * x;
    return;
  }
  bool pos = x > 0.0;
  double dp1 = pos ? ps - p1 : p1 - F(VS_P_R);
  double k1 = pos ? F(VS_KW1) : F(VS_KW3);
  double dp2 = pos ? p2 - F(VS_P_R) : ps - p2;
  double k2 = pos ? F(VS_KW2) : F(VS_KW4);
  q1 = k1 * x * vs_sq(dp1, F(VS_P_TR2));
  q2 = k2 * x * vs_sq(dp2, F(VS_P_TR2));
}

// simulate.rs `rhs`: one actuator standing for two unless they differ (VS_E_TWO).
VS_FN void vs_rhs(const double *P, long long n, long long l, bool linear, double x_c,
                  const VsState &s, VsState &d) {
  double ps = F(VS_P_S);
  if (VS_ON(VS_E_SUPPLY)) ps = ps + F(VS_SUPPLY) * (s.e[VS_S_SUPPLY] - ps);
  double ys, vs;
  vs_stroke(s, ys, vs);
  double b1_0 = F(VS_BETA) / (F(VS_A1) * (F(VS_L) + ys) + F(VS_VD1));
  double b2_0 = F(VS_BETA) / (F(VS_A2) * (F(VS_L) - ys) + F(VS_VD2));
  double f = 0.0, qs = 0.0;
  for (int i = 0; i < VS_NA; ++i) {
    double x = vs_opening(P, n, l, i, s, x_c), q1, q2;
    vs_valve(P, n, l, linear, x, s.p1[i], s.p2[i], ps, q1, q2);
    qs += x > 0.0 ? q1 : -q2;
    vs_flows(P, n, l, i, s.p1[i], s.p2[i], q1, q2);
    double b1 = b1_0, b2 = b2_0;
    vs_stiffness(P, n, l, s.p1[i], s.p2[i], b1, b2);
    d.p1[i] = b1 * (q1 - F(VS_A1) * vs);
    d.p2[i] = b2 * (F(VS_A2) * vs - q2);
    f += s.p1[i] * F(VS_A1) - s.p2[i] * F(VS_A2);
  }
  if (VS_NA == 1) {
    f = f + f;
    qs = qs + qs;
  }
  double alpha = F(VS_ALPHA), va = fabs(s.v);
  double damp = alpha == 0.5 ? sqrt(va) : pow(va, alpha);
  double fe = vs_extra_force(P, n, l, s);
  d.v = (f + fe - F(VS_K) * s.y - (F(VS_C) * damp + F(VS_MU)) * s.z) * F(VS_INV_M);
  d.y = s.v;
  double zv = s.z * s.v;
  double bracket = zv > 0.0 ? 1.0 : (zv < 0.0 ? F(VS_KAPPA_NEG) : F(VS_KAPPA));
  d.z = s.v * F(VS_INV_Y) * (1.0 - s.z * s.z * bracket);
  vs_effect_derivs(P, n, l, x_c, qs, f, d.v, ys, s, d);
}

#undef F

VS_FN void vs_axpy(VsState &o, const VsState &b, double h, const VsState &k) {
  for (int i = 0; i < VS_NA; ++i) {
    o.p1[i] = b.p1[i] + h * k.p1[i];
    o.p2[i] = b.p2[i] + h * k.p2[i];
  }
  o.y = b.y + h * k.y;
  o.v = b.v + h * k.v;
  o.z = b.z + h * k.z;
  for (int i = 0; i < VS_NES; ++i)
    if (vs_live(i)) o.e[i] = b.e[i] + h * k.e[i];
}

VS_FN double vs_rk4(double s, double h6, double k1, double k2, double k3, double k4) {
  return s + h6 * (k1 + 2.0 * (k2 + k3) + k4);
}

// The RK4 combination of the four stages into s.
VS_FN void vs_combine(VsState &s, double h6, const VsState &k1, const VsState &k2,
                      const VsState &k3, const VsState &k4) {
  for (int i = 0; i < VS_NA; ++i) {
    s.p1[i] = vs_rk4(s.p1[i], h6, k1.p1[i], k2.p1[i], k3.p1[i], k4.p1[i]);
    s.p2[i] = vs_rk4(s.p2[i], h6, k1.p2[i], k2.p2[i], k3.p2[i], k4.p2[i]);
  }
  s.y = vs_rk4(s.y, h6, k1.y, k2.y, k3.y, k4.y);
  s.v = vs_rk4(s.v, h6, k1.v, k2.v, k3.v, k4.v);
  s.z = vs_rk4(s.z, h6, k1.z, k2.z, k3.z, k4.z);
  for (int i = 0; i < VS_NES; ++i)
    if (vs_live(i)) s.e[i] = vs_rk4(s.e[i], h6, k1.e[i], k2.e[i], k3.e[i], k4.e[i]);
}

// controller.rs `sum`: the force high-pass, then the gains.
// The controller's memory; `apc` and `ahc` the adaptive compensators' states (D, E per harmonic:
// effects/amplitude_phase.rs, effects/harmonic_cancellation.rs), `aic` the inverse's
// (effects/adaptive_inverse.rs: STATES), which change at the ticks only.
#define VS_TAPS 16
#define VS_AHEAD 16
struct VsCtrl {
  double f_prev, f_hp, notch[5][2], apc[4], ahc[16], aic[VS_TAPS * VS_TAPS + 5 * VS_TAPS + VS_AHEAD + 8];
};

VS_FN double vs_sum(const double *P, long long n, long long l, VsCtrl &m, double xr, double vr,
                    double ar, double jr, double x, double f) {
#define F(i) vs_p(P, n, l, (i))
  m.f_hp = F(VS_HP_B) * (f - m.f_prev) + F(VS_HP_A) * m.f_hp;
  m.f_prev = f;
  return F(VS_C_FB) * (xr - x) + F(VS_C_D) * xr + F(VS_C_V) * vr + F(VS_C_A) * ar +
         F(VS_C_J) * jr + F(VS_C_F) * m.f_hp;
#undef F
}

// controller.rs `shape`: five notches, the clamp.
VS_FN double vs_shape(const double *P, long long n, long long l, VsCtrl &m, double u) {
#define F(i) vs_p(P, n, l, (i))
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

// effects/valve_compensator.rs `command`: u divided by the orifice law's factor g (the mean
// √(Δp/Δp₀) of the ports u opens, over the actuators), g at least g_min.
VS_FN double vs_vcomp(const double *P, long long n, long long l, const VsState &s, double u) {
#define F(i) vs_p(P, n, l, (i))
  double ps = F(VS_VCOMP + 1), pr = F(VS_VCOMP + 2), g = 0.0;
  for (int i = 0; i < VS_NA; ++i) {
    double d1 = u >= 0.0 ? (ps - s.p1[i]) * F(VS_VCOMP + 3) : (s.p1[i] - pr) * F(VS_VCOMP + 5);
    double d2 = u >= 0.0 ? (s.p2[i] - pr) * F(VS_VCOMP + 4) : (ps - s.p2[i]) * F(VS_VCOMP + 6);
    g += sqrt(d1 > 0.0 ? d1 : 0.0) + sqrt(d2 > 0.0 ? d2 : 0.0);
  }
  g = g / (double)(2 * VS_NA);
  double g_min = F(VS_VCOMP + 7);
  g = g > g_min ? g : g_min;
  return u + F(VS_VCOMP) * (u / g - u);
#undef F
}

// effects/adaptive.rs `Phase::of`: the reference's phase from its states; false where they are
// not a sine's. ph = {ω, A, cos θ, sin θ}.
VS_FN bool vs_phase(const double r[4], double ph[4]) {
  double x = r[0], v = r[1], a = r[2], j = r[3];
  double w2 = (a * a - v * j) / (v * v - x * a);
  if (!(w2 > 0.0 && vs_finite(w2))) return false;
  double omega = sqrt(w2), wx = omega * x;
  double nn = sqrt(v * v + wx * wx);
  if (!(nn > 0.0)) return false;
  ph[0] = omega;
  ph[1] = nn / omega;
  ph[2] = v / nn;
  ph[3] = wx / nn;
  return true;
}

// effects/adaptive.rs `cancel`: one tick of harmonic k's canceller (settings at field `at`,
// states st = D_re, D_im, E_re, E_im); returns the command's correction.
VS_FN double vs_cancel(const double *P, long long n, long long l, int at, int k, const double ph[4],
                       double e, double t, double *st) {
#define F(i) vs_p(P, n, l, (i))
  double c = ph[2], s = ph[3];
  for (int i = 1; i < k; ++i) {
    double c2 = c * ph[2] - s * ph[3], s2 = s * ph[2] + c * ph[3];
    c = c2;
    s = s2;
  }
  double big = (double)k * ph[0], lambda = F(at + 2), freeze = F(at + 5);
  st[2] += lambda * (2.0 * e * c - st[2]);
  st[3] += lambda * (-2.0 * e * s - st[3]);
  if (!(freeze > 0.0 && t >= freeze)) {
    double phi = big * F(at + 3), mu = F(at + 1);
    double pc = cos(phi), ps = sin(phi);
    st[0] += mu * (pc * st[2] - ps * st[3]);
    st[1] += mu * (ps * st[2] + pc * st[3]);
    double cap = F(at + 4) * ph[1];
    double size = sqrt(st[0] * st[0] + st[1] * st[1]);
    if (size > cap) {
      st[0] *= cap / size;
      st[1] *= cap / size;
    }
  }
  double w2 = big * big;
  double f_re = (F(VS_C_FB) + F(VS_C_D)) - F(VS_C_A) * w2;
  double f_im = big * (F(VS_C_V) - F(VS_C_J) * w2);
  double z_re = f_re * st[0] - f_im * st[1], z_im = f_re * st[1] + f_im * st[0];
  return z_re * c - z_im * s;
#undef F
}

// effects/amplitude_phase.rs and harmonic_cancellation.rs `command`: the corrections at the
// fundamental, then at the 3rd, 5th, 7th and 9th harmonics.
VS_FN double vs_adaptive(const double *P, long long n, long long l, VsCtrl &m, const double r[4],
                         double x, double t, double u) {
  double ph[4];
  if (!vs_phase(r, ph)) return u;
  double e = r[0] - x;
  // An off lane passes the command untouched (amplitude_phase.rs, harmonic_cancellation.rs).
  if (VS_ON(VS_E_APC) && vs_p(P, n, l, VS_APC) != 0.0)
    u = u + vs_cancel(P, n, l, VS_APC, 1, ph, e, t, m.apc);
  if (VS_ON(VS_E_AHC) && vs_p(P, n, l, VS_AHC) != 0.0) {
    double sum = 0.0;
    for (int h = 0; h < 4; ++h) sum += vs_cancel(P, n, l, VS_AHC, 3 + 2 * h, ph, e, t, m.ahc + 4 * h);
    u = u + sum;
  }
  return u;
}

// effects/adaptive_inverse.rs `ahead`: component `i` of the reference's states read d ahead.
VS_FN double vs_ahead(const double r[4], double d, int i) {
  if (i == 0) return r[0] + d * (r[1] + 0.5 * d * (r[2] + d * r[3] / 3.0));
  if (i == 1) return r[1] + d * (r[2] + 0.5 * d * r[3]);
  if (i == 2) return r[2] + d * r[3];
  return r[3];
}

// effects/adaptive_inverse.rs `network`: one tick of a Laguerre network (st = input at n−1, then
// L1..L15 at n−1), its taps at n written to `taps`.
VS_FN void vs_network(double a, double s, double u, double *st, double *taps) {
  taps[0] = u;
  double old = st[0], nw = u;
  st[0] = u;
  for (int i = 1; i < VS_TAPS; ++i) {
    double before = st[i];
    st[i] = i == 1 ? a * before + s * old : a * before + old - a * nw;
    old = before;
    nw = st[i];
    taps[i] = st[i];
  }
}

// effects/adaptive_inverse.rs `weigh`: the two weighting high-passes (st = each stage's input and
// output at n−1).
VS_FN double vs_weigh(double alpha, double x, double *st) {
  if (alpha == 1.0) return x;
  for (int i = 0; i < 2; ++i) {
    st[2 * i + 1] = alpha * (st[2 * i + 1] + x - st[2 * i]);
    st[2 * i] = x;
    x = st[2 * i + 1];
  }
  return x;
}

// effects/adaptive_inverse.rs `rls`: one step of recursive least squares (P row-major).
VS_FN void vs_rls(double lambda, const double *psi, double y, double *w, double *p) {
  double pp[VS_TAPS], quad = 0.0, fit = 0.0;
  for (int i = 0; i < VS_TAPS; ++i) {
    double acc = 0.0;
    for (int j = 0; j < VS_TAPS; ++j) acc += p[i * VS_TAPS + j] * psi[j];
    pp[i] = acc;
  }
  for (int i = 0; i < VS_TAPS; ++i) quad += psi[i] * pp[i];
  for (int i = 0; i < VS_TAPS; ++i) fit += w[i] * psi[i];
  double den = lambda + quad, err = y - fit;
  for (int i = 0; i < VS_TAPS; ++i) {
    double k = pp[i] / den;
    w[i] += k * err;
    for (int j = 0; j < VS_TAPS; ++j) p[i * VS_TAPS + j] = (p[i * VS_TAPS + j] - k * pp[j]) / lambda;
  }
}

// effects/adaptive_inverse.rs `tick`: the fit's step, then the command given the reference through
// the inverse. States: w, P, the networks on x, on x̂_r and on F·r̂, the sent reference, the
// weightings', the taps in use (effects/adaptive_inverse.rs: W, P, NET_X, NET_R, NET_G, SENT,
// WEIGH_X, WEIGH_Y, WOUT).
VS_FN double vs_aic(const double *P, long long n, long long l, VsCtrl &m, const double r[4],
                    double x, double t, double u) {
#define F(i) vs_p(P, n, l, (i))
  if (F(VS_AIC) == 0.0) return u;
  double *w = m.aic, *p = w + VS_TAPS, *net_x = p + VS_TAPS * VS_TAPS, *net_r = net_x + VS_TAPS;
  double *net_g = net_r + VS_TAPS, *sent = net_g + VS_TAPS, *weigh_x = sent + VS_AHEAD;
  double *weigh_y = weigh_x + 4, *wout = weigh_y + 4;
  double a = F(VS_AIC + 2), sq = F(VS_AIC + 3), d = F(VS_AIC + 5), alpha = F(VS_AIC + 6);
  double psi[VS_TAPS], rho[VS_TAPS], phi[VS_TAPS];
  vs_network(a, sq, vs_weigh(alpha, x, weigh_x), net_x, psi);
  double y = vs_weigh(alpha, sent[(int)F(VS_AIC + 4) - 1], weigh_y);
  double freeze = F(VS_AIC + 7);
  if (!(freeze > 0.0 && t >= freeze)) vs_rls(F(VS_AIC + 1), psi, y, w, p);
  double beta = F(VS_AIC + 8);
  for (int i = 0; i < VS_TAPS; ++i) wout[i] += beta * (w[i] - wout[i]);
  double f0 = F(VS_C_FB) + F(VS_C_D), f1 = F(VS_C_V), f2 = F(VS_C_A), f3 = F(VS_C_J);
  double rh[4];
  for (int i = 0; i < 4; ++i) rh[i] = vs_ahead(r, d, i);
  vs_network(a, sq, rh[0], net_r, rho);
  vs_network(a, sq, f0 * rh[0] + f1 * rh[1] + f2 * rh[2] + f3 * rh[3], net_g, phi);
  double out = 0.0, c = 0.0;
  for (int i = 0; i < VS_TAPS; ++i) {
    out += wout[i] * rho[i];
    c += wout[i] * phi[i];
  }
  for (int i = VS_AHEAD - 1; i > 0; --i) sent[i] = sent[i - 1];
  sent[0] = out;
  return u + (c - (f0 * r[0] + f1 * r[1] + f2 * r[2] + f3 * r[3]));
#undef F
}

// simulate.rs `check_lane`: 0 alive, else the status code, with the value and the chamber
// (1, 2: actuator 1's cap and rod side; 3, 4: actuator 2's).
VS_FN int vs_guard(const double *P, long long n, long long l, const VsState &s, double &value,
                   double &chamber) {
  bool finite = vs_finite(s.y) && vs_finite(s.v) && vs_finite(s.z);
  for (int i = 0; i < VS_NA; ++i) finite = finite && vs_finite(s.p1[i]) && vs_finite(s.p2[i]);
  if (!finite) return 1;
  if (fabs(s.y) >= vs_p(P, n, l, VS_L)) {
    value = s.y;
    return 2;
  }
  double hi = 2.0 * vs_p(P, n, l, VS_P_S);
  for (int i = 0; i < VS_NA; ++i) {
    const double p[2] = {s.p1[i], s.p2[i]};
    for (int c = 0; c < 2; ++c) {
      if (!(p[c] >= -1.0e6 && p[c] <= hi)) {
        value = p[c];
        chamber = (double)(2 * i + c + 1);
        return 3;
      }
    }
  }
  return 0;
}

// metrics.rs `MetricsAcc`: the sums of one lane.
struct VsAcc {
  double n, max_u, err_a2, err_x2, peak_err_a, peak_err_x, peak[3], peak_r[3];
  double ar_re, ar_im, xr_re, xr_im, ar2, xr2, x_re, x_im, a_re[9], a_im[9];
  double osc_u[VS_MAX_OSC], osc_v[VS_MAX_OSC], osc_peak[VS_MAX_OSC], prev;
  double spec[4];
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
  for (int i = 0; i < 4; ++i) O(VS_SPECIMEN + i) = c.spec[i];
  for (long long i = 0; i < r.n_osc; ++i) O(VS_OSC_PEAK + i) = c.osc_peak[i];
#undef O
}

// The spool command held over tick k (simulate.rs `integrate`, the drive match), from the
// stroke x and the actuator force f the controller reads.
VS_FN double vs_command(const double *P, long long n, long long l, const VsRun &r, long long k,
                        VsCtrl &m, const VsState &s, double x, double f, double &u) {
  double k_sp = vs_p(P, n, l, VS_K_SP);
  if (r.drive == 0) {
    long long at = l * r.ref_stride + k;
    u = vs_sum(P, n, l, m, r.x[at], r.v[at], r.a[at], r.j[at], x, f);
    if (VS_ON(VS_E_VCOMP)) u = vs_vcomp(P, n, l, s, u);
    if (VS_ON(VS_E_APC) || VS_ON(VS_E_AHC)) {
      const double ref[4] = {r.x[at], r.v[at], r.a[at], r.j[at]};
      u = vs_adaptive(P, n, l, m, ref, x, (double)k / r.f_s, u);
    }
    if (VS_ON(VS_E_AIC)) {
      const double ref[4] = {r.x[at], r.v[at], r.a[at], r.j[at]};
      u = vs_aic(P, n, l, m, ref, x, (double)k / r.f_s, u);
    }
    u = vs_shape(P, n, l, m, u);
    return k_sp * u;
  }
  if (r.drive == 1) {
    double lim = vs_p(P, n, l, VS_U_LIM), c = r.drive_signal[k];
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
    if (sub > 0) vs_rhs(P, n, l, linear, x_c, s, k1);
    vs_axpy(t, s, 0.5 * h, k1);
    vs_rhs(P, n, l, linear, x_c, t, k2);
    vs_axpy(t, s, 0.5 * h, k2);
    vs_rhs(P, n, l, linear, x_c, t, k3);
    vs_axpy(t, s, h, k3);
    vs_rhs(P, n, l, linear, x_c, t, k4);
    vs_combine(s, h / 6.0, k1, k2, k3, k4);
  }
}

// The state at t = 0: the no-load pressures, the platen at rest, the supply's accumulator at
// P_S0, every other effect state 0.
VS_FN void vs_initial(const double *P, long long n, long long l, VsState &s) {
  for (int i = 0; i < 2; ++i) {
    s.p1[i] = vs_p(P, n, l, VS_P0_1);
    s.p2[i] = vs_p(P, n, l, VS_P0_2);
  }
  s.y = s.v = s.z = 0.0;
  for (int i = 0; i < VS_NES; ++i) s.e[i] = 0.0;
  if (VS_ON(VS_E_SUPPLY)) s.e[VS_S_SUPPLY] = vs_p(P, n, l, VS_SUPPLY + 1);
}

// The actuators' total force on the platen (simulate.rs `total_force`).
VS_FN double vs_force(const double *P, long long n, long long l, const VsState &s) {
  double a1 = vs_p(P, n, l, VS_A1), a2 = vs_p(P, n, l, VS_A2);
  double f0 = s.p1[0] * a1 - s.p2[0] * a2;
  return VS_NA == 1 ? f0 + f0 : f0 + (s.p1[1] * a1 - s.p2[1] * a2);
}

// The whole run of lane l: params P (n lanes), results to out (n lanes).
VS_FN void vs_lane(const VsRun &r, const double *P, double *out, long long n, long long l) {
  VsState s, k1;
  vs_initial(P, n, l, s);
  VsCtrl m = {};
  // effects/adaptive_inverse.rs `initial`: the taps learned and in use from the lane's record,
  // P = P0·I.
  if (VS_ON(VS_E_AIC)) {
    double *wout = m.aic + VS_TAPS * VS_TAPS + 4 * VS_TAPS + VS_AHEAD + 8;
    for (int i = 0; i < VS_TAPS; ++i) {
      m.aic[i] = wout[i] = vs_p(P, n, l, VS_AIC + 9 + i);
      m.aic[VS_TAPS + i * (VS_TAPS + 1)] = 1e6;
    }
  }
  VsAcc c = {};
  for (int i = 0; i < 4; ++i) c.spec[i] = vs_from_bits(0x7ff8000000000000ULL);  // NaN: no building
  m.f_prev = vs_force(P, n, l, s);
  double status = 0.0, fail_tick = 0.0, value = 0.0, chamber = 0.0;
  bool linear = r.linear_valve != 0;
  for (long long k = 0; k < r.ticks; ++k) {
    double x, v_s, f = vs_force(P, n, l, s), u = 0.0;
    vs_stroke(s, x, v_s);
    double x_c = vs_command(P, n, l, r, k, m, s, x, f, u);
    vs_rhs(P, n, l, linear, x_c, s, k1);
    c.max_u = fmax(c.max_u, fabs(u));
    if (VS_ON(VS_E_BLD)) vs_watch(P, n, l, s, c.spec);
    if (k >= r.w0 && k < r.w1) {
      // The metrics see the channels as recorded (the sensors' chains), the controller the plant's.
      double a_rec = vs_sensed(P, n, l, 0, k1.v, s), x_rec = vs_sensed(P, n, l, 1, x, s);
      vs_window(r, k, l * r.ref_stride + k, c, a_rec, s.v, x_rec);
    }
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
// Blocks of 128 lanes (gpu.rs: BLOCK), at least VS_MIN_BLOCKS of them resident per
// multiprocessor: the register budget per lane that ptxas keeps to (4: 128 registers).
#ifndef VS_MIN_BLOCKS
#define VS_MIN_BLOCKS 4
#endif
// The launch: the run's integers in the order of gpu_lanes.rs `Shared::ints`, then its arrays.
extern "C" __global__ void __launch_bounds__(128, VS_MIN_BLOCKS) vs_lanes(long long ticks, long long substeps, long long w0,
                                    long long w1, long long has_basis, long long drive,
                                    long long linear_valve, long long n_osc,
                                    long long ref_stride, long long effects, double f_s,
                                    const double *x, const double *v, const double *a,
                                    const double *j, const double *drive_signal,
                                    const double *basis, const double *osc, const double *__restrict__ P,
                                    double *out, long long n) {
  long long l = (long long)blockIdx.x * blockDim.x + threadIdx.x;
  VsRun r = {ticks, substeps, w0, w1, has_basis, drive, linear_valve, n_osc, ref_stride, effects, f_s,
             x, v, a, j, drive_signal, basis, osc};
  if (l < n) vs_lane(r, P, out, n, l);
}
#endif
