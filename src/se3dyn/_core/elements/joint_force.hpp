// Force elements on the relative coordinates of a joint (Secs. 8-10): springs (Eq. (62)),
// dampers (Eq. (64)), actuators tau(t) (Eq. (66)) and PD and PID control laws
// tau = -kp e - ki z - kd (v - rate_ref(t)), e = alpha - alpha_ref(t), z = int e dt, with an
// optional saturation |tau| <= limit.
//
// PID: the integral z is a state carried from step to step, integrated by the trapezoidal
// rule inside the step's Newton iterations: z_{n+1} = z_n + h/2 (e_n + e_{n+1}), implicit and
// second order, A-stable (the rule the generalized-alpha scheme reduces to for a first-order
// state without numerical damping). The inputs of the step hold (z_n, e_n, h/2) per
// coordinate (slots `zslot`, written by the time loop, newton.hpp); the kernel writes the
// iterate's (z_{n+1}, e_{n+1}) to Context::ctrl. d tau / d alpha = -(kp + ki h/2). Saturated:
// tau = +-limit, no tangent, and the integral holds (z_{n+1} = z_n) while integrating would
// push further into saturation (conditional integration: anti-windup).
//
// On abelian joints alpha are the relative coordinates of Eq. (60) (d alpha = d n_j), so the
// tangent is diag(cK (K + kp) + cC (C + kd)) (Eqs. (63), (65)). On non-abelian joints springs
// act on the log coordinates alpha = A^+ log(H_J0^-1 H_J) through g = T_A(alpha)^-T K (alpha -
// alpha0), T_A = A^+ T(A alpha) A (T of Eqs. (21)-(22) maps the subalgebra spanned by A to
// itself, so T_A is its restriction and A^+ T(A alpha)^-1 A = T_A^-1). Exact tangent: the
// unknowns n_j move the joint frame by H_J = H_Jn exp(A n_j) (Eq. (38)), so by Eqs. (23), (27)
//   d alpha = T_A^-1 A^+ T(A n_j) A d n_j,
// and, with f = K (alpha - alpha0), y = T_A^-T f and d(T_A^-T) f = -T_A^-T d(T_A^T) y,
//   dg = T_A^-T (K - G) d alpha,  G = d(T_A^T y)/d alpha at fixed y = A^T DTt(A alpha, A^+T y) A,
// DTt(x, p) = d(T(x)^T p)/dx (dtt_apply, lie.hpp). The G term is the non-abelian part: it
// vanishes with y (no spring load) and is O(|alpha| |y|).
#pragma once
#include <vector>

#include "context.hpp"

namespace se3dyn {

struct JointForces : ElementBatch {
  std::vector<int> f;                       // (n,) joint frame
  std::vector<double> K, ref, C, kp, kd;    // (n, 6), first k used
  std::vector<double> ki, lim;              // (n, 6) PID integral gains, output limits (inf)
  std::vector<double> Ja;                   // (n, 6) armature: inertia on the coordinates
  std::vector<double> ts;                   // (n, 6) sample time of a sampled PID law, or 0
  std::vector<int> lidx;                    // (n,) the user's law: its offset in Context::law
  // (n, 6) the sensor a sampled PID law reads instead of its coordinate (se3dyn.model.sensors):
  // kind 0 none, 1 a marker's position component, 2 the distance of two markers, 3 a joint
  // coordinate; sidx the axis or the joint unknown; snode (n, 6, 2) the markers' node frames,
  // spoint (n, 6, 2, 3) their origins in the nodes' material frames
  std::vector<int> skind, sidx, snode;
  std::vector<double> spoint;
  std::vector<int> zslot, zidx;             // (n,) PID: first input slot (3 per coordinate:
                                            // z_n, e_n, h/2) and first state index, or -1
  std::vector<int> tau, pref, prate;        // (n,) first input slot (k consecutive) or -1
  std::vector<char> nonab;                  // (n,) spring on a non-abelian joint
  std::vector<double> Apinv;                // (n, 6, 6) A^+ (k x 6, ld 6)
  std::vector<double> A;                    // (n, 6, 6) A (6 x k, ld 6)
  std::vector<long> off;                    // (n,) block (f, f)

  // T_A(alpha) = A^+ T(A alpha) A (k x k, ld 6)
  void TA(int e, int k, const double* alpha, double* out) const {
    double nA[6] = {0}, T6[36], TA6[36];
    const double* Ae = &A[36 * e];
    for (int i = 0; i < 6; ++i)
      for (int c = 0; c < k; ++c) nA[i] += Ae[6 * i + c] * alpha[c];
    Frame E;
    exp_tangent_se3(nA, E, T6);
    cols_times(6, k, T6, Ae, TA6);
    for (int i = 0; i < k; ++i)
      for (int c = 0; c < k; ++c) {
        double s = 0.0;
        for (int l = 0; l < 6; ++l) s += Apinv[36 * e + 6 * i + l] * TA6[6 * l + c];
        out[6 * i + c] = s;
      }
  }

  void load(const Tables& t) override {
    f = t.ints<int>("frame");
    n = static_cast<int>(f.size());
    K = t.real("K");
    ref = t.real("ref");
    C = t.real("C");
    kp = t.real("kp");
    kd = t.real("kd");
    ki = t.real("ki");
    lim = t.real("lim");
    Ja = t.real("Ja");
    ts = t.real("ts");
    zslot = t.ints<int>("zslot");
    zidx = t.ints<int>("zidx");
    lidx = t.ints<int>("lidx");
    skind = t.ints<int>("skind");
    sidx = t.ints<int>("sidx");
    snode = t.ints<int>("snode");
    spoint = t.real("spoint");
    tau = t.ints<int>("tau");
    pref = t.ints<int>("pref");
    prate = t.ints<int>("prate");
    nonab = t.ints<char>("nonab");
    Apinv = t.real("Apinv");
    A = t.real("A");
    off = t.integer("off");
  }

  void frames_of(int e, std::vector<int>& out) const override { out = {f[e]}; }

  void eval(Context& X, bool, Span span) const override {
    const FrameTables& T = *X.T;
    for (int e = span.first; e < span.last; ++e) {
      int fr = f[e], k = T.k[fr], d = T.dof[fr];
      const double* al = X.coords + d;
      const double* v = X.vq + d;
      double fs[6], g[6], tpd[6], wk[6], wd[6];  // (wk, wd: the control law's tangent gains)
      for (int c = 0; c < k; ++c) fs[c] = K[6 * e + c] * (al[c] - ref[6 * e + c]);
      double TAi[36];
      if (nonab[e]) {
        // g = T_A^-T K (alpha - alpha0): solve T_A^T y = fs
        double TAm[36];
        TA(e, k, al, TAm);
        invert(k, TAm, TAi);
        double y[6];
        for (int i = 0; i < k; ++i) {
          y[i] = 0.0;
          for (int c = 0; c < k; ++c) y[i] += TAi[6 * c + i] * fs[c];
        }
        for (int c = 0; c < k; ++c) fs[c] = y[c];
      }
      for (int c = 0; c < k; ++c) {
        double pd = 0.0;
        if (pref[e] >= 0) pd -= kp[6 * e + c] * (al[c] - X.u[pref[e] + c]);
        if (prate[e] >= 0) pd -= kd[6 * e + c] * (v[c] - X.u[prate[e] + c]);
        else pd -= kd[6 * e + c] * v[c];
        wk[c] = kp[6 * e + c];
        wd[c] = kd[6 * e + c];
        if (zslot[e] >= 0) pd = pid(X, e, c, al[c], pd, wk, wd);
        double ta = tau[e] >= 0 ? X.u[tau[e] + c] : 0.0;
        if (lidx[e] >= 0 && X.law) ta += X.law[lidx[e] + c];  // (the user's law f(t, q, v))
        tpd[c] = ta + pd;
        g[c] = fs[c] + C[6 * e + c] * v[c] - tpd[c] + Ja[6 * e + c] * X.vdq[d + c];
        X.r[d + c] += g[c];
      }
      X.scale(g, k);
      X.scale(tpd, k);
      {  // round-off floor (ROUNDOFF_SCALE, context.hpp): K alpha - K alpha0, kp alpha - kp target
        double floor = 0.0;
        for (int c = 0; c < k; ++c) {
          double a = std::fabs(al[c]);
          floor = std::fmax(floor, K[6 * e + c] * (a + std::fabs(ref[6 * e + c])));
          if (pref[e] >= 0)
            floor = std::fmax(floor, kp[6 * e + c] * (a + std::fabs(X.u[pref[e] + c])));
        }
        floor *= ROUNDOFF_SCALE;
        X.scale(&floor, 1);
      }
      if (X.energy) {
        for (int c = 0; c < k; ++c) {
          double dl = al[c] - ref[6 * e + c];
          X.energy[ELASTIC] += 0.5 * K[6 * e + c] * dl * dl;
          X.energy[P_ACTUATOR] += tpd[c] * v[c];
          X.energy[P_DISSIPATION] += C[6 * e + c] * v[c] * v[c];
          X.energy[KINETIC] += 0.5 * Ja[6 * e + c] * v[c] * v[c];
        }
      }
      if (!X.vals || off[e] < 0) continue;
      double Bk[36] = {0}, Bc[36] = {0};
      for (int c = 0; c < k; ++c) {
        Bk[7 * c] = X.cK * (K[6 * e + c] + wk[c]);
        Bc[7 * c] = X.cC * (C[6 * e + c] + wd[c]);
      }
      if (nonab[e]) {
        // Bk = cK [T_A^-T (K - G) + diag(kp)] J, J = d alpha / d n_j = T_A^-1 A^+ T(A n_j) A
        // (the header; fs holds y = T_A^-T K (alpha - alpha0) here)
        const double* Ae = &A[36 * e];
        const double* Ap = &Apinv[36 * e];
        const double* TAJ = &X.S->TA[36 * fr];
        double TAn[36], J[36], nA[6] = {0}, p[6] = {0}, Dt[36], DA[36], G[36], KG[36], M[36];
        prod6(k, 6, k, Ap, false, TAJ, false, TAn);  // A^+ T(A n_j) A
        prod6(k, k, k, TAi, false, TAn, false, J);
        // G = A^T DTt(A alpha, A^+T y) A
        for (int i = 0; i < 6; ++i)
          for (int c = 0; c < k; ++c) {
            nA[i] += Ae[6 * i + c] * al[c];
            p[i] += Ap[6 * c + i] * fs[c];
          }
        dtt_apply(nA, p, Dt);
        cols_times(6, k, Dt, Ae, DA);
        prod6(k, 6, k, Ae, true, DA, false, G);
        // M = T_A^-T (K - G) + diag(kp)
        for (int i = 0; i < k; ++i)
          for (int c = 0; c < k; ++c) KG[6 * i + c] = (i == c ? K[6 * e + c] : 0.0) - G[6 * i + c];
        prod6(k, k, k, TAi, true, KG, false, M);
        for (int c = 0; c < k; ++c) M[7 * c] += wk[c];
        prod6(k, k, k, M, false, J, false, Bk);
        for (int i = 0; i < k; ++i)
          for (int c = 0; c < k; ++c) Bk[6 * i + c] *= X.cK;
      }
      for (int c = 0; c < k; ++c) Bc[7 * c] += X.cM * Ja[6 * e + c];  // (velocity level)
      if (lidx[e] >= 0 && X.law) {  // the user's law: -d f / d q, -d f / d v (k x k)
        const double* Jq = X.law + lidx[e] + k;
        const double* Jv = Jq + k * k;
        for (int i = 0; i < k; ++i)
          for (int c = 0; c < k; ++c) {
            Bk[6 * i + c] -= X.cK * Jq[k * i + c];
            Bc[6 * i + c] -= X.cC * Jv[k * i + c];
          }
      }
      double Bt[36];
      for (int i = 0; i < 36; ++i) Bt[i] = Bk[i] + Bc[i];
      add_block(X.vals, off[e], k, k, Bt, 1.0);
      if (double* V = X.vel(off[e])) add_block(V, 0, k, k, Bc, 1.0);
    }
  }

  // The PID law of coordinate c of element e (the header): its force from the PD part `pd`,
  // the tangent gains wk (d/d alpha) and wd (d/d v) set, (z_{n+1}, e_{n+1}) to X.ctrl
  double pid(Context& X, int e, int c, double alpha, double pd, double* wk, double* wd) const {
    const double* zs = X.u + zslot[e] + 3 * c;  // z_n, e_n, h/2
    const double err = alpha - X.u[pref[e] + c];
    const double gi = ki[6 * e + c], L = lim[6 * e + c];
    if (ts[6 * e + c] > 0) {
      double es = err;
      if (skind[6 * e + c]) pd = sensor_law(X, e, c, es);
      return sampled(X, e, c, es, pd, wk, wd);
    }
    double z = zs[0] + zs[2] * (zs[1] + err);
    double out = pd - gi * z;
    wk[c] += gi * zs[2];
    if (std::fabs(out) > L) {
      if (-gi * zs[2] * (zs[1] + err) * out > 0) z = zs[0];  // (anti-windup)
      out = out > 0 ? L : -L;
      wk[c] = wd[c] = 0.0;
    }
    if (X.ctrl) {
      X.ctrl[2 * (zidx[e] + c)] = z;
      X.ctrl[2 * (zidx[e] + c) + 1] = err;
    }
    return out;
  }

  // A sampled PID law (the header of se3dyn.model.specs.PID): the output held over the step,
  // u_hold (no tangent); at a sample time t_{n+1} = k T the law of the iterate's state, held
  // from the next step on: I_k = I_(k-1) + T e_k, u_k = sat(-kp e_k - ki I_k - kd e'_k), the
  // sum held while saturated outward (anti-windup). State slots: u_hold, I, t_{n+1}.
  double sampled(Context& X, int e, int c, double err, double pd, double* wk,
                 double* wd) const {
    const double* zs = X.u + zslot[e] + 3 * c;
    const double T = ts[6 * e + c], gi = ki[6 * e + c], L = lim[6 * e + c];
    wk[c] = wd[c] = 0.0;
    const double t1 = zs[2], k = std::round(t1 / T);
    double u = zs[0], I = zs[1];
    if (std::fabs(t1 - k * T) <= 1e-9 * std::fmax(T, std::fabs(t1))) {
      double In = I + T * err, out = pd - gi * In;
      if (std::fabs(out) > L) {
        if (-gi * T * err * out > 0) In = I;
        out = out > 0 ? L : -L;
      }
      u = out;
      I = In;
    }
    if (X.ctrl) {
      X.ctrl[2 * (zidx[e] + c)] = u;
      X.ctrl[2 * (zidx[e] + c) + 1] = I;
    }
    return zs[0];
  }

  // A sampled law reading a sensor s (the header's skind): err = s - target, and its PD part
  // -kp err - kd (s' - target_rate) returned. The sensor comes from the iterate's frames and
  // velocities (read only: no tangent, the law being sampled)
  double sensor_law(Context& X, int e, int c, double& err) const {
    const int i = 6 * e + c, kind = skind[i];
    double s = 0.0, sd = 0.0;
    if (kind == 3) {
      s = X.coords[sidx[i]];
      sd = X.vq[sidx[i]];
    } else {
      double p[2][3], pd[2][3];
      for (int m = 0; m < kind; ++m) marker_point(X, snode[2 * i + m], &spoint[6 * i + 3 * m],
                                                  p[m], pd[m]);
      if (kind == 1) {
        s = p[0][sidx[i]];
        sd = pd[0][sidx[i]];
      } else {
        double d[3], dd[3];
        for (int a = 0; a < 3; ++a) {
          d[a] = p[1][a] - p[0][a];
          dd[a] = pd[1][a] - pd[0][a];
        }
        s = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        sd = s > 0 ? (d[0] * dd[0] + d[1] * dd[1] + d[2] * dd[2]) / s : 0.0;
      }
    }
    err = s - X.u[pref[e] + c];
    const double rate = prate[e] >= 0 ? X.u[prate[e] + c] : 0.0;
    return -kp[i] * err - kd[i] * (sd - rate);
  }

  // A point a (material frame of node frame f) in the inertial frame, x + R a, and its
  // velocity R (U + Omega x a) (Eq. (4): material velocities (U, Omega))
  static void marker_point(const Context& X, int f, const double* a, double* p, double* pd) {
    const Frame& H = X.S->H[f];
    const double* v = &X.S->v[6 * f];
    const double w[3] = {v[1 + 3] * a[2] - v[2 + 3] * a[1] + v[0],
                         v[2 + 3] * a[0] - v[0 + 3] * a[2] + v[1],
                         v[0 + 3] * a[1] - v[1 + 3] * a[0] + v[2]};
    for (int r = 0; r < 3; ++r) {
      p[r] = H.x[r];
      pd[r] = 0.0;
      for (int k = 0; k < 3; ++k) {
        p[r] += H.R[3 * r + k] * a[k];
        pd[r] += H.R[3 * r + k] * w[k];
      }
    }
  }

  // Gauss-Jordan inverse of a k x k matrix (ld 6) with partial pivoting
  static void invert(int k, const double* A, double* Ai) {
    double M[36], I[36] = {0};
    for (int i = 0; i < 36; ++i) M[i] = A[i];
    for (int i = 0; i < k; ++i) I[7 * i] = 1.0;
    for (int c = 0; c < k; ++c) {
      int p = c;
      for (int i = c + 1; i < k; ++i)
        if (std::fabs(M[6 * i + c]) > std::fabs(M[6 * p + c])) p = i;
      for (int j = 0; j < 6; ++j) {
        std::swap(M[6 * c + j], M[6 * p + j]);
        std::swap(I[6 * c + j], I[6 * p + j]);
      }
      double piv = M[6 * c + c];
      for (int j = 0; j < 6; ++j) { M[6 * c + j] /= piv; I[6 * c + j] /= piv; }
      for (int i = 0; i < k; ++i) {
        if (i == c) continue;
        double fct = M[6 * i + c];
        for (int j = 0; j < 6; ++j) { M[6 * i + j] -= fct * M[6 * c + j]; I[6 * i + j] -= fct * I[6 * c + j]; }
      }
    }
    for (int i = 0; i < 36; ++i) Ai[i] = I[i];
  }
};

}  // namespace se3dyn
