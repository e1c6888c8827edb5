// Rigid body: inertia and gravity on one node frame (Sec. 6, Eqs. (47)-(53), (66)-(67)),
// generalised to a centre of mass at a constant material offset c from the node.
//
// With the node frame H = (R, x) and the centre of mass at x + R c, the kinetic energy
// 1/2 v^T M v has the constant 6 x 6 material mass matrix
//     M = [[m I, -m hat(c)], [m hat(c), J_c - m hat(c)^2]]   (J_c about the centre of mass)
// (Eq. (49) for c = 0). The inertia force is M vd - ad(v)^T M v (Eq. (36); Eq. (51) for
// c = 0), its tangent damping C_T = -Lambda(M v) - ad(v)^T M with ad(d)^T p = Lambda(p) d
// (Eq. (53) for c = 0). Gravity g acts at the centre of mass: the generalised force is
// (m R^T g, m c x R^T g) (Eq. (66)), its stiffness K = -[[0, m hat(R^T g)], [0, m hat(c)
// hat(R^T g)]] (Eq. (67)); potential energy -g . (m x + R m c).
#pragma once
#include <vector>

#include "context.hpp"

namespace se3dyn {

struct Bodies : ElementBatch {
  std::vector<int> f;         // (n,) frame
  std::vector<double> M;      // (n, 6, 6) material mass matrix about the node
  std::vector<double> mc;     // (n, 3) m c
  std::vector<double> m;      // (n,)
  std::vector<long> off;      // (n,) block (f, f)

  void load(const Tables& t) override {
    f = t.ints<int>("frame");
    n = static_cast<int>(f.size());
    M = t.real("M");
    mc = t.real("mc");
    m = t.real("m");
    off = t.integer("off");
  }

  void frames_of(int e, std::vector<int>& out) const override { out = {f[e]}; }

  void eval(Context& X, bool, Span span) const override {
    const FrameTables& T = *X.T;
    const FrameState& S = *X.S;
    for (int e = span.first; e < span.last; ++e) {
      int fr = f[e];
      if (T.dof[fr] < 0 && !X.energy) continue;
      const double* Me = &M[36 * e];
      const double* v = &S.v[6 * fr];
      const double* vd = &S.vd[6 * fr];
      const Frame& H = S.H[fr];
      double p[6], Mvd[6], L[36], g[6], gin[6], rtg[3];
      mv<6, 6>(Me, v, p);
      mv<6, 6>(Me, vd, Mvd);
      lam_matrix(p, L);
      double adTp[6];
      mv<6, 6>(L, v, adTp);  // ad(v)^T M v
      mTv<3, 3>(H.R, X.gravity, rtg);
      const double* c = &mc[3 * e];
      for (int i = 0; i < 3; ++i) g[i] = m[e] * rtg[i];
      cross(c, rtg, g + 3);
      for (int i = 0; i < 6; ++i) gin[i] = Mvd[i] - adTp[i];
      if (X.energy) {
        X.energy[KINETIC] += 0.5 * (v[0] * p[0] + v[1] * p[1] + v[2] * p[2] + v[3] * p[3] +
                                    v[4] * p[4] + v[5] * p[5]);
        double Rc[3];
        mv<3, 3>(H.R, c, Rc);
        X.energy[POTENTIAL] -= m[e] * dot3(X.gravity, H.x) + dot3(X.gravity, Rc);
      }
      if (T.dof[fr] < 0) continue;
      X.scale(gin, 6);
      X.scale(g, 6);
      double rr[6];
      for (int i = 0; i < 6; ++i) rr[i] = gin[i] - g[i];
      frame_force(T, fr, rr, 1.0, X.r);
      if (!X.vals) continue;
      // velocity-level part cM M + cC C_T, C_T = -Lambda(M v) - ad(v)^T M
      double ad[36], adTM[36], B[36];
      ad6(v, ad);
      mTm<6, 6, 6>(ad, Me, adTM);
      for (int i = 0; i < 36; ++i) B[i] = X.cM * Me[i] - X.cC * (L[i] + adTM[i]);
      add_frame_block(T, S, X.vals, off[e], fr, fr, B, 1.0, false);
      if (double* V = X.vel(off[e])) add_frame_block(T, S, V, 0, fr, fr, B, 1.0, false);
      if (X.cK != 0.0) {
        double K[36] = {0}, G[9], CG[9], Cm[9];
        hat3(rtg, G);
        hat3(c, Cm);
        mm<3, 3, 3>(Cm, G, CG);
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) {
            K[6 * i + 3 + j] = -m[e] * G[3 * i + j];
            K[6 * (3 + i) + 3 + j] = -CG[3 * i + j];
          }
        add_frame_block(T, S, X.vals, off[e], fr, fr, K, X.cK, true);
      }
    }
  }
};

}  // namespace se3dyn
