// One generalized-alpha step on the Lie group (Eqs. (38)-(46)) with Newton iterations on the
// increments, in the paper's index-3 form or the stabilised index-2 form; written once for
// fixed-step, adaptive, streamed and statics-free runs alike.
//
// Unknowns of Newton: the increment n (nq), the scaled multipliers lambda / beta' (nm) and for
// index 2 xi (nm). Rows: dynamics / beta' (Eq. (39)), constraints (Eq. (40)) and for index 2
// velocity constraints / gamma'; every block is O(1) whatever h. Velocities and accelerations
// follow m = n - B_n^T xi: dv = gamma' dm, dvd = beta' dm (Eqs. (41)-(43)).
//
// Modified Newton: the matrix is factorised at the predictor of every step (vd_{n+1} = vd_n)
// and kept over the step's iterations while Newton contracts fast enough; it is refactorised at
// the current iterate when the scaled residual or constraint error grows, when the contraction
// rate reaches 0.9, or when more than kmax further iterations are predicted at that rate.
#pragma once
#include <cmath>
#include <vector>

#include "engine.hpp"

namespace se3dyn {

enum StepStatus { CONVERGED = 0, NONFINITE = 1, MAXITER = 2, DIVERGING = 3, SINGULAR = 4 };

struct StepInfo {
  int iterations = 0, factorisations = 0, status = 0;
  double residual = 0, constraint = 0;
};

struct Stepper {
  Engine* E;
  bool index2;
  int N = 0;                         // size of the linear system
  std::vector<int> perm;             // value index -> CSC position (nnz fits an int: colptr)
  std::vector<long> zero_at, one_at; // CSC positions of dropped equations: zero, or 1 (diagonal)
  std::vector<char> dropm;           // (nm,) dropped multiplier equations
  SparseLU lu;
  bool analysed = false;
  std::vector<double> vals, csc, rhs, r, phi, psi;

  void init(Engine* e, bool idx2, int n_sys, const int* colptr, const int* rowind,
            const long* perm_, long nv, const int* group, const char* drop) {
    E = e;
    index2 = idx2;
    N = n_sys;
    perm.assign(perm_, perm_ + nv);
    long nnz = colptr[N];
    dropm.assign(drop, drop + E->nm);
    std::vector<char> dropped(N, 0);
    for (int i = 0; i < E->nm; ++i)
      if (dropm[i]) {
        dropped[E->nq + i] = 1;
        if (index2) dropped[E->nq + E->nm + i] = 1;
      }
    for (int c = 0; c < N; ++c)
      for (int p = colptr[c]; p < colptr[c + 1]; ++p) {
        int rw = rowind[p];
        if (dropped[rw] || dropped[c]) (rw == c ? one_at : zero_at).push_back(p);
      }
    // pattern entries that are zero at every step (a third to two thirds of the engine's) are
    // left out of the factors; a refactorisation that meets one of them nonzero reports it and
    // the step factorises afresh (factor())
    SparseLU::Options opt;
    opt.drop_zeros = true;
    lu.set_options(opt);
    lu.analyze(N, colptr, rowind, group);
    vals.assign(nv, 0.0);
    csc.assign(nnz, 0.0);
    rhs.assign(N, 0.0);
    r.assign(E->nq, 0.0);
    phi.assign(E->nm, 0.0);
    psi.assign(E->nm, 0.0);
  }

  int factor() {
    for (size_t i = 0; i < vals.size(); ++i) csc[perm[i]] = vals[i];
    for (long p : zero_at) csc[p] = 0.0;  // dropped (redundant) equations: identity rows/cols
    for (long p : one_at) csc[p] = 1.0;
    int code = analysed ? lu.refactor(csc.data()) : 1;
    if (code != 0) {
      code = lu.factor(csc.data());
      analysed = code == 0;
    }
    return code;
  }

  struct Params {
    double h, am, af, g, b, tol_r, ltol, lscale, kmax;
    int max_iter;
    bool reuse;
  };

  // State at t_n in (frames loaded in E->Hn, alpha_n, v_n, vd_n, a_n rescaled to h, lam_n),
  // inputs u at t_{n+1}; state at t_{n+1} out (frames in E->S.H).
  StepInfo step(const Params& P, const double* alpha_n, const double* v_n, const double* vd_n,
                const double* a_n, const double* lam_n, const double* u, double* alpha,
                double* v, double* vd, double* a, double* lam, double* n) {
    Engine& G = *E;
    int nq = G.nq, nm = G.nm;
    bool stab = index2 && nm > 0;
    double h = P.h, am = P.am, af = P.af, g = P.g, b = P.b;
    for (int i = 0; i < nq; ++i) {
      vd[i] = vd_n[i];
      a[i] = (vd_n[i] - am * a_n[i]) / (1 - am);
      v[i] = v_n[i] + h * (1 - g) * a_n[i] + h * g * a[i];
      n[i] = h * v_n[i] + h * h * (0.5 - b) * a_n[i] + h * h * b * a[i];
    }
    for (int i = 0; i < nm; ++i) lam[i] = lam_n[i];
    double bp = (1 - am) / (b * h * h * (1 - af));
    double gp = g / (b * h);
    double cM = 1.0, cC = gp / bp, cK = 1.0 / bp, cv = 1.0 / gp;
    StepInfo info;
    int it = 0;
    double er0 = 1.0, er = 0.0, ep = 0.0, dn_prev = 0.0;
    double ec_prev = std::numeric_limits<double>::infinity();
    bool refac = true;
    auto measure = [&](double fs) {
      fs = std::fmax(fs, 1e-300);
      er = 0.0;
      for (int i = 0; i < nq; ++i) er = std::fmax(er, std::fabs(r[i]));
      er /= fs;
      ep = 0.0;
      for (int i = 0; i < nm; ++i) ep = std::fmax(ep, std::fabs(phi[i]));
      if (stab)
        for (int i = 0; i < nm; ++i) ep = std::fmax(ep, std::fabs(psi[i]) / gp);
    };
    Engine::Out o{r.data(), phi.data(), stab ? psi.data() : nullptr, alpha, nullptr, nullptr};
    while (true) {
      bool with_matrix = refac || !P.reuse;  // the matrix is evaluated with the residual
      o.vals = with_matrix ? vals.data() : nullptr;
      double fs = G.evaluate(alpha_n, n, v, vd, lam, u, cM, cC, cK, stab, cv, false, o);
      o.vals = nullptr;
      measure(fs);
      if (!(std::isfinite(er) && std::isfinite(ep))) { info.status = NONFINITE; break; }
      if (er <= P.tol_r && ep <= P.ltol) break;
      if (it >= P.max_iter) { info.status = MAXITER; break; }
      if (it >= 3 && (ep > 10.0 * P.lscale || er > 1e3 * std::fmax(er0, 1.0))) {
        info.status = DIVERGING;
        break;
      }
      if (it == 0) er0 = er;
      double ec = nm > 0 ? std::fmax(er / P.tol_r, ep / P.ltol) : er / P.tol_r;
      if (ec > ec_prev) refac = true;
      ec_prev = ec;
      if (refac || !P.reuse) {
        if (!with_matrix) {
          o.vals = vals.data();
          G.evaluate(alpha_n, n, v, vd, lam, u, cM, cC, cK, stab, cv, false, o);
          o.vals = nullptr;
        }
        info.factorisations++;
        if (factor() != 0) { info.status = SINGULAR; break; }
        refac = false;
      }
      for (int i = 0; i < nq; ++i) rhs[i] = -r[i] / bp;
      for (int i = 0; i < nm; ++i) {
        rhs[nq + i] = dropm[i] ? 0.0 : -phi[i];
        if (stab) rhs[nq + nm + i] = dropm[i] ? 0.0 : -psi[i] / gp;
      }
      lu.solve(rhs.data());
      double dnmax = 0.0, nmax = 0.0;
      for (int i = 0; i < nq; ++i) {
        n[i] += rhs[i];
        dnmax = std::fmax(dnmax, std::fabs(rhs[i]));
        nmax = std::fmax(nmax, std::fabs(n[i]));
      }
      if (stab) G.subtract_BnT(rhs.data() + nq + nm, rhs.data());  // dm = dn - B_n^T xi
      for (int i = 0; i < nq; ++i) {
        v[i] += gp * rhs[i];
        vd[i] += bp * rhs[i];
      }
      for (int i = 0; i < nm; ++i) lam[i] += bp * rhs[nq + i];
      ++it;
      if (dn_prev > 0 && dnmax > 1e-12 * nmax) {
        double theta = dnmax / dn_prev;
        if (theta >= 0.9) refac = true;
        else if (theta > 1e-3) {
          double lt = std::log(theta);
          double k_rem = std::log(P.tol_r / std::fmax(er * theta, P.tol_r)) / lt;
          if (nm > 0) k_rem = std::fmax(k_rem, std::log(P.ltol / std::fmax(ep * theta, P.ltol)) / lt);
          if (k_rem > P.kmax) refac = true;
        }
      }
      dn_prev = dnmax;
      if (ep <= P.ltol && dnmax <= 4e-16 * std::fmax(nmax, 1e-300)) {
        double fs2 = G.evaluate(alpha_n, n, v, vd, lam, u, cM, cC, cK, stab, cv, false, o);
        measure(fs2);
        break;
      }
    }
    info.iterations = it;
    info.residual = er;
    info.constraint = ep;
    if (info.status == CONVERGED) {
      double c1 = (1 - af) / (1 - am);
      for (int i = 0; i < nq; ++i) a[i] += c1 * (vd[i] - vd_n[i]);
      G.coordinates(alpha_n, n, alpha, true);  // log coordinates of non-abelian joints too
    }
    return info;
  }

  // Rows of stored results (the recorder of se3dyn.simulate), written by run()
  struct Rows {
    long cap = 0, count = 0;
    int M = 0;
    double *t, *H, *v, *vd, *lam, *alpha, *scal;  // (cap,), (cap, M, 16), ..., (cap, 9)
  };
  // The integration state carried between steps: frames (F, 16), alpha, v, vd, a, lam and
  // acc = (powers p_act, p_ext, p_diss, works W_act, W_ext, dissipated, h_last, t)
  struct Carry {
    double *H, *alpha, *v, *vd, *a, *lam, *acc;
  };
  struct RunResult {
    int status = 0, done = 0, iterations = 0, factorisations = 0;
    double residual = 0, constraint = 0;
  };

  // Fixed-step loop over steps i0 <= i < i1 to the times[i], inputs U (nsteps, nu); stores
  // every output_every-th state (and the last one, i = last) into rows. Energies, powers
  // (trapezoidal works) and log coordinates of the stored states are computed here too. On a
  // failing step, returns its status with the carry at the last converged state.
  RunResult run(Params P, const double* times, int i0, int i1, int last, const double* U,
                int output_every, Carry c, Rows& rows) {
    Engine& G = *E;
    int nq = G.nq, nm = G.nm, F = G.T.F, nu = G.nu;
    std::vector<double> alpha(nq), v(nq), vd(nq), a(nq), lam(nm), n(nq), a_n(nq), zero(nq, 0.0);
    std::vector<double> er(nq), ep(nm), ev(nm), en(N_ENERGY);
    RunResult R;
    for (int i = i0; i < i1; ++i) {
      double t1 = times[i], h = t1 - c.acc[7], h_last = c.acc[6];
      const double* u = U + (long)i * nu;
      for (int q = 0; q < nq; ++q)
        a_n[q] = (h_last > 0 && h != h_last) ? c.vd[q] + (h / h_last) * (c.a[q] - c.vd[q]) : c.a[q];
      G.load_frames(c.H);
      P.h = h;
      StepInfo info = step(P, c.alpha, c.v, c.vd, a_n.data(), c.lam, u, alpha.data(), v.data(),
                           vd.data(), a.data(), lam.data(), n.data());
      R.iterations += info.iterations;
      R.factorisations += info.factorisations;
      if (info.status != CONVERGED) {
        R.status = info.status;
        R.done = i;
        return R;
      }
      R.residual = info.residual;
      R.constraint = info.constraint;
      for (int f = 0; f < F; ++f) frame_to4(G.S.H[f], c.H + 16 * f);
      // energies and powers of the new state (its frames as the step start, n = 0)
      G.load_frames(c.H);
      Engine::Out o{er.data(), ep.data(), nullptr, alpha.data(), nullptr, en.data()};
      G.evaluate(alpha.data(), zero.data(), v.data(), zero.data(), lam.data(), u, 0, 0, 0, false,
                 0, false, o);
      for (int k = 0; k < 3; ++k) {
        c.acc[3 + k] += 0.5 * h * (c.acc[k] + en[P_ACTUATOR + k]);
        c.acc[k] = en[P_ACTUATOR + k];
      }
      c.acc[6] = h;
      c.acc[7] = t1;
      std::copy(alpha.begin(), alpha.end(), c.alpha);
      std::copy(v.begin(), v.end(), c.v);
      std::copy(vd.begin(), vd.end(), c.vd);
      std::copy(a.begin(), a.end(), c.a);
      std::copy(lam.begin(), lam.end(), c.lam);
      if (((i + 1) % output_every == 0 || i == last) && rows.count < rows.cap) {
        long r = rows.count++;
        rows.t[r] = t1;
        std::copy(c.H, c.H + 16L * rows.M, rows.H + r * 16L * rows.M);
        std::copy(v.begin(), v.end(), rows.v + r * nq);
        std::copy(vd.begin(), vd.end(), rows.vd + r * nq);
        std::copy(lam.begin(), lam.end(), rows.lam + r * nm);
        std::copy(alpha.begin(), alpha.end(), rows.alpha + r * nq);
        double* sc = rows.scal + 9 * r;
        sc[0] = en[KINETIC];
        sc[1] = en[POTENTIAL];
        sc[2] = en[ELASTIC];
        sc[3] = c.acc[3];
        sc[4] = c.acc[4];
        sc[5] = c.acc[5];
        sc[6] = info.iterations;
        sc[7] = info.residual;
        sc[8] = info.constraint;
      }
      R.done = i + 1;
    }
    return R;
  }
};

}  // namespace se3dyn
