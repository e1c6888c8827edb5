// Load at a point of a body: a force F(t) and a torque T(t), each given in the inertial frame
// or in the body (material) frame, applied at the constant material offset c of the node
// (Sec. 10, Eqs. (66)-(67) for c = 0, an inertial force and a material torque).
//
// With F_m = R^T F (inertial) or F (body) and T_m = R^T T (inertial) or T (body), the
// generalised force is g = (F_m, c x F_m + T_m) (virtual work F . d(x + R c) + T_m . dOmega);
// an inertial F or T turns with the body: d(R^T F) = hat(R^T F) dOmega, so
// K = -[[0, hat(R^T F)], [0, hat(c) hat(R^T F) + hat(R^T T)]] (Eq. (67) for c = 0).
// Power g . v*.
#pragma once
#include <vector>

#include "context.hpp"

namespace se3dyn {

struct Loads : ElementBatch {
  std::vector<int> f;           // (n,) node frame
  std::vector<double> c;        // (n, 3) material offset of the point
  std::vector<int> force, torque;           // (n,) input slot of the 3 components or -1
  std::vector<char> force_body, torque_body;  // (n,) given in the body frame
  std::vector<long> off;        // (n,) block (f, f)

  void load(const Tables& t) override {
    f = t.ints<int>("frame");
    n = static_cast<int>(f.size());
    c = t.real("c");
    force = t.ints<int>("force");
    torque = t.ints<int>("torque");
    force_body = t.ints<char>("force_body");
    torque_body = t.ints<char>("torque_body");
    off = t.integer("off");
  }

  void frames_of(int e, std::vector<int>& out) const override { out = {f[e]}; }

  void eval(Context& X, bool, Span span) const override {
    const FrameTables& T = *X.T;
    const FrameState& S = *X.S;
    for (int e = span.first; e < span.last; ++e) {
      int fr = f[e];
      if (T.dof[fr] < 0) continue;
      const Frame& H = S.H[fr];
      double Fm[3] = {0, 0, 0}, Tm[3] = {0, 0, 0};
      if (force[e] >= 0) {
        const double* F = X.u + force[e];
        if (force_body[e]) { Fm[0] = F[0]; Fm[1] = F[1]; Fm[2] = F[2]; }
        else mTv<3, 3>(H.R, F, Fm);
      }
      if (torque[e] >= 0) {
        const double* Tq = X.u + torque[e];
        if (torque_body[e]) { Tm[0] = Tq[0]; Tm[1] = Tq[1]; Tm[2] = Tq[2]; }
        else mTv<3, 3>(H.R, Tq, Tm);
      }
      const double* ce = &c[3 * e];
      double g[6];
      g[0] = Fm[0]; g[1] = Fm[1]; g[2] = Fm[2];
      cross(ce, Fm, g + 3);
      g[3] += Tm[0]; g[4] += Tm[1]; g[5] += Tm[2];
      X.scale(g, 6);
      frame_force(T, fr, g, -1.0, X.r);
      if (X.energy) {
        const double* v = &S.v[6 * fr];
        X.energy[P_LOADS] += g[0] * v[0] + g[1] * v[1] + g[2] * v[2] + g[3] * v[3] + g[4] * v[4] +
                             g[5] * v[5];
      }
      if (!X.vals || X.cK == 0.0) continue;
      bool fi = force[e] >= 0 && !force_body[e], ti = torque[e] >= 0 && !torque_body[e];
      if (!fi && !ti) continue;
      double K[36] = {0};
      if (fi) {
        double G[9], Cm[9], CG[9];
        hat3(Fm, G);
        hat3(ce, Cm);
        mm<3, 3, 3>(Cm, G, CG);
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) {
            K[6 * i + 3 + j] -= G[3 * i + j];
            K[6 * (3 + i) + 3 + j] -= CG[3 * i + j];
          }
      }
      if (ti) {
        double G[9];
        hat3(Tm, G);
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) K[6 * (3 + i) + 3 + j] -= G[3 * i + j];
      }
      add_frame_block(T, S, X.vals, off[e], fr, fr, K, X.cK, true);
    }
  }
};

}  // namespace se3dyn
