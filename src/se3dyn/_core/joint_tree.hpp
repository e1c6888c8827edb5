// Joint-space dynamics of a tree (se3dyn.analysis.JointSpace's compiled path): recursive
// Newton-Euler (inverse dynamics, bias, gravity) and the composite-rigid-body algorithm (mass
// matrix) over the links of the tree, from tables that JointSpace computes once.
//
// A link is a node placed either as a floating root (its pose from (x, y, z, qx, qy, qz, qw),
// its velocity the material (U, Omega), Eq. (4)) or by an abelian joint from its parent link
// (or from a fixed node, whose pose is folded into P): H_child = H_parent P exp(S0 da) Q
// (Eq. (7) with X_A H_J0 = P, X_B^-1 = Q; da = alpha - alpha0). Velocities are material
// (the node frame's), the link's motion subspace S = Ad(Q^-1) S0 (6 x k). Per link the
// constant material mass matrix about the node M (body.hpp) and gravity at the centre of
// mass (m R^T g, m c x R^T g) (Eq. (66)). Sign: M(q) a + b(q, v) = tau, with the engine's
// residual M vd - ad(v)^T M v - g (Eq. (36)).
#pragma once
#include <cmath>
#include <vector>

#include "lie.hpp"

namespace se3dyn {

struct JointTree {
  int nl = 0, nq = 0, nv = 0;
  std::vector<int> par, kind, k, qadr, vadr;  // kind 0: joint, 1: floating root
  std::vector<Frame> P, Q;
  std::vector<double> S0, S, alpha0;  // (nl, 6, 6): column c of link l at 36 l + 6 c
  std::vector<double> M, mc, m;       // (nl, 6, 6), (nl, 3), (nl,)
  std::vector<double> armature;       // (nv,)
  // joint springs and dampers (joint_force.hpp on abelian joints): K (q - ref) + C v per
  // velocity coordinate, qidx its position in q (-1: a root's)
  std::vector<double> K, ref, C;
  std::vector<int> qidx;
  double g[3] = {0.0, 0.0, 0.0};

  struct Work {
    std::vector<Frame> H;
    std::vector<double> Ad, v, a, f, I;
    explicit Work(int n) : H(n), Ad(36 * n), v(6 * n), a(6 * n), f(6 * n), I(36 * n) {}
  };

  // poses and Ad(X^-1) of the links' relative placements at q (nq,)
  void place(const double* q, Work& w) const {
    for (int l = 0; l < nl; ++l) {
      Frame& H = w.H[l];
      if (kind[l] == 1) {
        const double* p = q + qadr[l];
        double n = std::sqrt(p[3] * p[3] + p[4] * p[4] + p[5] * p[5] + p[6] * p[6]);
        double x = p[3] / n, y = p[4] / n, z = p[5] / n, s = p[6] / n;
        double R[9] = {1 - 2 * (y * y + z * z), 2 * (x * y - z * s), 2 * (x * z + y * s),
                       2 * (x * y + z * s), 1 - 2 * (x * x + z * z), 2 * (y * z - x * s),
                       2 * (x * z - y * s), 2 * (y * z + x * s), 1 - 2 * (x * x + y * y)};
        for (int i = 0; i < 9; ++i) H.R[i] = R[i];
        for (int i = 0; i < 3; ++i) H.x[i] = p[i];
        continue;
      }
      double n[6] = {0, 0, 0, 0, 0, 0};
      for (int c = 0; c < k[l]; ++c) {
        double da = q[qadr[l] + c] - alpha0[6 * l + c];
        for (int r = 0; r < 6; ++r) n[r] += S0[36 * l + 6 * c + r] * da;
      }
      Frame E, PE, X;
      exp_se3(n, E);
      compose(P[l], E, PE);
      compose(PE, Q[l], X);
      adjoint_inv(X, &w.Ad[36 * l]);
      if (par[l] >= 0)
        compose(w.H[par[l]], X, H);
      else
        H = X;
    }
  }

  // S_l x (k,) -> (6,) added to out
  void add_S(int l, const double* x, double* out) const {
    for (int c = 0; c < k[l]; ++c)
      for (int r = 0; r < 6; ++r) out[r] += S[36 * l + 6 * c + r] * x[c];
  }

  static void ad_apply(const double* v, const double* u, double* out) {  // out += ad(v) u
    double t[3];
    cross(v + 3, u, t);
    for (int i = 0; i < 3; ++i) out[i] += t[i];
    cross(v, u + 3, t);
    for (int i = 0; i < 3; ++i) out[i] += t[i];
    cross(v + 3, u + 3, t);
    for (int i = 0; i < 3; ++i) out[3 + i] += t[i];
  }

  // link forces f = M a - ad(v)^T M v - g in the forward pass
  void forward(const double* vv, const double* aa, Work& w) const {
    for (int l = 0; l < nl; ++l) {
      double* v = &w.v[6 * l];
      double* a = &w.a[6 * l];
      if (kind[l] == 1) {
        for (int i = 0; i < 6; ++i) {
          v[i] = vv ? vv[vadr[l] + i] : 0.0;
          a[i] = aa ? aa[vadr[l] + i] : 0.0;
        }
      } else {
        const double* Ad = &w.Ad[36 * l];
        double zero[6] = {0, 0, 0, 0, 0, 0};
        const double* vp = par[l] >= 0 ? &w.v[6 * par[l]] : zero;
        const double* ap = par[l] >= 0 ? &w.a[6 * par[l]] : zero;
        mv<6, 6>(Ad, vp, v);
        mv<6, 6>(Ad, ap, a);
        double Sqd[6] = {0, 0, 0, 0, 0, 0};
        if (vv) add_S(l, vv + vadr[l], Sqd);
        for (int i = 0; i < 6; ++i) v[i] += Sqd[i];
        if (aa) add_S(l, aa + vadr[l], a);
        ad_apply(v, Sqd, a);
      }
      const double* Me = &M[36 * l];
      double p[6], rtg[3], t[3];
      mv<6, 6>(Me, v, p);
      double* f = &w.f[6 * l];
      mv<6, 6>(Me, a, f);
      cross(v + 3, p, t);  // -ad(v)^T p = (Omega x p_U, U x p_U + Omega x p_O)
      for (int i = 0; i < 3; ++i) f[i] += t[i];
      cross(v, p, t);
      for (int i = 0; i < 3; ++i) f[3 + i] += t[i];
      cross(v + 3, p + 3, t);
      for (int i = 0; i < 3; ++i) f[3 + i] += t[i];
      mTv<3, 3>(w.H[l].R, g, rtg);
      cross(&mc[3 * l], rtg, t);
      for (int i = 0; i < 3; ++i) {
        f[i] -= m[l] * rtg[i];
        f[3 + i] -= t[i];
      }
    }
  }

  // tau (nv,) = M(q) a + b(q, v); v or a null: zero
  void rnea(const double* q, const double* vv, const double* aa, double* tau, Work& w) const {
    place(q, w);
    forward(vv, aa, w);
    for (int l = nl - 1; l >= 0; --l) {
      const double* f = &w.f[6 * l];
      if (kind[l] == 1) {
        for (int i = 0; i < 6; ++i) tau[vadr[l] + i] = f[i];
        continue;
      }
      for (int c = 0; c < k[l]; ++c) {
        double s = 0.0;
        for (int r = 0; r < 6; ++r) s += S[36 * l + 6 * c + r] * f[r];
        tau[vadr[l] + c] = s;
      }
      if (par[l] >= 0) {
        double fp[6];
        mTv<6, 6>(&w.Ad[36 * l], f, fp);
        for (int i = 0; i < 6; ++i) w.f[6 * par[l] + i] += fp[i];
      }
    }
    for (int i = 0; i < nv; ++i) {
      if (qidx[i] < 0) continue;
      if (aa) tau[i] += armature[i] * aa[i];
      tau[i] += K[i] * (q[qidx[i]] - ref[i]);
      if (vv) tau[i] += C[i] * vv[i];
    }
  }

  // column c of link l's subspace (the identity for a root)
  double s_at(int l, int r, int c) const {
    return kind[l] == 1 ? (r == c ? 1.0 : 0.0) : S[36 * l + 6 * c + r];
  }
  int width(int l) const { return kind[l] == 1 ? 6 : k[l]; }

  // mass matrix (nv, nv), row-major, both triangles
  void crba(const double* q, double* Mz, Work& w) const {
    place(q, w);
    for (int i = 0; i < nv * nv; ++i) Mz[i] = 0.0;
    w.I = M;
    for (int l = nl - 1; l >= 0; --l) {
      if (par[l] < 0) continue;
      const double* Ad = &w.Ad[36 * l];
      double IA[36], AtIA[36];
      mm<6, 6, 6>(&w.I[36 * l], Ad, IA);
      mTm<6, 6, 6>(Ad, IA, AtIA);
      for (int i = 0; i < 36; ++i) w.I[36 * par[l] + i] += AtIA[i];
    }
    for (int l = 0; l < nl; ++l) {
      int kl = width(l);
      double F[36], G[36];  // (6, kl) column c at 6 c
      for (int c = 0; c < kl; ++c)
        for (int r = 0; r < 6; ++r) {
          double s = 0.0;
          for (int j = 0; j < 6; ++j) s += w.I[36 * l + 6 * r + j] * s_at(l, j, c);
          F[6 * c + r] = s;
        }
      for (int j = l;;) {
        int kj = width(j);
        for (int c = 0; c < kl; ++c)
          for (int b = 0; b < kj; ++b) {
            double s = 0.0;
            for (int r = 0; r < 6; ++r) s += s_at(j, r, b) * F[6 * c + r];
            Mz[(vadr[j] + b) * nv + vadr[l] + c] = s;
            Mz[(vadr[l] + c) * nv + vadr[j] + b] = s;
          }
        if (par[j] < 0 || kind[j] == 1) break;
        for (int c = 0; c < kl; ++c) mTv<6, 6>(&w.Ad[36 * j], F + 6 * c, G + 6 * c);
        for (int i = 0; i < 6 * kl; ++i) F[i] = G[i];
        j = par[j];
      }
    }
    for (int i = 0; i < nv; ++i) Mz[i * nv + i] += armature[i];
  }
};

}  // namespace se3dyn
