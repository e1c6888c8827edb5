// Kinematic joint (or rigid constraint) between two node frames A and B, through the joint frame
// J (Sec. 7, Eqs. (7)-(11), (54)-(59)), attached to the nodes by constant frames X_A, X_B
// (the identity for joints between the nodes themselves, as in the paper).
//
//   G = (H_B X_B)^-1 (H_A X_A) H_J,   Phi = vect(G)  (Eqs. (55)-(56)).
//
// A variation H_A exp(d_a) gives G exp(Ad_{H_J^-1} PA d_a), H_B exp(d_b) gives
// G exp(-Ad_{G^-1} PB d_b) and H_J exp(d_j) gives G exp(d_j), with PA = Ad(X_A^-1),
// PB = Ad(X_B^-1). The constraint forces are those of the gradient at Phi = 0 (Eq. (58)):
// B = [Ad_{H_J^-1} PA, -PB, I] (frames A, B, J), forces B^T lambda; the constraint rows of the
// iteration matrix are the exact linearisation D [Ad PA, -Ad_{G^-1} PB, I] T A (Eq. (59) at
// G = I; D = dvect(G)), and the geometric stiffness of PA^T Ad^T lambda with respect to the
// joint frame, -PA^T Ad^T Lambda(lambda) T_J A, is included.
//
// Stabilised index 2 (Arnold, Bruls & Cardona, Numer. Math. 129 (2015) 149-179): velocity
// constraints psi = B v* and the blocks B A + cv d(B v*)/dh* T A, with
// d(B v*)/dh*_J = ad(w) (w = Ad PA v*_A); the increment correction B_n^T xi uses B at the start
// of the step (stored per joint by `store_Bn`).
#pragma once
#include <vector>

#include "context.hpp"

namespace se3dyn {

struct Joints : ElementBatch {
  std::vector<int> fa, fb, fj;      // (n,) frames of node A, node B and the joint
  std::vector<int> mult;            // (n,) first multiplier row
  std::vector<Frame> XA, XB;        // (n,) attachment frames
  std::vector<double> PA, PB;       // (n, 6, 6) Ad(X_A^-1), Ad(X_B^-1)
  std::vector<char> offset;         // (n,) X_A or X_B not the identity
  // block offsets: constraint rows x (A, B, J); (A, B, J) x multiplier columns; (A, J) geometric
  std::vector<long> off_ca, off_cb, off_cj, off_ac, off_bc, off_jc, off_aj;
  // index 2: velocity-constraint rows x (A, B, J)
  std::vector<long> off_xa, off_xb, off_xj;
  // B A per frame slot (n, 3, 6, 6) at the iterate and at the start of the step; the slots of
  // node B (-PB A_B) and of the joint frame (A_J) are constant: written once (const_ready)
  mutable std::vector<double> Bu, Bnu;
  mutable bool const_ready = false;

  void resize_scratch() {
    Bu.assign(108 * n, 0.0);
    Bnu.assign(108 * n, 0.0);
    const_ready = false;
  }

  void constant_slots(const FrameTables& T) const {
    if (const_ready) return;
    for (int e = 0; e < n; ++e) {
      int fr[3] = {fa[e], fb[e], fj[e]};
      for (int s = 1; s < 3; ++s) {
        double Bs[36];
        B(e, s, Frame(), Bs);  // (independent of the joint frame)
        frame_cols(T, fr[s], Bs, &Bu[108 * e + 36 * s]);
        std::copy(&Bu[108 * e + 36 * s], &Bu[108 * e + 36 * s] + 36, &Bnu[108 * e + 36 * s]);
        // (a prescribed coordinate is no part of the index-2 correction: frames.hpp)
        for (int c = 0; c < T.k[fr[s]]; ++c)
          if (T.driven(fr[s], c))
            for (int i = 0; i < 6; ++i) Bnu[108 * e + 36 * s + 6 * i + c] = 0.0;
      }
    }
    const_ready = true;
  }

  // B_s (6x6) of slot s (0: A, 1: B, 2: J) at the joint frame H_J
  void B(int e, int s, const Frame& HJ, double* out) const {
    if (s == 0) {
      if (offset[e]) {  // Ad_{H_J^-1} Ad_{X_A^-1} = Ad_{(X_A H_J)^-1}
        Frame XH;
        compose(XA[e], HJ, XH);
        adjoint_inv(XH, out);
      } else {
        adjoint_inv(HJ, out);
      }
    } else if (s == 1) {
      for (int i = 0; i < 36; ++i) out[i] = offset[e] ? -PB[36 * e + i] : (i % 7 == 0 ? -1.0 : 0.0);
    } else {
      for (int i = 0; i < 36; ++i) out[i] = (i % 7 == 0) ? 1.0 : 0.0;
    }
  }

  // B_s A_f of every joint at the given frames into `dst` (n, 3, 36)
  void store_B(const FrameTables& T, const std::vector<Frame>& H, std::vector<double>& dst) const {
    constant_slots(T);
    for (int e = 0; e < n; ++e) store_B0(T, H, dst, e);
  }
  // slot 0 (node A) of joint e (slots 1 and 2 are constant: constant_slots)
  void store_B0(const FrameTables& T, const std::vector<Frame>& H, std::vector<double>& dst,
                int e) const {
    double Bs[36];
    B(e, 0, H[fj[e]], Bs);
    frame_cols(T, fa[e], Bs, &dst[108 * e]);
  }

  void load(const Tables& t) override {
    fa = t.ints<int>("fa");
    n = static_cast<int>(fa.size());
    fb = t.ints<int>("fb");
    fj = t.ints<int>("fj");
    mult = t.ints<int>("mult");
    XA = t.frames("XA");
    XB = t.frames("XB");
    PA = t.real("PA");
    PB = t.real("PB");
    offset = t.ints<char>("offset");
    off_ca = t.integer("off_ca");
    off_cb = t.integer("off_cb");
    off_cj = t.integer("off_cj");
    off_ac = t.integer("off_ac");
    off_bc = t.integer("off_bc");
    off_jc = t.integer("off_jc");
    off_aj = t.integer("off_aj");
    off_xa = t.integer("off_xa");
    off_xb = t.integer("off_xb");
    off_xj = t.integer("off_xj");
    resize_scratch();
  }

  void frames_of(int e, std::vector<int>& out) const override { out = {fa[e], fb[e], fj[e]}; }

  void eval(Context& X, bool index2, Span span) const override {
    const FrameTables& T = *X.T;
    constant_slots(T);
    const FrameState& S = *X.S;
    for (int e = span.first; e < span.last; ++e) {
      int a = fa[e], b = fb[e], j = fj[e];
      const Frame& HJ = S.H[j];
      Frame HA = S.H[a], HB = S.H[b], G, t1;
      if (offset[e]) {
        compose(S.H[a], XA[e], HA);
        compose(S.H[b], XB[e], HB);
      }
      compose_inv(HB, HA, t1);
      compose(t1, HJ, G);
      const double* lam = X.lam + mult[e];
      vect(G, X.phi + mult[e]);
      X.scale(lam, 6);
      double AdP[36], PBe[36];
      B(e, 0, HJ, AdP);
      B(e, 1, HJ, PBe);  // -PB
      double fa6[6], fb6[6];
      mTv<6, 6>(AdP, lam, fa6);
      mTv<6, 6>(PBe, lam, fb6);
      frame_force(T, a, fa6, 1.0, X.r);
      frame_force(T, b, fb6, 1.0, X.r);
      frame_force(T, j, lam, 1.0, X.r);
      double w[6];
      if (X.arhs) {
        // acceleration-level constraints B vd* = ad(v*_J) Ad PA v*_A: the time derivative of
        // B v* = 0, with d/dt Ad_{H_J^-1} = -ad(v*_J) Ad_{H_J^-1} and constant PA, PB
        double ad[36], wa[6];
        mv<6, 6>(AdP, &S.v[6 * a], wa);
        ad6(&S.v[6 * j], ad);
        mv<6, 6>(ad, wa, X.arhs + mult[e]);
      }
      if (X.psi) {  // velocity constraints B v*
        double vb[6];
        mv<6, 6>(AdP, &S.v[6 * a], w);
        mv<6, 6>(PBe, &S.v[6 * b], vb);
        double* ps = X.psi + mult[e];
        const double* vj = &S.v[6 * j];
        for (int i = 0; i < 6; ++i) ps[i] = w[i] + vb[i] + vj[i];
      }
      if (!X.vals) continue;
      double D[36], C[36], Y[36];
      if (X.phi_rows) dvect(G, D);
      // constraint rows: D Ad PA T_A A_A, -D Ad_{G^-1} PB T_B A_B, D T_J A_J
      if (X.phi_rows && T.k[a]) {
        mm<6, 6, 6>(D, AdP, C);
        cols_times(6, T.k[a], C, &S.TA[36 * a], Y);
        add_block(X.vals, off_ca[e], 6, T.k[a], Y, 1.0);
      }
      if (X.phi_rows && T.k[b]) {
        double AdG[36], t[36];
        adjoint_inv(G, AdG);
        mm<6, 6, 6>(D, AdG, t);
        if (offset[e]) mm<6, 6, 6>(t, &PB[36 * e], C);
        else for (int i = 0; i < 36; ++i) C[i] = t[i];
        cols_times(6, T.k[b], C, &S.TA[36 * b], Y);
        add_block(X.vals, off_cb[e], 6, T.k[b], Y, -1.0);
      }
      if (X.phi_rows && T.k[j]) {
        cols_times(6, T.k[j], D, &S.TA[36 * j], Y);
        add_block(X.vals, off_cj[e], 6, T.k[j], Y, 1.0);
      }
      // multiplier columns: A^T B^T (Eq. (58))
      int fr[3] = {a, b, j};
      long offs[3] = {off_ac[e], off_bc[e], off_jc[e]};
      for (int s = 0; s < 3; ++s) {
        int f = fr[s];
        if (!T.k[f]) continue;
        double* BA = &Bu[108 * e + 36 * s];  // kept for the index-2 products
        // B A (6 x k): its transpose is A^T B^T (slots 1 and 2 constant: constant_slots)
        if (s == 0) frame_cols(T, f, AdP, BA);
        add_block_T(X.vals, offs[s], T.k[f], 6, BA, 1.0);
      }
      // geometric stiffness: d(PA^T Ad^T lambda)/dh*_J = -(Ad PA)^T Lambda(lambda)
      if (T.k[a] && T.k[j] && X.cK != 0.0) {
        double L[36], K[36];
        lam_matrix(lam, L);
        mTm<6, 6, 6>(AdP, L, K);
        add_frame_block(T, S, X.vals, off_aj[e], a, j, K, -X.cK, true);
      }
      if (index2) {  // the matrix is the stabilised index-2 one (w was computed: psi given)
        // velocity-constraint rows: B A + cv ad(w) T_J A, cv = 1/gamma'
        long xo[3] = {off_xa[e], off_xb[e], off_xj[e]};
        for (int s = 0; s < 3; ++s) {
          int f = fr[s];
          if (!T.k[f]) continue;
          const double* BA = &Bu[108 * e + 36 * s];
          add_block(X.vals, xo[s], 6, T.k[f], BA, 1.0);
        }
        if (T.k[j]) {
          double ad[36];
          ad6(w, ad);
          cols_times(6, T.k[j], ad, &S.TA[36 * j], Y);
          add_block(X.vals, off_xj[e], 6, T.k[j], Y, cv_);
        }
      }
    }
  }
  double cv_ = 0.0;  // 1/gamma' of the current step (index 2)
};

}  // namespace se3dyn
