// Spring-damper between two points attached to two node frames: the points p = x + R c (c a
// constant material offset), the force N = k (L - L0) + d dL/dt along the line of the points,
// L = |p_b - p_a|, e = (p_b - p_a)/L.
//
// With J = R [I, -hat(c)] (dp = J dh, 3 x 6) the generalised forces are
// r_a = -N J_a^T e... written in material form -N P_a^T q_a, r_b = N P_b^T q_b with
// P = [I, -hat(c)], q = R^T e. Their exact linearisation (configuration and velocity) is
// assembled from dL = e . dd, dd = J_b dh_b - J_a dh_a,
// d(dL/dt) = w^T Pe dd + e^T (R_a hat(P_a v_a) dOmega_a - R_b hat(P_b v_b) dOmega_b)
//            + e^T (J_b dv_b - J_a dv_a),
// dq = hat(q) dOmega + R^T Pe dd, with w = J_b v_b - J_a v_a and Pe = (I - e e^T)/L.
// Energy k (L - L0)^2 / 2, dissipated power d (dL/dt)^2.
#pragma once
#include <vector>

#include "context.hpp"

namespace se3dyn {

struct SpringDampers : ElementBatch {
  std::vector<int> fa, fb;          // (n,) node frames
  std::vector<double> ca, cb;       // (n, 3) material offsets of the points
  std::vector<double> k, d, L0;     // (n,)
  std::vector<long> off_aa, off_ab, off_ba, off_bb;

  void load(const Tables& t) override {
    fa = t.ints<int>("fa");
    n = static_cast<int>(fa.size());
    fb = t.ints<int>("fb");
    ca = t.real("ca");
    cb = t.real("cb");
    k = t.real("k");
    d = t.real("d");
    L0 = t.real("L0");
    off_aa = t.integer("off_aa");
    off_ab = t.integer("off_ab");
    off_ba = t.integer("off_ba");
    off_bb = t.integer("off_bb");
  }

  void frames_of(int e, std::vector<int>& out) const override { out = {fa[e], fb[e]}; }

  void eval(Context& X, bool, Span span) const override {
    const FrameTables& T = *X.T;
    const FrameState& S = *X.S;
    for (int e = span.first; e < span.last; ++e) {
      int fr[2] = {fa[e], fb[e]};
      const double* cs[2] = {&ca[3 * e], &cb[3 * e]};
      double p[2][3], J[2][18], Pm[2][18], q[2][3], Pv[2][3];
      double dvec[3], w[3] = {0, 0, 0};
      for (int s = 0; s < 2; ++s) {
        const Frame& H = S.H[fr[s]];
        apply(H, cs[s], p[s]);
        // P = [I, -hat(c)] (3 x 6)
        double* P = Pm[s];
        for (int i = 0; i < 18; ++i) P[i] = 0.0;
        P[0] = P[7] = P[14] = 1.0;
        hat3(cs[s], P + 3, 6, -1.0);
        mm<3, 3, 6>(H.R, P, J[s]);
        mv<3, 6>(P, &S.v[6 * fr[s]], Pv[s]);
        double Jv[3];
        mv<3, 3>(H.R, Pv[s], Jv);
        double sg = s ? 1.0 : -1.0;
        for (int i = 0; i < 3; ++i) w[i] += sg * Jv[i];
      }
      for (int i = 0; i < 3; ++i) dvec[i] = p[1][i] - p[0][i];
      double L = std::sqrt(dot3(dvec, dvec));
      double ev[3] = {0, 0, 0};
      if (L > 0) for (int i = 0; i < 3; ++i) ev[i] = dvec[i] / L;
      double Ldot = dot3(ev, w);
      double N = k[e] * (L - L0[e]) + d[e] * Ldot;
      double g[2][6];
      for (int s = 0; s < 2; ++s) {
        mTv<3, 3>(S.H[fr[s]].R, ev, q[s]);
        mTv<3, 6>(Pm[s], q[s], g[s]);
        double sg = s ? 1.0 : -1.0;
        for (int i = 0; i < 6; ++i) g[s][i] *= sg * N;
        frame_force(T, fr[s], g[s], 1.0, X.r);
        X.scale(g[s], 6);
      }
      if (X.energy) {
        X.energy[ELASTIC] += 0.5 * k[e] * (L - L0[e]) * (L - L0[e]);
        X.energy[P_DISSIPATION] += d[e] * Ldot * Ldot;
      }
      if (!X.vals || L <= 0) continue;
      // row vectors over (dh_a, dh_b) (12,): dL, d(Ldot) (configuration), d(Ldot)/dv
      double Pe[9];
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) Pe[3 * i + j] = ((i == j) - ev[i] * ev[j]) / L;
      double dd[36];  // dd (3 x 12) = [-J_a, J_b]
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 6; ++j) {
          dd[12 * i + j] = -J[0][6 * i + j];
          dd[12 * i + 6 + j] = J[1][6 * i + j];
        }
      double dL[12], dLd[12], dLv[12], wP[3];
      mTv<3, 3>(Pe, w, wP);
      for (int c = 0; c < 12; ++c) {
        dL[c] = ev[0] * dd[c] + ev[1] * dd[12 + c] + ev[2] * dd[24 + c];
        dLd[c] = wP[0] * dd[c] + wP[1] * dd[12 + c] + wP[2] * dd[24 + c];
        dLv[c] = dL[c];
      }
      for (int s = 0; s < 2; ++s) {
        // e^T R hat(P v) dOmega, sign + for a, - for b
        double Hm[9], RH[9], row[3];
        hat3(Pv[s], Hm);
        mm<3, 3, 3>(S.H[fr[s]].R, Hm, RH);
        mTv<3, 3>(RH, ev, row);
        double sg = s ? -1.0 : 1.0;
        for (int i = 0; i < 3; ++i) dLd[6 * s + 3 + i] += sg * row[i];
      }
      double dN[12];
      for (int c = 0; c < 12; ++c) dN[c] = k[e] * dL[c] + d[e] * dLd[c];
      for (int s = 0; s < 2; ++s) {
        double sg = s ? 1.0 : -1.0;
        // dq (3 x 12) = hat(q) Omega-columns of own frame + R^T Pe dd
        double RPe[9], dq[36];
        mTm<3, 3, 3>(S.H[fr[s]].R, Pe, RPe);
        mm<3, 3, 12>(RPe, dd, dq);
        double Q[9];
        hat3(q[s], Q);
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) dq[12 * i + 6 * s + 3 + j] += Q[3 * i + j];
        double Pq[6];
        mTv<3, 6>(Pm[s], q[s], Pq);
        double Kr[72], Cr[72];  // rows of frame s (6 x 12)
        double PdQ[72];
        mTm<6, 3, 12>(Pm[s], dq, PdQ);
        for (int i = 0; i < 6; ++i)
          for (int c = 0; c < 12; ++c) {
            Kr[12 * i + c] = sg * (Pq[i] * dN[c] + N * PdQ[12 * i + c]);
            Cr[12 * i + c] = sg * Pq[i] * d[e] * dLv[c];
          }
        long offs[2] = {s ? off_ba[e] : off_aa[e], s ? off_bb[e] : off_ab[e]};
        for (int t = 0; t < 2; ++t) {
          double Kb[36], Cb[36];
          for (int i = 0; i < 6; ++i)
            for (int j = 0; j < 6; ++j) {
              Kb[6 * i + j] = Kr[12 * i + 6 * t + j];
              Cb[6 * i + j] = Cr[12 * i + 6 * t + j];
            }
          add_frame_block(T, S, X.vals, offs[t], fr[s], fr[t], Kb, X.cK, true);
          add_frame_block(T, S, X.vals, offs[t], fr[s], fr[t], Cb, X.cC, false);
          if (double* V = X.vel(offs[t]))
            add_frame_block(T, S, V, 0, fr[s], fr[t], Cb, X.cC, false);
        }
      }
    }
  }
};

}  // namespace se3dyn
