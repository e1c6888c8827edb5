// Compliant contact between two shapes on two node frames (se3dyn.elements.contact): a
// half-space on frame a and a sphere on frame b (kind 0), two spheres (kind 1), or a capsule
// on frame a (a segment from ca along na of length la, radius ra) and a sphere (kind 2: the
// sphere of the segment's point closest to b's centre).
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
// v_in (0: apart); then 10 outputs (the normal force, the force on b, the contact point and
// the normal, inertial frame). The kernel writes those of the iterate to Context::ctrl.
//
// Residual: the force F = F_n n + F_t on b at p_c and -F on a, as tangent-space forces
// g = -+[R^T F; rho x R^T F], rho = R^T (p_c - x). Its exact linearisation in configuration
// (H -> H exp(dh), the SE(3) geometric stiffness included) and velocity is taken by forward
// automatic differentiation through the same code (24 directions: dh_a, dh_b, dv_a, dv_b; 12
// when one of the frames has no unknowns); residual-only evaluations run on plain doubles.
#pragma once
#include <cmath>
#include <type_traits>
#include <vector>

#include "context.hpp"

namespace se3dyn {
namespace contact_detail {

// numbers per contact in Context::ctrl: the state (9) and the outputs of the iterate (10,
// Results.contact_*): normal force, force on b (3, inertial), contact point (3), normal (3)
constexpr int CS = 19;

// forward-mode number with N derivatives
template <int N>
struct G {
  double v;
  double d[N];
  G() : v(0.0) { for (int i = 0; i < N; ++i) d[i] = 0.0; }
  G(double x) : v(x) { for (int i = 0; i < N; ++i) d[i] = 0.0; }  // NOLINT: constants
};
template <int N>
inline G<N> operator+(const G<N>& a, const G<N>& b) {
  G<N> r(a.v + b.v);
  for (int i = 0; i < N; ++i) r.d[i] = a.d[i] + b.d[i];
  return r;
}
template <int N>
inline G<N> operator-(const G<N>& a, const G<N>& b) {
  G<N> r(a.v - b.v);
  for (int i = 0; i < N; ++i) r.d[i] = a.d[i] - b.d[i];
  return r;
}
template <int N>
inline G<N> operator-(const G<N>& a) {
  G<N> r(-a.v);
  for (int i = 0; i < N; ++i) r.d[i] = -a.d[i];
  return r;
}
template <int N>
inline G<N> operator*(const G<N>& a, const G<N>& b) {
  G<N> r(a.v * b.v);
  for (int i = 0; i < N; ++i) r.d[i] = a.d[i] * b.v + a.v * b.d[i];
  return r;
}
template <int N>
inline G<N> operator*(double s, const G<N>& a) {
  G<N> r(s * a.v);
  for (int i = 0; i < N; ++i) r.d[i] = s * a.d[i];
  return r;
}
template <int N>
inline G<N> operator/(const G<N>& a, const G<N>& b) {
  G<N> r(a.v / b.v);
  const double ib = 1.0 / b.v;
  for (int i = 0; i < N; ++i) r.d[i] = (a.d[i] - r.v * b.d[i]) * ib;
  return r;
}
template <int N>
inline G<N> gsqrt(const G<N>& a) {
  G<N> r(std::sqrt(a.v));
  const double s = r.v > 0 ? 0.5 / r.v : 0.0;
  for (int i = 0; i < N; ++i) r.d[i] = s * a.d[i];
  return r;
}
inline double gsqrt(double a) { return std::sqrt(a); }
inline double val(double x) { return x; }
template <int N>
inline double val(const G<N>& x) { return x.v; }
// x as a variable of direction i (i < 0: a constant)
template <class T>
inline T var(double x, int i) {
  T g(x);
  if constexpr (!std::is_same_v<T, double>) {
    if (i >= 0) g.d[i] = 1.0;
  } else {
    (void)i;
  }
  return g;
}

template <class T>
inline T dot(const T* a, const T* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
template <class T>
inline void gcross(const T* a, const T* b, T* c) {
  c[0] = a[1] * b[2] - a[2] * b[1];
  c[1] = a[2] * b[0] - a[0] * b[2];
  c[2] = a[0] * b[1] - a[1] * b[0];
}
template <class T>
inline void mat_vec(const T* R, const T* x, T* y) {  // y = R x
  for (int i = 0; i < 3; ++i) y[i] = R[3 * i] * x[0] + R[3 * i + 1] * x[1] + R[3 * i + 2] * x[2];
}
template <class T>
inline void mat_tvec(const T* R, const T* x, T* y) {  // y = R^T x
  for (int i = 0; i < 3; ++i) y[i] = R[i] * x[0] + R[3 + i] * x[1] + R[6 + i] * x[2];
}

// A body of the pair: its frame perturbed as H exp(dh) to first order (R (I + hat dOmega),
// x + R dU) and its velocity (U, Omega) + dv, derivative directions from ih (configuration)
// and iv (velocity), -1: none
template <class T>
struct Body {
  T R[9], x[3], v[6];
  void set(const Frame& H, const double* vel, int ih, int iv) {
    T dU[3], dW[3];
    for (int i = 0; i < 3; ++i) {
      dU[i] = var<T>(0.0, ih < 0 ? -1 : ih + i);
      dW[i] = var<T>(0.0, ih < 0 ? -1 : ih + 3 + i);
    }
    for (int i = 0; i < 3; ++i) {  // R (I + hat(dW))
      const double* r = H.R + 3 * i;
      R[3 * i + 0] = T(r[0]) + r[1] * dW[2] - r[2] * dW[1];
      R[3 * i + 1] = T(r[1]) - r[0] * dW[2] + r[2] * dW[0];
      R[3 * i + 2] = T(r[2]) + r[0] * dW[1] - r[1] * dW[0];
      x[i] = T(H.x[i]) + r[0] * dU[0] + r[1] * dU[1] + r[2] * dU[2];
    }
    for (int i = 0; i < 6; ++i) v[i] = var<T>(vel[i], iv < 0 ? -1 : iv + i);
  }
  void point(const double* c, T* p) const {  // x + R c
    T cg[3] = {T(c[0]), T(c[1]), T(c[2])};
    mat_vec(R, cg, p);
    for (int i = 0; i < 3; ++i) p[i] = p[i] + x[i];
  }
  void velocity_at(const T* p, T* w) const {  // R U + (R Omega) x (p - x)
    T RU[3], RW[3], r[3], c[3];
    mat_vec(R, v, RU);
    mat_vec(R, v + 3, RW);
    for (int i = 0; i < 3; ++i) r[i] = p[i] - x[i];
    gcross(RW, r, c);
    for (int i = 0; i < 3; ++i) w[i] = RU[i] + c[i];
  }
  void wrench(const T* F, const T* p, double sign, T* g) const {  // sign [R^T F; rho x R^T F]
    T f[3], r[3], rho[3], m[3];
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
template <class T>
inline void geometry(int kind, const Body<T>& A, const Body<T>& B, const double* ca,
                     const double* cb, const double* na, double la, double ra, double rb, T* n,
                     T& delta, T* pc) {
  T pb[3];
  B.point(cb, pb);
  if (kind == 0) {  // half-space of a (point ca, outward normal na) and sphere b
    T p0[3], nm[3] = {T(na[0]), T(na[1]), T(na[2])}, d[3];
    A.point(ca, p0);
    mat_vec(A.R, nm, n);
    for (int i = 0; i < 3; ++i) d[i] = pb[i] - p0[i];
    delta = T(rb) - dot(n, d);
  } else {  // spheres a and b; a capsule a: the sphere of its segment's point closest to b
    T pa[3], d[3];
    A.point(ca, pa);
    if (kind == 2) {
      T u[3], nm[3] = {T(na[0]), T(na[1]), T(na[2])}, r[3];
      mat_vec(A.R, nm, u);
      for (int i = 0; i < 3; ++i) r[i] = pb[i] - pa[i];
      T s = dot(r, u);
      if (val(s) < 0) s = T(0.0);
      if (val(s) > la) s = T(la);
      for (int i = 0; i < 3; ++i) pa[i] = pa[i] + s * u[i];
    }
    for (int i = 0; i < 3; ++i) d[i] = pb[i] - pa[i];
    T L = gsqrt(dot(d, d));
    for (int i = 0; i < 3; ++i) n[i] = d[i] / L;
    delta = T(ra + rb) - L;
  }
  T arm = T(rb) - 0.5 * delta;
  for (int i = 0; i < 3; ++i) pc[i] = pb[i] - arm * n[i];
}

}  // namespace contact_detail

struct Contacts : ElementBatch {
  static constexpr int CS = contact_detail::CS;
  std::vector<int> fa, fb, kind;     // (n,) frames, 0 half-space-sphere, 1 sphere-sphere
  std::vector<double> ca, cb, na;    // (n, 3) material centres / plane point, plane normal
  std::vector<double> ra, rb;        // (n,) radii (ra: 0 for a half-space)
  std::vector<double> la;            // (n,) a capsule's segment length (0 otherwise)
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
    la = t.real("la");
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
    using contact_detail::G;
    const FrameTables& T = *X.T;
    for (int e = span.first; e < span.last; ++e) {
      if (!X.vals) {
        one<double>(X, e, -1, -1);
      } else if (T.k[fa[e]] == 0 || T.k[fb[e]] == 0) {  // one frame moves: 12 directions
        one<G<12>>(X, e, T.k[fa[e]] == 0 ? -1 : 0, T.k[fb[e]] == 0 ? -1 : 0);
      } else {
        one<G<24>>(X, e, 0, 6);
      }
    }
  }

 private:
  // normal force and the touch-down speed v_in of the iterate
  template <class S>
  S normal_force(int e, const S& delta, const S& rate, const double* st, S& vin) const {
    using contact_detail::gsqrt;
    const double vin_n = st[8], pen_n = st[6], rate_n = st[7];
    if (vin_n > 0) {
      vin = S(vin_n);
    } else {  // touch-down in this step: the approach rate where the gap closed
      S th = pen_n < 0 ? S(-pen_n) / (delta - S(pen_n)) : S(0.0);
      vin = (S(1.0) - th) * S(rate_n) + th * rate;
      if (contact_detail::val(vin) < vmin[e]) vin = S(vmin[e]);
    }
    S fac = S(1.0) + c[e] * (rate / vin);
    if (contact_detail::val(fac) < 0) fac = S(0.0);
    return k[e] * (delta * gsqrt(delta)) * fac;
  }

  // friction force in frame a (3) and the new bristle state (values) from the slip wt (frame a)
  template <class S>
  void friction(int e, const S& Fn, const S* nA, const S* wt, const double* st, double hh,
                bool fresh, S* Ft, double* s_out) const {
    using contact_detail::dot;
    using contact_detail::gsqrt;
    using contact_detail::val;
    S s[3];
    for (int i = 0; i < 3; ++i) s[i] = S(fresh ? 0.0 : st[i]) + hh * (S(st[3 + i]) + wt[i]);
    S sn = dot(s, nA);
    for (int i = 0; i < 3; ++i) s[i] = s[i] - sn * nA[i];
    S lim = mu[e] * Fn, kt = lim / S(slen[e]), Ftr[3];
    for (int i = 0; i < 3; ++i) Ftr[i] = -(kt * (s[i] + tau[e] * wt[i]));
    S mag = gsqrt(dot(Ftr, Ftr));
    bool stick = val(mag) <= val(lim);
    for (int i = 0; i < 3; ++i) {
      Ft[i] = stick ? Ftr[i] : Ftr[i] * (lim / mag);
      s_out[i] = stick ? val(s[i]) : -slen[e] * val(Ftr[i]) / val(mag);
    }
  }

  // element e with scalars S (double: the residual only; G<N>: with the tangent blocks, the
  // configuration and velocity directions of frame a from ia, of frame b from ib, -1: none)
  template <class S>
  void one(Context& X, int e, int ia, int ib) const {
    using namespace contact_detail;
    constexpr int N = std::is_same_v<S, double> ? 0 : (std::is_same_v<S, G<12>> ? 12 : 24);
    constexpr int NV = N / 2;  // velocity directions follow the configuration ones
    const FrameTables& T = *X.T;
    const FrameState& St = *X.S;
    const int fr[2] = {fa[e], fb[e]};
    Body<S> A, B;
    A.set(St.H[fr[0]], &St.v[6 * fr[0]], ia, ia < 0 ? -1 : ia + NV);
    B.set(St.H[fr[1]], &St.v[6 * fr[1]], ib, ib < 0 ? -1 : ib + NV);
    S n[3], delta, pc[3], wa[3], wb[3], w[3];
    geometry(kind[e], A, B, &ca[3 * e], &cb[3 * e], &na[3 * e], la[e], ra[e], rb[e], n, delta,
             pc);
    A.velocity_at(pc, wa);
    B.velocity_at(pc, wb);
    for (int i = 0; i < 3; ++i) w[i] = wb[i] - wa[i];
    S wn = dot(w, n), rate = -wn, wtw[3], wt[3], nA[3];
    for (int i = 0; i < 3; ++i) wtw[i] = w[i] - wn * n[i];
    mat_tvec(A.R, wtw, wt);
    mat_tvec(A.R, n, nA);
    const double* st = X.u + slot[e];
    const double hh = st[CS];
    double out[CS] = {0, 0, 0, val(wt[0]), val(wt[1]), val(wt[2]), val(delta), val(rate), 0.0,
                      0.0, 0.0, 0.0, 0.0};
    for (int i = 0; i < 3; ++i) {
      out[13 + i] = val(pc[i]);
      out[16 + i] = val(n[i]);
    }
    if (val(delta) > 0) {
      S vin, Ft[3] = {S(0.0), S(0.0), S(0.0)}, F[3], FtW[3], g[2][6];
      S Fn = normal_force(e, delta, rate, st, vin);
      out[8] = val(vin);
      if (mu[e] > 0 && val(Fn) > 0) friction(e, Fn, nA, wt, st, hh, st[8] <= 0, Ft, out);
      mat_vec(A.R, Ft, FtW);
      for (int i = 0; i < 3; ++i) F[i] = Fn * n[i] + FtW[i];
      out[9] = val(Fn);
      for (int i = 0; i < 3; ++i) out[10 + i] = val(F[i]);
      A.wrench(F, pc, 1.0, g[0]);
      B.wrench(F, pc, -1.0, g[1]);
      for (int s = 0; s < 2; ++s) {
        double gv[6];
        for (int i = 0; i < 6; ++i) gv[i] = val(g[s][i]);
        frame_force(T, fr[s], gv, 1.0, X.r);
        X.scale(gv, 6);
      }
      if constexpr (N > 0) blocks<S, N>(X, e, fr, g, ia, ib);
      if (X.energy) {
        const double d = val(delta), el = k[e] * d * std::sqrt(d);
        X.energy[ELASTIC] += el * d / 2.5;
        X.energy[P_DISSIPATION] += (val(Fn) - el) * val(rate) - val(dot(Ft, wt));
      }
    }
    if (X.ctrl)
      for (int i = 0; i < CS; ++i) X.ctrl[ctrl0 + CS * e + i] = out[i];
  }

  // the tangent blocks K = dg/dh, C = dg/dv of both frames from the derivatives of g
  template <class S, int N>
  void blocks(Context& X, int e, const int* fr, const S (*g)[6], int ia, int ib) const {
    const FrameTables& T = *X.T;
    const FrameState& St = *X.S;
    const long offs[2][2] = {{off_aa[e], off_ab[e]}, {off_ba[e], off_bb[e]}};
    const int i0[2] = {ia, ib};
    for (int s = 0; s < 2; ++s)
      for (int t = 0; t < 2; ++t) {
        if (i0[t] < 0) continue;
        double Kb[36], Cb[36];
        for (int i = 0; i < 6; ++i)
          for (int j = 0; j < 6; ++j) {
            Kb[6 * i + j] = g[s][i].d[i0[t] + j];
            Cb[6 * i + j] = g[s][i].d[N / 2 + i0[t] + j];
          }
        add_frame_block(T, St, X.vals, offs[s][t], fr[s], fr[t], Kb, X.cK, true);
        add_frame_block(T, St, X.vals, offs[s][t], fr[s], fr[t], Cb, X.cC, false);
        if (double* V = X.vel(offs[s][t]))
          add_frame_block(T, St, V, 0, fr[s], fr[t], Cb, X.cC, false);
      }
  }
};

}  // namespace se3dyn
