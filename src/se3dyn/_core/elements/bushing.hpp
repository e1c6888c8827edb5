// Bushing: 6 x 6 stiffness K and damping D on the relative motion of two frames attached to two
// nodes, H_a' = H_a X_a and H_b' = H_b X_b (X constant; the frames coincide initially unless the
// bushing is preloaded, H_b' = H_a' exp(d0) at t0).
//
// Relative motion d = log(G), G = H_a'^-1 H_b' (6,), translation first (Eq. (17) inverted).
// Variations and velocities of G (material, right-trivialised, Eqs. (2), (4)):
//   dg = P_b dh_b - A P_a dh_a,  w = P_b v_b - A P_a v_a,
// with P = Ad(X^-1) (Eq. (57)) and A = Ad(G^-1); the log coordinates then vary by
// dd = T(d)^-1 dg and move at d_dot = T(d)^-1 w (Eqs. (26)-(27); T of Eqs. (21)-(22)).
// Elastic energy V = d^T K d / 2, Rayleigh dissipation d_dot^T D d_dot / 2 (K, D symmetric):
// the generalised forces are r = Jg^T f with
//   f = T(d)^-T (K d + D d_dot),  Jg = [-A P_a, P_b] (6 x 12 over (dh_a, dh_b)),
// so that their power is dV/dt + d_dot^T D d_dot (energy-consistent), and everything depends on
// G only (objective: invariant under a superposed rigid motion).
//
// Exact linearisation (configuration dh and velocity dv), with dA x = ad(A x) dg and
// d(A^T f) = -A^T Lambda(f) dg (ad(e)^T f = Lambda(f) e):
//   dd       = T^-1 Jg dh                                   (Jd = T^-1 Jg)
//   dw       = -ad(y_a) Jg dh + Jg dv,   y_a = A P_a v_a
//   dd_dot   = N_w Jd dh + T^-1 dw,      N_w = d(T(d)^-1 w)/dd
//   df       = M_p Jd dh + T^-T (K dd + D dd_dot),  M_p = d(T(d)^-T p)/dd at p = K d + D d_dot
//   K_T      = Jg^T (df/dh) + [P_a^T A^T Lambda(f) Jg; 0],   C_T = Jd^T D Jd.
// The derivatives N_w, M_p of the inverse tangent operator are computed exactly by forward
// automatic differentiation (dual numbers) through the closed form of T^-1 (Eq. (21) inverted
// blockwise, as tangent_se3_inv), with the Taylor series of lie.hpp below the cut-off.
// log is the principal branch: the relative rotation angle must stay below pi.
#pragma once
#include <cmath>
#include <vector>

#include "context.hpp"

namespace se3dyn {
namespace bushing_detail {

// forward-mode dual number x + dx eps (eps^2 = 0)
struct Dual {
  double v = 0.0, d = 0.0;
  Dual() = default;
  Dual(double x, double dx = 0.0) : v(x), d(dx) {}
};
inline Dual operator+(Dual a, Dual b) { return {a.v + b.v, a.d + b.d}; }
inline Dual operator-(Dual a, Dual b) { return {a.v - b.v, a.d - b.d}; }
inline Dual operator-(Dual a) { return {-a.v, -a.d}; }
inline Dual operator*(Dual a, Dual b) { return {a.v * b.v, a.d * b.v + a.v * b.d}; }
inline Dual operator/(Dual a, Dual b) {
  return {a.v / b.v, (a.d * b.v - a.v * b.d) / (b.v * b.v)};
}
inline Dual dsin(Dual a) { return {std::sin(a.v), std::cos(a.v) * a.d}; }
inline Dual dcos(Dual a) { return {std::cos(a.v), -std::sin(a.v) * a.d}; }
inline Dual dsqrt(Dual a) {
  double s = std::sqrt(a.v);
  return {s, 0.5 * a.d / s};
}
inline Dual dseries(const double* C, Dual t2) {
  Dual s(0.0), p(1.0);
  for (int j = 0; j < SERIES_TERMS; ++j) {
    s = s + C[j] * p;
    p = p * t2;
  }
  return s;
}

// T_SE(3)(n)^-1 (6 x 6, row-major) on dual numbers: the formula of tangent_se3_inv,
// [[Ti, -Ti C Ti], [0, Ti]] with Ti = I + W/2 + f W^2 and C the block T_UOmega+ of Eq. (22)
inline void tangent_se3_inv_dual(const Dual* n, Dual* out) {
  const Series& S = series();
  const Dual* u = n;
  const Dual* w = n + 3;
  Dual t2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
  Dual h, c, d, e, f;
  if (t2.v < S.cut * S.cut) {
    c = dseries(S.c, t2);
    d = dseries(S.d, t2);
    e = dseries(S.e, t2);
    f = dseries(S.f, t2);
    Dual a = Dual(1.0) - c * t2;         // sin t / t
    h = Dual(0.5) * (a + d * t2);        // (1 - cos t) / t^2, from d = (2 h - a) / t^2
  } else {
    Dual t = dsqrt(t2);
    Dual a = dsin(t) / t;
    Dual half = Dual(0.5) * t;
    Dual sh = dsin(half) / half;
    h = Dual(0.5) * sh * sh;
    c = (Dual(1.0) - a) / t2;
    d = (Dual(2.0) * h - a) / t2;
    e = (h - Dual(3.0) * c) / t2;
    f = (Dual(1.0) - half * dcos(half) / dsin(half)) / t2;
  }
  auto hat = [](const Dual* x, Dual* X) {
    X[0] = Dual(0.0); X[1] = -x[2]; X[2] = x[1];
    X[3] = x[2]; X[4] = Dual(0.0); X[5] = -x[0];
    X[6] = -x[1]; X[7] = x[0]; X[8] = Dual(0.0);
  };
  auto mul = [](const Dual* A, const Dual* B, Dual* C3) {
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        C3[3 * i + j] = A[3 * i] * B[j] + A[3 * i + 1] * B[3 + j] + A[3 * i + 2] * B[6 + j];
  };
  Dual W[9], W2[9], U[9], UW[9], WU[9], Ti[9], C[9], t1[9], B[9];
  hat(w, W);
  hat(u, U);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) W2[3 * i + j] = w[i] * w[j] - (i == j ? t2 : Dual(0.0));
  mul(U, W, UW);
  mul(W, U, WU);
  Dual wu = w[0] * u[0] + w[1] * u[1] + w[2] * u[2];
  for (int q = 0; q < 9; ++q) {
    Ti[q] = Dual(q % 4 == 0 ? 1.0 : 0.0) + Dual(0.5) * W[q] + f * W2[q];
    C[q] = -(h * U[q]) + c * (UW[q] + WU[q]) + wu * (d * W[q] + e * W2[q]);
  }
  mul(Ti, C, t1);
  mul(t1, Ti, B);
  for (int i = 0; i < 36; ++i) out[i] = Dual(0.0);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      out[6 * i + j] = Ti[3 * i + j];
      out[6 * (3 + i) + 3 + j] = Ti[3 * i + j];
      out[6 * i + 3 + j] = -B[3 * i + j];
    }
}

}  // namespace bushing_detail

struct Bushings : ElementBatch {
  std::vector<int> fa, fb;              // (n,) node frames
  std::vector<Frame> Xa, Xb;            // (n,) attachment frames in the node frames
  std::vector<double> PA, PB;           // (n, 6, 6) Ad(X_a^-1), Ad(X_b^-1)
  std::vector<double> K, D;             // (n, 6, 6) symmetric stiffness and damping
  std::vector<long> off_aa, off_ab, off_ba, off_bb;

  void load(const Tables& t) override {
    fa = t.ints<int>("fa");
    n = static_cast<int>(fa.size());
    fb = t.ints<int>("fb");
    Xa = t.frames("Xa");
    Xb = t.frames("Xb");
    PA = t.real("PA");
    PB = t.real("PB");
    K = t.real("K");
    D = t.real("D");
    off_aa = t.integer("off_aa");
    off_ab = t.integer("off_ab");
    off_ba = t.integer("off_ba");
    off_bb = t.integer("off_bb");
  }

  void frames_of(int e, std::vector<int>& out) const override { out = {fa[e], fb[e]}; }

  void eval(Context& X, bool, Span span) const override {
    using bushing_detail::Dual;
    const FrameTables& T = *X.T;
    const FrameState& S = *X.S;
    for (int e = span.first; e < span.last; ++e) {
      const double* Pa = &PA[36 * e];
      const double* Pb = &PB[36 * e];
      const double* Ke = &K[36 * e];
      const double* De = &D[36 * e];
      int fr[2] = {fa[e], fb[e]};
      Frame A1, B1, G;
      compose(S.H[fa[e]], Xa[e], A1);
      compose(S.H[fb[e]], Xb[e], B1);
      compose_inv(A1, B1, G);
      double d[6], Ti[36], Ag[36];
      log_se3(G, d);
      tangent_se3_inv(d, Ti);
      adjoint_inv(G, Ag);  // A = Ad(G^-1)
      double va[6], ya[6], vb[6], w[6], dd[6], p[6], f[6];
      mv<6, 6>(Pa, &S.v[6 * fa[e]], va);
      mv<6, 6>(Ag, va, ya);
      mv<6, 6>(Pb, &S.v[6 * fb[e]], vb);
      for (int i = 0; i < 6; ++i) w[i] = vb[i] - ya[i];
      mv<6, 6>(Ti, w, dd);  // d_dot
      double Kd[6], Ddd[6];
      mv<6, 6>(Ke, d, Kd);
      mv<6, 6>(De, dd, Ddd);
      for (int i = 0; i < 6; ++i) p[i] = Kd[i] + Ddd[i];
      mTv<6, 6>(Ti, p, f);  // f = T^-T p
      double Af[6], g[2][6];
      mTv<6, 6>(Ag, f, Af);
      mTv<6, 6>(Pa, Af, g[0]);
      for (int i = 0; i < 6; ++i) g[0][i] = -g[0][i];
      mTv<6, 6>(Pb, f, g[1]);
      for (int s = 0; s < 2; ++s) {
        frame_force(T, fr[s], g[s], 1.0, X.r);
        X.scale(g[s], 6);
      }
      if (X.energy) {
        X.energy[ELASTIC] += 0.5 * dot6(d, Kd);
        X.energy[P_DISSIPATION] += dot6(dd, Ddd);
      }
      if (!X.vals) continue;
      // Jg (6 x 12) = [-A P_a, P_b], Jd = T^-1 Jg
      double APa[36], Jg[72], Jd[72];
      mm<6, 6, 6>(Ag, Pa, APa);
      for (int i = 0; i < 6; ++i)
        for (int j = 0; j < 6; ++j) {
          Jg[12 * i + j] = -APa[6 * i + j];
          Jg[12 * i + 6 + j] = Pb[6 * i + j];
        }
      mm<6, 6, 12>(Ti, Jg, Jd);
      // N_w = d(T^-1 w)/dd and M_p = d(T^-T p)/dd, column by column (dual numbers)
      double Nw[36], Mp[36];
      for (int c = 0; c < 6; ++c) {
        Dual nd[6], Td[36];
        for (int i = 0; i < 6; ++i) nd[i] = Dual(d[i], i == c ? 1.0 : 0.0);
        bushing_detail::tangent_se3_inv_dual(nd, Td);
        for (int i = 0; i < 6; ++i) {
          double sn = 0.0, sm = 0.0;
          for (int j = 0; j < 6; ++j) {
            sn += Td[6 * i + j].d * w[j];
            sm += Td[6 * j + i].d * p[j];
          }
          Nw[6 * i + c] = sn;
          Mp[6 * i + c] = sm;
        }
      }
      // d(d_dot)/dh = N_w Jd - T^-1 ad(y_a) Jg
      double adY[36], adJ[72], Tad[72], NJ[72], ddd[72];
      ad6(ya, adY);
      mm<6, 6, 12>(adY, Jg, adJ);
      mm<6, 6, 12>(Ti, adJ, Tad);
      mm<6, 6, 12>(Nw, Jd, NJ);
      for (int i = 0; i < 72; ++i) ddd[i] = NJ[i] - Tad[i];
      // dp/dh = K Jd + D d(d_dot)/dh ; df/dh = M_p Jd + T^-T dp/dh
      double KJ[72], DJ[72], dp[72], MJ[72], Tdp[72], df[72];
      mm<6, 6, 12>(Ke, Jd, KJ);
      mm<6, 6, 12>(De, ddd, DJ);
      for (int i = 0; i < 72; ++i) dp[i] = KJ[i] + DJ[i];
      mm<6, 6, 12>(Mp, Jd, MJ);
      mTm<6, 6, 12>(Ti, dp, Tdp);
      for (int i = 0; i < 72; ++i) df[i] = MJ[i] + Tdp[i];
      // K_T = Jg^T df + [P_a^T A^T Lambda(f) Jg; 0] ; C_T = Jd^T D Jd
      double KT[144], CT[144], Lf[36], LJ[72], ALJ[72], PALJ[72], DJd[72];
      mTm<12, 6, 12>(Jg, df, KT);
      lam_matrix(f, Lf);
      mm<6, 6, 12>(Lf, Jg, LJ);
      mTm<6, 6, 12>(Ag, LJ, ALJ);
      mTm<6, 6, 12>(Pa, ALJ, PALJ);
      for (int i = 0; i < 72; ++i) KT[i] += PALJ[i];
      mm<6, 6, 12>(De, Jd, DJd);
      mTm<12, 6, 12>(Jd, DJd, CT);
      for (int s = 0; s < 2; ++s) {
        long offs[2] = {s ? off_ba[e] : off_aa[e], s ? off_bb[e] : off_ab[e]};
        for (int t = 0; t < 2; ++t) {
          double Kb[36], Cb[36];
          for (int i = 0; i < 6; ++i)
            for (int j = 0; j < 6; ++j) {
              Kb[6 * i + j] = KT[12 * (6 * s + i) + 6 * t + j];
              Cb[6 * i + j] = CT[12 * (6 * s + i) + 6 * t + j];
            }
          add_frame_block(T, S, X.vals, offs[t], fr[s], fr[t], Kb, X.cK, true);
          add_frame_block(T, S, X.vals, offs[t], fr[s], fr[t], Cb, X.cC, false);
          if (double* V = X.vel(offs[t]))
            add_frame_block(T, S, V, 0, fr[s], fr[t], Cb, X.cC, false);
        }
      }
    }
  }

  static double dot6(const double* a, const double* b) {
    double s = 0.0;
    for (int i = 0; i < 6; ++i) s += a[i] * b[i];
    return s;
  }
};

}  // namespace se3dyn
