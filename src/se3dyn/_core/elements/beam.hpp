// Geometrically exact two-node beam element on SE(3) (Sonneville, Cardona & Bruls,
// "Geometrically exact beam finite element formulated on the special Euclidean group SE(3)",
// Comput. Methods Appl. Mech. Engrg. 268 (2014) 451-474, doi:10.1016/j.cma.2013.10.008).
//
// The element acts on the section frames H_A X_A and H_B X_B of its two nodes (X constant
// offsets, the identity for the nodes the builder creates along a beam). Its deformation is the
// relative motion d = log(X_A^-1 H_A^-1 H_B X_B) in se(3) against the reference d0, the strain
// eps = (d - d0)/L (L the reference length) is constant along the element, and the section law
// f = K eps + D deps/dt (K the section stiffness, translation first: EA, GA2, GA3, GJ, EI2, EI3;
// D the strain-rate damping) gives the elastic energy L/2 eps^T K eps.
//
// With H_r = exp(d), A_r = Ad(H_r^-1) and the (right-trivialised) tangent operator T(d) of
// Eqs. (21)-(22) of the multibody paper (delta h_r = T(d) delta d, its Eq. (23)):
//   delta d = T^-1(d) (delta h'_B - A_r delta h'_A),  h'_X = Ad(X^-1) h_X,
//   d' = T^-1(d) v_r, v_r = v'_B - A_r v'_A,
//   y = T^-T(d) f, forces on the node frames g_B = Ad(X_B^-1)^T y, g_A = -Ad(X_A^-1)^T A_r^T y
// (the derivative of log is T^-1: delta h = T(n) delta n, Eqs. (20)-(23) and (26) of the
// multibody paper).
// Exact linearisation: delta A_r = -ad(delta h_r) A_r, so delta(A_r^T y) = A_r^T (delta y -
// Lambda(y) delta h_r) with ad(x)^T p = Lambda(p) x; delta(T^-1 z) = -T^-1 DT(d, T^-1 z) delta d
// with DT(x, z) = d(T(x) z)/dx (dt_apply, lie.hpp); and T(x)^T = Pi T(-x) Pi (Pi swapping the
// translation and rotation halves, from ad(x)^T = -Pi ad(x) Pi), so
//   d(T^-T(d) f)/dd at fixed f = T^-T(d) Pi DT(-d, Pi y).
#pragma once
#include <vector>

#include "context.hpp"

namespace se3dyn {

struct Beams : ElementBatch {
  std::vector<int> fa, fb;              // (n,) node frames
  std::vector<Frame> XAinv, XB;         // (n,) section-frame offsets X_A^-1, X_B
  std::vector<double> AdA, AdB;         // (n, 6, 6) Ad(X_A^-1), Ad(X_B^-1)
  std::vector<double> d0, L, K, D;      // (n, 6), (n,), (n, 6, 6), (n, 6, 6)
  std::vector<char> damped;             // (n,)
  std::vector<long> off_aa, off_ab, off_ba, off_bb;

  void load(const Tables& t) override {
    fa = t.ints<int>("fa");
    n = static_cast<int>(fa.size());
    fb = t.ints<int>("fb");
    XAinv = t.frames("XAinv");
    XB = t.frames("XB");
    AdA = t.real("AdA");
    AdB = t.real("AdB");
    d0 = t.real("d0");
    L = t.real("L");
    K = t.real("K");
    D = t.real("D");
    damped = t.ints<char>("damped");
    off_aa = t.integer("off_aa");
    off_ab = t.integer("off_ab");
    off_ba = t.integer("off_ba");
    off_bb = t.integer("off_bb");
  }

  // Deformation of element e in the state S: relative motion H_r, d = log(H_r), A_r, T^-1(d)
  void kinematics(int e, const FrameState& S, Frame& Hr, double* d, double* Ar,
                  double* Ti) const {
    Frame G1, G2;
    compose_inv(S.H[fa[e]], S.H[fb[e]], G1);
    compose(XAinv[e], G1, G2);
    compose(G2, XB[e], Hr);
    log_se3(Hr, d);
    adjoint_inv(Hr, Ar);
    tangent_se3_inv(d, Ti);
  }

  void frames_of(int e, std::vector<int>& out) const override { out = {fa[e], fb[e]}; }

  void eval(Context& X, bool, Span span) const override {
    const FrameTables& T = *X.T;
    const FrameState& S = *X.S;
    for (int e = span.first; e < span.last; ++e) {
      const double* Ke = &K[36 * e];
      const double* De = &D[36 * e];
      const double* AA = &AdA[36 * e];
      const double* AB = &AdB[36 * e];
      double Le = L[e];
      Frame Hr;
      double d[6], Ar[36], Ti[36];
      kinematics(e, S, Hr, d, Ar, Ti);
      double vA[6], vB[6], AvA[6], vr[6], dd[6], eps[6], epsd[6], f[6], y[6];
      mv<6, 6>(AA, &S.v[6 * fa[e]], vA);
      mv<6, 6>(AB, &S.v[6 * fb[e]], vB);
      mv<6, 6>(Ar, vA, AvA);
      for (int i = 0; i < 6; ++i) vr[i] = vB[i] - AvA[i];
      mv<6, 6>(Ti, vr, dd);
      for (int i = 0; i < 6; ++i) {
        eps[i] = (d[i] - d0[6 * e + i]) / Le;
        epsd[i] = dd[i] / Le;
      }
      double Ke_eps[6], De_epsd[6];
      mv<6, 6>(Ke, eps, Ke_eps);
      mv<6, 6>(De, epsd, De_epsd);
      for (int i = 0; i < 6; ++i) f[i] = Ke_eps[i] + De_epsd[i];
      mTv<6, 6>(Ti, f, y);
      double gA[6], gB[6], Ary[6];
      mTv<6, 6>(Ar, y, Ary);
      mTv<6, 6>(AA, Ary, gA);
      for (int i = 0; i < 6; ++i) gA[i] = -gA[i];
      mTv<6, 6>(AB, y, gB);
      frame_force(T, fa[e], gA, 1.0, X.r);
      frame_force(T, fb[e], gB, 1.0, X.r);
      X.scale(gA, 6);
      X.scale(gB, 6);
      {
        // Round-off floor of the force scale (ROUNDOFF_SCALE, context.hpp). The strain is the
        // difference of d and d0, each of size 1 relative to L, and d comes from absolute
        // positions |x|: the section forces carry a round-off of about eps S,
        // S = kU (|x| + L)/L max(1, L) + kO/L (kU, kO the largest translational and rotational
        // stiffnesses), whatever the load.
        double xs = std::fmax(std::sqrt(dot3(S.H[fa[e]].x, S.H[fa[e]].x)),
                              std::sqrt(dot3(S.H[fb[e]].x, S.H[fb[e]].x)));
        double kU = 0.0, kO = 0.0;
        for (int i = 0; i < 3; ++i) {
          kU = std::fmax(kU, std::fabs(Ke[7 * i]));
          kO = std::fmax(kO, std::fabs(Ke[7 * (i + 3)]));
        }
        double floor = ROUNDOFF_SCALE * (kU * (xs + Le) / Le * std::fmax(1.0, Le) + kO / Le);
        X.scale(&floor, 1);
      }
      if (X.energy) {
        double we = 0.0, wd = 0.0;
        for (int i = 0; i < 6; ++i) {
          we += eps[i] * Ke_eps[i];
          wd += epsd[i] * De_epsd[i];
        }
        X.energy[ELASTIC] += 0.5 * Le * we;
        X.energy[P_DISSIPATION] += Le * wd;
      }
      if (!X.vals) continue;
      // Y = T^-T [K/L T^-1 + D/L T^-1 Qc + Pi DT(-d, Pi y) T^-1],
      // Qc = -ad(A_r v'_A) - DT(d, d') T^-1 (configuration derivative of d' = T^-1 v_r)
      double M1[36], M2[36], M3[36], Y[36], Yv[36];
      double KL[36], DL[36];
      for (int i = 0; i < 36; ++i) {
        KL[i] = Ke[i] / Le;
        DL[i] = De[i] / Le;
      }
      double inner[36];
      mm<6, 6, 6>(KL, Ti, inner);
      {  // geometric part from the derivative of T^-T at fixed f: Pi DT(-d, Pi y) = -dT^T y/dd
        double PD[36];
        dtt_apply(d, y, PD);
        mm<6, 6, 6>(PD, Ti, M1);
        for (int i = 0; i < 36; ++i) inner[i] -= M1[i];
      }
      if (damped[e]) {
        double Qc[36], adv[36], DTd[36];
        ad6(AvA, adv);
        dt_apply(d, dd, DTd);
        mm<6, 6, 6>(DTd, Ti, M1);
        for (int i = 0; i < 36; ++i) Qc[i] = -adv[i] - M1[i];
        mm<6, 6, 6>(DL, Ti, M2);   // D/L T^-1
        mm<6, 6, 6>(M2, Qc, M3);
        for (int i = 0; i < 36; ++i) inner[i] += M3[i];
        mTm<6, 6, 6>(Ti, M2, Yv);  // T^-T D/L T^-1
      }
      mTm<6, 6, 6>(Ti, inner, Y);
      // rows: A: -AdA^T A_r^T (Y - Lambda(y)), B: AdB^T Y; columns: A: -A_r AdA, B: AdB
      double Lam[36], RA[36], RB[36], CA[36], t1[36];
      lam_matrix(y, Lam);
      for (int i = 0; i < 36; ++i) t1[i] = Y[i] - Lam[i];
      mTm<6, 6, 6>(Ar, t1, M1);
      mTm<6, 6, 6>(AA, M1, RA);
      for (int i = 0; i < 36; ++i) RA[i] = -RA[i];
      mTm<6, 6, 6>(AB, Y, RB);
      mm<6, 6, 6>(Ar, AA, CA);
      for (int i = 0; i < 36; ++i) CA[i] = -CA[i];
      const double* Rw[2] = {RA, RB};
      const double* Cl[2] = {CA, AB};
      int fr[2] = {fa[e], fb[e]};
      long offs[2][2] = {{off_aa[e], off_ab[e]}, {off_ba[e], off_bb[e]}};
      double RvA[36], RvB[36];
      if (damped[e]) {
        mTm<6, 6, 6>(Ar, Yv, M1);
        mTm<6, 6, 6>(AA, M1, RvA);
        for (int i = 0; i < 36; ++i) RvA[i] = -RvA[i];
        mTm<6, 6, 6>(AB, Yv, RvB);
      }
      const double* Rv[2] = {RvA, RvB};
      for (int s = 0; s < 2; ++s)
        for (int t = 0; t < 2; ++t) {
          double Kb[36];
          mm<6, 6, 6>(Rw[s], Cl[t], Kb);
          add_frame_block(T, S, X.vals, offs[s][t], fr[s], fr[t], Kb, X.cK, true);
          if (!damped[e]) continue;
          double Cb[36];
          mm<6, 6, 6>(Rv[s], Cl[t], Cb);
          add_frame_block(T, S, X.vals, offs[s][t], fr[s], fr[t], Cb, X.cC, false);
          if (double* V = X.vel(offs[s][t]))
            add_frame_block(T, S, V, 0, fr[s], fr[t], Cb, X.cC, false);
        }
    }
  }
};

}  // namespace se3dyn
