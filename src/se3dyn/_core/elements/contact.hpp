// Compliant contact between two shapes on two node frames (se3dyn.elements.contact): a
// half-space on frame a and a sphere on frame b (kind 0), or two spheres (kind 1).
//
// Geometry at the iterate: the normal n (from a into b), the penetration delta and the contact
// point p_c (the middle of the overlap). Velocity of b relative to a at p_c: w = w_b - w_a with
// w_i = R_i U_i + (R_i Omega_i) x (p_c - x_i); the approach rate delta' = -w . n, the slip
// w_t = w - (w . n) n.
//
// Normal law (Hertz with the exact-restitution dissipation of Carvalho & Martins 2019):
//   F_n = k delta^{3/2} max(0, 1 + c delta' / v_in)
// with c = c(e) the root of c - ln(1 + c) = -c e - ln(1 - c e) (se3dyn.elements.contact), which
// makes the rebound speed e v_in exactly for any k, mass and impact speed v_in. v_in is a state
// of the contact, set at touch-down from the approach rates at the step's start and end
// interpolated to the instant the gap closes, floored at the material's v_min.
//
// Friction: Coulomb with an elastic bristle s (a state, in frame a), the elastic slip of the
// contact. Per step (trapezoidal, as the PID integral of joint_force.hpp)
//   s_trial = P (s_n + h/2 (w_t,n + w_t)),  F_trial = -(mu F_n / s_len) (s_trial + tau w_t)
// stick if |F_trial| <= mu F_n (F_t = F_trial, s = s_trial), else slip at F_t = mu F_n
// F_trial / |F_trial| and s = -s_len F_trial / |F_trial| (a return map: no creep in stick).
//
// State of a contact, 9 numbers (State.ctrl after the PID states, written into its input
// slots with h/2 by Stepper::controller_inputs): s (3), w_t (3) in frame a, delta, delta',
// v_in (0: apart). The kernel writes those of the iterate to Context::ctrl.
//
// Residual: the force F = F_n n + F_t on b at p_c and -F on a, as tangent-space forces
// g = -+[R^T F; rho x R^T F], rho = R^T (p_c - x). Its exact linearisation in configuration
// (H -> H exp(dh), the SE(3) geometric stiffness included) and velocity is taken by forward
// automatic differentiation through the same code (24 directions: dh_a, dh_b, dv_a, dv_b).
#pragma once
#include <cmath>
#include <vector>

#include "context.hpp"

namespace se3dyn {
namespace contact_detail {

constexpr int ND = 24;  // derivative directions: dh_a (6), dh_b (6), dv_a (6), dv_b (6)
constexpr int CS = 9;   // state numbers per contact

// forward-mode number with ND derivatives
struct G {
  double v = 0.0;
  double d[ND] = {};
  G() = default;
  G(double x) : v(x) {}  // NOLINT: constants
};
inline G var(double x, int i) {
  G g(x);
  g.d[i] = 1.0;
  return g;
}
inline G operator+(const G& a, const G& b) {
  G r(a.v + b.v);
  for (int i = 0; i < ND; ++i) r.d[i] = a.d[i] + b.d[i];
  return r;
}
inline G operator-(const G& a, const G& b) {
  G r(a.v - b.v);
  for (int i = 0; i < ND; ++i) r.d[i] = a.d[i] - b.d[i];
  return r;
}
inline G operator-(const G& a) {
  G r(-a.v);
  for (int i = 0; i < ND; ++i) r.d[i] = -a.d[i];
  return r;
}
inline G operator*(const G& a, const G& b) {
  G r(a.v * b.v);
  for (int i = 0; i < ND; ++i) r.d[i] = a.d[i] * b.v + a.v * b.d[i];
  return r;
}
inline G operator*(double s, const G& a) {
  G r(s * a.v);
  for (int i = 0; i < ND; ++i) r.d[i] = s * a.d[i];
  return r;
}
inline G operator/(const G& a, const G& b) {
  G r(a.v / b.v);
  const double ib = 1.0 / b.v;
  for (int i = 0; i < ND; ++i) r.d[i] = (a.d[i] - r.v * b.d[i]) * ib;
  return r;
}
inline G gsqrt(const G& a) {
  G r(std::sqrt(a.v));
  const double s = r.v > 0 ? 0.5 / r.v : 0.0;
  for (int i = 0; i < ND; ++i) r.d[i] = s * a.d[i];
  return r;
}
inline G dot(const G* a, const G* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
inline void gcross(const G* a, const G* b, G* c) {
  c[0] = a[1] * b[2] - a[2] * b[1];
  c[1] = a[2] * b[0] - a[0] * b[2];
  c[2] = a[0] * b[1] - a[1] * b[0];
}
inline void mat_vec(const G* R, const G* x, G* y) {  // y = R x
  for (int i = 0; i < 3; ++i) y[i] = R[3 * i] * x[0] + R[3 * i + 1] * x[1] + R[3 * i + 2] * x[2];
}
inline void mat_tvec(const G* R, const G* x, G* y) {  // y = R^T x
  for (int i = 0; i < 3; ++i) y[i] = R[i] * x[0] + R[3 + i] * x[1] + R[6 + i] * x[2];
}

// A body of the pair: its frame perturbed as H exp(dh) to first order (R (I + hat dOmega),
// x + R dU) and its velocity (U, Omega) + dv, derivative directions from i0 (configuration)
// and i0 + 12 (velocity)
struct Body {
  G R[9], x[3], v[6];
  void set(const Frame& H, const double* vel, int i0) {
    G dU[3], dW[3];
    for (int i = 0; i < 3; ++i) {
      dU[i] = var(0.0, i0 + i);
      dW[i] = var(0.0, i0 + 3 + i);
    }
    for (int i = 0; i < 3; ++i) {  // R (I + hat(dW))
      const double* r = H.R + 3 * i;
      R[3 * i + 0] = G(r[0]) + r[1] * dW[2] - r[2] * dW[1];
      R[3 * i + 1] = G(r[1]) - r[0] * dW[2] + r[2] * dW[0];
      R[3 * i + 2] = G(r[2]) + r[0] * dW[1] - r[1] * dW[0];
      x[i] = G(H.x[i]) + r[0] * dU[0] + r[1] * dU[1] + r[2] * dU[2];
    }
    for (int i = 0; i < 6; ++i) v[i] = var(vel[i], i0 + 12 + i);
  }
  void point(const double* c, G* p) const {  // x + R c
    G cg[3] = {G(c[0]), G(c[1]), G(c[2])};
    mat_vec(R, cg, p);
    for (int i = 0; i < 3; ++i) p[i] = p[i] + x[i];
  }
  void velocity_at(const G* p, G* w) const {  // R U + (R Omega) x (p - x)
    G RU[3], RW[3], r[3], c[3];
    mat_vec(R, v, RU);
    mat_vec(R, v + 3, RW);
    for (int i = 0; i < 3; ++i) r[i] = p[i] - x[i];
    gcross(RW, r, c);
    for (int i = 0; i < 3; ++i) w[i] = RU[i] + c[i];
  }
  void wrench(const G* F, const G* p, double sign, G* g) const {  // sign [R^T F; rho x R^T F]
    G f[3], r[3], rho[3], m[3];
    mat_tvec(R, F, f);
    for (int i = 0; i < 3; ++i) r[i] = p[i] - x[i];
    mat_tvec(R, r, rho);
    gcross(rho, f, m);
    for (int i = 0; i < 3; ++i) {
      g[i] = sign * f[i];
      g[3 + i] = sign * m[i];
    }
  }
};

// The contact's geometry: normal n (a into b), penetration delta, contact point pc
inline void geometry(int kind, const Body& A, const Body& B, const double* ca, const double* cb,
                     const double* na, double ra, double rb, G* n, G& delta, G* pc) {
  G pb[3];
  B.point(cb, pb);
  if (kind == 0) {  // half-space of a (point ca, outward normal na) and sphere b
    G p0[3], nm[3] = {G(na[0]), G(na[1]), G(na[2])}, d[3];
    A.point(ca, p0);
    mat_vec(A.R, nm, n);
    for (int i = 0; i < 3; ++i) d[i] = pb[i] - p0[i];
    delta = G(rb) - dot(n, d);
  } else {  // spheres a and b
    G pa[3], d[3];
    A.point(ca, pa);
    for (int i = 0; i < 3; ++i) d[i] = pb[i] - pa[i];
    G L = gsqrt(dot(d, d));
    for (int i = 0; i < 3; ++i) n[i] = d[i] / L;
    delta = G(ra + rb) - L;
  }
  G arm = G(rb) - 0.5 * delta;
  for (int i = 0; i < 3; ++i) pc[i] = pb[i] - arm * n[i];
}

}  // namespace contact_detail

struct Contacts : ElementBatch {
  static constexpr int CS = contact_detail::CS;
  std::vector<int> fa, fb, kind;     // (n,) frames, 0 half-space-sphere, 1 sphere-sphere
  std::vector<double> ca, cb, na;    // (n, 3) material centres / plane point, plane normal
  std::vector<double> ra, rb;        // (n,) radii (ra: 0 for a half-space)
  std::vector<double> k, c, mu, slen, tau, vmin;  // (n,) the pair's material
  std::vector<int> slot;             // (n,) first input slot of the state (CS + 1: h/2)
  int ctrl0 = 0;                     // offset of the contact states in Context::ctrl
  std::vector<long> off_aa, off_ab, off_ba, off_bb;

  void load(const Tables& t) override {
    fa = t.ints<int>("fa");
    n = static_cast<int>(fa.size());
    fb = t.ints<int>("fb");
    kind = t.ints<int>("kind");
    ca = t.real("ca");
    cb = t.real("cb");
    na = t.real("na");
    ra = t.real("ra");
    rb = t.real("rb");
    k = t.real("k");
    c = t.real("c");
    mu = t.real("mu");
    slen = t.real("slen");
    tau = t.real("tau");
    vmin = t.real("vmin");
    slot = t.ints<int>("slot");
    std::vector<long> c0 = t.integer("ctrl0");
    ctrl0 = c0.empty() ? 0 : int(c0[0]);
    off_aa = t.integer("off_aa");
    off_ab = t.integer("off_ab");
    off_ba = t.integer("off_ba");
    off_bb = t.integer("off_bb");
  }

  void frames_of(int e, std::vector<int>& out) const override { out = {fa[e], fb[e]}; }

  void eval(Context& X, bool, Span span) const override {
    for (int e = span.first; e < span.last; ++e) one(X, e);
  }

 private:
  using G = contact_detail::G;

  // normal force and the touch-down speed v_in of the iterate
  G normal_force(int e, const G& delta, const G& rate, const double* st, G& vin) const {
    const double vin_n = st[8], pen_n = st[6], rate_n = st[7];
    if (vin_n > 0) {
      vin = G(vin_n);
    } else {  // touch-down in this step: the approach rate where the gap closed
      G th = pen_n < 0 ? G(-pen_n) / (delta - G(pen_n)) : G(0.0);
      vin = (G(1.0) - th) * G(rate_n) + th * rate;
      if (vin.v < vmin[e]) vin = G(vmin[e]);
    }
    G fac = G(1.0) + c[e] * (rate / vin);
    if (fac.v < 0) fac = G(0.0);
    return k[e] * (delta * gsqrt(delta)) * fac;
  }

  // friction force in frame a (3) and the new bristle state (values) from the slip wt (frame a)
  void friction(int e, const G& Fn, const G* nA, const G* wt, const double* st, double hh,
                bool fresh, G* Ft, double* s_out) const {
    G s[3];
    for (int i = 0; i < 3; ++i) s[i] = G(fresh ? 0.0 : st[i]) + hh * (G(st[3 + i]) + wt[i]);
    G sn = dot(s, nA);
    for (int i = 0; i < 3; ++i) s[i] = s[i] - sn * nA[i];
    G lim = mu[e] * Fn, kt = lim / G(slen[e]), Ftr[3];
    for (int i = 0; i < 3; ++i) Ftr[i] = -(kt * (s[i] + tau[e] * wt[i]));
    G mag = gsqrt(dot(Ftr, Ftr));
    bool stick = mag.v <= lim.v;
    for (int i = 0; i < 3; ++i) {
      Ft[i] = stick ? Ftr[i] : Ftr[i] * (lim / mag);
      s_out[i] = stick ? s[i].v : -slen[e] * Ftr[i].v / mag.v;
    }
  }

  void one(Context& X, int e) const {
    using namespace contact_detail;
    const FrameTables& T = *X.T;
    const FrameState& S = *X.S;
    const int fr[2] = {fa[e], fb[e]};
    Body A, B;
    A.set(S.H[fr[0]], &S.v[6 * fr[0]], 0);
    B.set(S.H[fr[1]], &S.v[6 * fr[1]], 6);
    G n[3], delta, pc[3], wa[3], wb[3], w[3];
    contact_detail::geometry(kind[e], A, B, &ca[3 * e], &cb[3 * e], &na[3 * e], ra[e], rb[e], n,
                             delta, pc);
    A.velocity_at(pc, wa);
    B.velocity_at(pc, wb);
    for (int i = 0; i < 3; ++i) w[i] = wb[i] - wa[i];
    G wn = dot(w, n), rate = -wn, wtw[3], wt[3], nA[3];
    for (int i = 0; i < 3; ++i) wtw[i] = w[i] - wn * n[i];
    mat_tvec(A.R, wtw, wt);
    mat_tvec(A.R, n, nA);
    const double* st = X.u + slot[e];
    const double hh = st[CS];
    double out[CS] = {0, 0, 0, wt[0].v, wt[1].v, wt[2].v, delta.v, rate.v, 0.0};
    if (delta.v > 0) {
      G vin, Ft[3] = {G(0.0), G(0.0), G(0.0)}, F[3], FtW[3], ga[6], gb[6];
      G Fn = normal_force(e, delta, rate, st, vin);
      out[8] = vin.v;
      if (mu[e] > 0 && Fn.v > 0) friction(e, Fn, nA, wt, st, hh, st[8] <= 0, Ft, out);
      mat_vec(A.R, Ft, FtW);
      for (int i = 0; i < 3; ++i) F[i] = Fn * n[i] + FtW[i];
      A.wrench(F, pc, 1.0, ga);
      B.wrench(F, pc, -1.0, gb);
      add(X, T, S, e, fr, ga, gb);
      if (X.energy) {
        const double el = k[e] * delta.v * std::sqrt(delta.v);
        X.energy[ELASTIC] += el * delta.v / 2.5;
        X.energy[P_DISSIPATION] += (Fn.v - el) * rate.v - dot(Ft, wt).v;
      }
    }
    if (X.ctrl)
      for (int i = 0; i < CS; ++i) X.ctrl[ctrl0 + CS * e + i] = out[i];
  }

  // residual rows and (with X.vals) the tangent blocks K = dg/dh, C = dg/dv of both frames
  void add(Context& X, const FrameTables& T, const FrameState& S, int e, const int* fr,
           const G* ga, const G* gb) const {
    const G* g[2] = {ga, gb};
    for (int s = 0; s < 2; ++s) {
      double val[6];
      for (int i = 0; i < 6; ++i) val[i] = g[s][i].v;
      frame_force(T, fr[s], val, 1.0, X.r);
      X.scale(val, 6);
    }
    if (!X.vals) return;
    const long offs[2][2] = {{off_aa[e], off_ab[e]}, {off_ba[e], off_bb[e]}};
    for (int s = 0; s < 2; ++s)
      for (int t = 0; t < 2; ++t) {
        double Kb[36], Cb[36];
        for (int i = 0; i < 6; ++i)
          for (int j = 0; j < 6; ++j) {
            Kb[6 * i + j] = g[s][i].d[6 * t + j];
            Cb[6 * i + j] = g[s][i].d[12 + 6 * t + j];
          }
        add_frame_block(T, S, X.vals, offs[s][t], fr[s], fr[t], Kb, X.cK, true);
        add_frame_block(T, S, X.vals, offs[s][t], fr[s], fr[t], Cb, X.cC, false);
        if (double* V = X.vel(offs[s][t]))
          add_frame_block(T, S, V, 0, fr[s], fr[t], Cb, X.cC, false);
      }
  }
};

}  // namespace se3dyn
