// One generalized-alpha step on the Lie group (Eqs. (38)-(46)) with Newton iterations on the
// increments, in the paper's index-3 form or the stabilised index-2 form; written once for
// fixed-step, adaptive, streamed and statics-free runs alike.
//
// Unknowns of Newton: the increment n (nq), the scaled multipliers lambda / beta' (nm) and for
// index 2 xi (nm). Rows: dynamics / beta' (Eq. (39)), constraints (Eq. (40)) and for index 2
// velocity constraints / gamma'; every block is O(1) whatever h. Velocities and accelerations
// follow m = n - B_n^T xi: dv = gamma' dm, dvd = beta' dm (Eqs. (41)-(43)).
//
// Split index-2 iteration matrix. With m = n - B_n^T xi (the increment the velocities and
// accelerations follow) as unknown instead of n, the Newton matrix of the stabilised index-2
// form reads, rows dynamics, constraints, velocity constraints:
//     [ S          Phi_q^T   cK K_T T B_n^T     ] [dm ]
//     [ Phi_q T    0         Phi_q T B_n^T      ] [dl ]
//     [ B + cv Z   0         cv Z B_n^T         ] [dxi]
// (S = cM M + cC C_T + cK K_T T, B = Phi_q, Z = d(B v)/dq T). The stepper iterates with its
// block-triangular part, Phi_q T taken as B in the dm columns and as B_n in the dxi ones (equal
// up to O(|n|) and O(|phi|)): (dm, dl) solve [S Phi_q^T; B + cv Z 0], the index-3 matrix with
// the velocity constraints' rows (its pattern), then dxi solves B_n B_n^T dxi = -phi - B dm
// (nm x nm, symmetric positive definite, coupling the joints that share a frame: a sparse
// LDL^T, sparse_ldlt.hpp; B of the matrix's iterate, B_n of the step's start), and dn = dm +
// B_n^T dxi. Only the iteration matrix changes (as modified Newton changes it anyway): the
// residuals are exact, so the converged step is the same. The omitted blocks are O(h^2 K) and
// O(h |v|) against the kept ones
// (spectral radius of the iteration's error map, measured at h = 1 ms: 2e-4 to 2e-2 on the 30-
// to 1000-link chains, 4e-3 to 2e-5 on the slider-crank and the gallery; docs/performance.md).
// In m the round-off of the positions (Phi of frames 100 m from the origin) stays out of the
// velocities: with n as unknown and the dynamic rows' xi block left out instead, Newton stalled
// at a residual of 2e-10 on the 300-link chain (the noise of xi times beta' in the dynamic
// rows). Why split: the full matrix couples, through its xi columns, every pair of joints that
// share a body, doubling the separator of a link in the elimination (4.7-6.1 times the
// multiply-adds of index 3). The price: no quadratic first iteration (1.6-3.9 iterations per
// step on the gallery and the chains where the full matrix takes 1.0-2.9, still 0.6-0.8 times
// the CPU time), and a contraction that grows with h^2 K / M (stiff elements: beams, bushings)
// and h |v|. So when a split iteration contracts too slowly to converge within KSPLIT more
// iterations, or its residual grows, the stepper goes over to the full matrix (luf) for the
// rest of the step and of the run: the mode is part of the solver memory (the last entry of an
// index-2 memory, 1 for the full matrix), so a State restarts in the mode its run was in and
// restarts stay exact; a run from a new State starts split. Full Newton (a factorisation at
// every iteration) never splits.
//
// Modified Newton: the matrix is factorised at the predictor of every step (vd_{n+1} = vd_n)
// and kept over the step's iterations while Newton contracts fast enough; it is refactorised at
// the current iterate when the scaled residual or constraint error grows, when the contraction
// rate reaches 0.9, or when more than kmax further iterations are predicted at that rate.
// (Factors carried over to later steps were tried: the iteration matrix of a step one step
// earlier contracts at rates of about 0.3 on the slider-crank and the 1000-link chain, so the
// extra iterations cost what the saved factorisations did; docs/design.md.)
//
// Everything later numbers depend on is a function of the model and of the integration state
// (the Python State, its SolverMemory included), so that a run restarted from a State, in this
// process or another one, continues bit for bit: the ordering and the patterns of the sparse LU
// come from a generic matrix of the model (probe()), not from the values the run happened to
// start with, and refactorisations reuse the pivot sequence of the last full factorisation:
// first that of the generic matrix (a function of the model: nothing to keep), after a
// refactorisation failed (a pivot fallen too small) that of a run's matrix, whose values are
// then the solver's memory.
#pragma once
#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <memory>
#include <stdexcept>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "engine.hpp"
#include "sparse_ldlt.hpp"

namespace se3dyn {

// max |x_i|, NaN if some x_i is NaN
inline double amax_nan(const double* x, int n) {
  double m = 0.0;
  bool nan = false;
  for (int i = 0; i < n; ++i) {
    double a = std::fabs(x[i]);
    m = a > m ? a : m;
    nan |= a != a;
  }
  return nan ? std::numeric_limits<double>::quiet_NaN() : m;
}

enum StepStatus { CONVERGED = 0, NONFINITE = 1, MAXITER = 2, DIVERGING = 3, SINGULAR = 4 };

struct StepInfo {
  int iterations = 0, factorisations = 0, status = 0;
  double residual = 0, constraint = 0;
};

struct Stepper {
  Engine* E;
  bool index2;
  int N = 0;                         // size of the linear system
  // split index-2 iteration matrix (see the header): lu holds the (dm, dl) block (rows:
  // dynamics, then per multiplier its velocity constraint, or for a dropped equation its
  // constraint row, the identity), lux the xi block -B_n B_n^T (in the velocity constraints'
  // rows of the values; negative definite, a dropped equation's row and column the identity's:
  // an LDL^T with those pivot signs, no pivot sequence, so nothing of it in the solver memory)
  bool split = false;
  int N1 = 0;
  SparseLDLT lux;
  SparseLU luf;            // split: the full matrix, once the split contracted too slowly
  bool full_mode = false;  // split: iterating with the full matrix (part of the memory)
  bool factored_full = false;  // the mode of the last successful factorisation
  // split: luf is analysed when first needed (ensure_luf), from the full matrix's pattern
  // (full_pattern: colptr, rowind, src) and the groups of its unknowns
  bool luf_ready = false;
  std::function<void(std::vector<int>&, std::vector<int>&, std::vector<int>&)> full_pattern;
  std::vector<int> full_groups;
  long full_steps = 0;     // steps done with the full matrix (counted over the stepper's life)
  static constexpr double KSPLIT = 6.0;  // (header)
  std::vector<double> dm;  // (nq,)
  std::vector<int> zero_at, one_at;  // values of dropped equations: zero, or 1 (diagonal)
  std::vector<char> dropm;           // (nm,) dropped multiplier equations
  SparseLU lu;                       // reads vals in place (its value map)
  std::vector<double> vals, rhs, r, phi, psi;
  std::vector<double> energy = std::vector<double>(N_ENERGY);  // (N_ENERGY,) of the last iterate
  std::vector<double> effort;  // (nd,) the drivers' forces of the last iterate (take_efforts)
  std::vector<double> ctrl_out;  // (2 npid,) PID states (z, e) of the last iterate
  std::vector<double> cforce;    // (ncpl,) the couplings' forces on their followers
  // solver memory (see the header): the matrix values of the last full factorisation, the
  // reference of the refactorisations' pivot sequence (none kept while it is the generic
  // matrix's, ref_probe), and a serial number of it (Python side). Never changed once made:
  // the States that hold it share it (module.cpp, memory()).
  std::shared_ptr<const std::vector<double>> ref_vals;
  bool have_ref = false, ref_probe = false;
  long ref_serial = 0;

  // The pattern in CSC (colptr, rowind) and the value of each of its entries (src: index in
  // vals), all taken over by the sparse LU. reference: the generic matrix's factorisation is
  // the first reference of the refactorisations (the solver memory of a new run); false for a
  // one-off solve (solve_values: a full factorisation of its matrix, nothing kept). split:
  // full_pattern gives the full matrix's pattern again when it is needed (ensure_luf).
  void init(Engine* e, bool idx2, int n_sys, std::vector<int>&& colptr,
            std::vector<int>&& rowind, std::vector<int>&& src, const int* group,
            const char* drop, bool split_matrix = true, bool reference = true,
            std::function<void(std::vector<int>&, std::vector<int>&, std::vector<int>&)>
                pattern = nullptr) {
    E = e;
    index2 = idx2;
    N = n_sys;
    split = split_matrix && index2 && E->nm > 0;
    N1 = split ? E->nq + E->nm : N;
    const long nnz = colptr[N];
    dropm.assign(drop, drop + E->nm);
    std::vector<char> dropped(N, 0);
    for (int i = 0; i < E->nm; ++i)
      if (dropm[i]) {
        dropped[E->nq + i] = 1;
        if (index2) dropped[E->nq + E->nm + i] = 1;
      }
    // a driven unknown: its row and column the identity's (its value is the driver's: step());
    // a coupling's follower likewise (its value follows the leader's: follow())
    for (int i = 0; i < E->ndrive(); ++i) dropped[E->drive[Engine::DRIVE * i]] = 1;
    for (int b : E->cpl_follow) dropped[b] = 1;
    cforce.assign(E->ncpl(), 0.0);
    effort.assign(E->ndrive(), 0.0);
    ctrl_out.assign(E->nctrl(), 0.0);
    for (int c = 0; c < N; ++c)
      for (int p = colptr[c]; p < colptr[c + 1]; ++p) {
        int rw = rowind[p];
        if (dropped[rw] || dropped[c]) (rw == c ? one_at : zero_at).push_back(src[p]);
      }
    // pattern entries that are zero in every state (a third to two thirds of the engine's) are
    // left out of the factors: those zero in a generic matrix of the model (probe())
    SparseLU::Options opt;
    opt.drop_zeros = true;
    // refactorisations kept down to a pivot ratio of 1e-6 (the LU's default 1e-5 factorised
    // anew 31 times in the 1000 steps of the 1000-link chain's 1-s run, 87 times on the closed
    // 100-link chain, each factorisation ~6 refactorisations' time; with 1e-6: 4 and 16 times,
    // the same Newton iterations, largest backward error of the solves 1.9e-11 instead of
    // 5.1e-12 over the models measured; docs/performance.md)
    opt.refactor_tol = 1e-6;
    lu.set_options(opt);
    luf.set_options(opt);
    vals.assign(nnz, 0.0);
    rhs.assign(N, 0.0);
    dm.assign(index2 ? E->nq : 0, 0.0);
    r.assign(E->nq, 0.0);
    phi.assign(E->nm, 0.0);
    psi.assign(E->nm, 0.0);
    // the ordering and the entries kept in the factors' patterns from a generic matrix
    probe();
    set_dropped();
    if (!split) {
      std::vector<char> keep(nnz);
      for (long p = 0; p < nnz; ++p) keep[p] = vals[src[p]] != 0.0;  // NaN counts as nonzero
      lu.analyze(N, std::move(colptr), std::move(rowind), std::move(src), group, vals.data());
      lu.set_keep(keep.data());
    } else {
      const int nq = E->nq, nm = E->nm;
      // row r of the index-2 matrix in the (dm, dl) block: -1 where it is not there
      std::vector<int> rowmap(N, -1);
      for (int r = 0; r < nq; ++r) rowmap[r] = r;
      for (int i = 0; i < nm; ++i) rowmap[dropm[i] ? nq + i : N1 + i] = nq + i;
      std::vector<int> cp1{0}, ri1, s1, cpx{0}, rix, sx;
      for (int c = 0; c < N; ++c) {
        for (int p = colptr[c]; p < colptr[c + 1]; ++p) {
          int rw = rowind[p];
          if (c < N1 && rowmap[rw] >= 0) {
            ri1.push_back(rowmap[rw]);
            s1.push_back(src[p]);
          } else if (c >= N1 && rw >= N1) {
            rix.push_back(rw - N1);
            sx.push_back(src[p]);
          }
        }
        if (c < N1) cp1.push_back(int(ri1.size()));
        else cpx.push_back(int(rix.size()));
      }
      auto keep_of = [&](const std::vector<int>& sv) {
        std::vector<char> k(sv.size());
        for (size_t p = 0; p < sv.size(); ++p) k[p] = vals[sv[p]] != 0.0;
        return k;
      };
      std::vector<char> k1 = keep_of(s1), kx = keep_of(sx);
      // (the full matrix's LU: analysed by ensure_luf, when a run first needs it)
      full_pattern = std::move(pattern);
      if (!full_pattern) throw std::invalid_argument("split stepper: the full pattern's source");
      if (group) full_groups.assign(group, group + N);
      lu.analyze(N1, std::move(cp1), std::move(ri1), std::move(s1), group, vals.data());
      lu.set_keep(k1.data());
      // the xi block: the ordering of a SparseLU of its pattern, the entries zero in the
      // generic matrix left out of L, the lower triangle read. (The generic matrix is the full
      // one, with -B B_n^T there, B of the iterate, nonzero also where the split matrix's
      // -B_n B_n^T is zero only mathematically: products of orthogonal rows. Round-off
      // residues in the entries left out, measured up to 4e-17 of the largest entry of their
      // supernode's columns over the test suite, are zeros to factor by drop_tol; a larger
      // entry there is an error, kPatternChanged.) A pivot below pivot_tol of its diagonal
      // entry is round-off of a zero one (a numerically singular block: -2e-16 on a corrupted
      // model of the hostile-input tests), an error too; the runs of the test suite stay above
      // 8e-10 (the smallest at the singular positions of a mechanism, tests/test_adaptive.py).
      SparseLDLT::Options xopt;
      xopt.drop_zeros = true;
      xopt.drop_tol = 1e-12;
      xopt.pivot_tol = 1e-13;
      lux.set_options(xopt);
      lux.analyze(nm, std::move(cpx), std::move(rix), std::move(sx), group ? group + N1 : nullptr,
                  vals.data(), kx.data());
      std::vector<signed char> sign(nm);
      for (int i = 0; i < nm; ++i) sign[i] = dropm[i] ? 1 : -1;
      lux.set_signs(sign.data());
    }
    if (reference) probe_reference();
    // (the blocks the split matrix leaves alone stay zero: Engine::split_ranges)
    std::fill(vals.begin(), vals.end(), 0.0);
  }

  // Split: analyse the full matrix's LU (luf) if not done yet. Like every analysis, from the
  // generic matrix (probe()), so it is the same whenever a run first needs it: when the split
  // iteration falls back to the full matrix, or a State of a run in that mode is restored.
  // The engine's step-start frames and the residual arrays are kept; the matrix values are
  // the generic matrix's afterwards (the full matrix is evaluated before its factorisation).
  // A run that never falls back does not pay for it (10 ms at 1000 links, 0.18 s at 10^4).
  void ensure_luf() {
    if (!split || luf_ready) return;
    std::vector<int> cp, ri, src;
    full_pattern(cp, ri, src);
    std::vector<Frame> Hn = E->Hn;
    std::vector<double> r0 = r, phi0 = phi, psi0 = psi;
    probe();
    set_dropped();
    std::vector<char> kf(src.size());
    for (size_t p = 0; p < src.size(); ++p) kf[p] = vals[src[p]] != 0.0;
    luf.analyze(N, std::move(cp), std::move(ri), std::move(src),
                full_groups.empty() ? nullptr : full_groups.data(), vals.data());
    luf.set_keep(kf.data());
    // (copied back in place: the step holds pointers into these arrays)
    std::copy(Hn.begin(), Hn.end(), E->Hn.begin());
    std::copy(r0.begin(), r0.end(), r.begin());
    std::copy(phi0.begin(), phi0.end(), phi.begin());
    std::copy(psi0.begin(), psi0.end(), psi.begin());
    luf_ready = true;
  }

  // Both factors (split) or the one: a full factorisation, or a refactorisation (of the LU:
  // the xi block's LDL^T is a factorisation every time, a function of the values alone)
  int lu_factor() {
    int code = lu.factor(vals.data());
    if (code == 0 && split) code = lux.factor(vals.data());
    return code;
  }
  int lu_refactor() {
    int code = lu.refactor(vals.data());
    if (code == 0 && split) code = lux.factor(vals.data());
    return code;
  }

  // Solve the iteration matrix in place (x: N entries; rows dynamics, constraints, velocity
  // constraints in, (dn, dl, dxi) out); index 2: also dm = dn - B_n^T dxi out
  void solve(double* x) {
    const int nq = E->nq, nm = E->nm;
    if (!split || full_mode) {
      (full_mode ? luf : lu).solve(x);
      if (index2 && nm > 0) {
        std::copy(x, x + nq, dm.begin());
        E->subtract_BnT(x + nq + nm, dm.data());
      }
      return;
    }
    double* xl = x + nq;  // constraints' right-hand side in, dl out
    double* xx = x + N1;  // velocity constraints' right-hand side in, dxi out
    for (int i = 0; i < nm; ++i) std::swap(xl[i], xx[i]);
    lu.solve(x);  // (dm, dl); xx: -B_n B_n^T dxi = -phi - B dm
    for (int i = 0; i < nm; ++i) xx[i] = -xx[i];
    E->add_BA(x, xx);
    for (int i = 0; i < nm; ++i) xx[i] = dropm[i] ? 0.0 : xx[i];
    lux.solve(xx);
    std::copy(x, x + nq, dm.begin());
    for (int i = 0; i < nm; ++i) xx[i] = -xx[i];
    E->subtract_BnT(xx, x);  // dn = dm + B_n^T dxi
    for (int i = 0; i < nm; ++i) xx[i] = -xx[i];
  }

  // The first reference of the refactorisations: a full factorisation of the generic matrix
  // (the solver memory is then the model's own: nothing to keep in a State). Split: of the
  // (dm, dl) block only; the xi block's LDL^T keeps nothing (a function of the values it
  // factorises), the first factorisation of a run makes it.
  int probe_reference() {
    full_mode = false;
    factored_full = false;
    probe();
    set_dropped();
    int code = lu.factor(vals.data());
    have_ref = code == 0;
    // the memory is the model's own even when the generic matrix's factorisation failed (the
    // first matrix of a run is then factorised anew, as by every stepper of the model)
    ref_probe = true;
    ref_vals.reset();
    ++ref_serial;
    return code;
  }

  // The iteration matrix at a pseudo-random state of the model (frames, increments, velocities,
  // accelerations, multipliers, inputs drawn from a fixed sequence; generic coefficients): an
  // entry of the pattern that is zero there is zero in every state (the kernels write exact
  // zeros only where a term is absent), one that is nonzero there may be nonzero in some state.
  void probe() {
    Engine& G = *E;
    uint64_t x = 0x9E3779B97F4A7C15ull;
    auto rnd = [&x]() {  // splitmix64, uniform in [-1, 1)
      x += 0x9E3779B97F4A7C15ull;
      uint64_t z = x;
      z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
      z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
      z ^= z >> 31;
      return double(z >> 11) * (2.0 / 9007199254740992.0) - 1.0;
    };
    int F = G.T.F, nq = G.nq, nm = G.nm;
    std::vector<double> H4(16L * F), an(nq), n(nq), v(nq), vd(nq), lam(nm), u(G.nu), al(nq);
    for (int f = 0; f < F; ++f) {
      double w[6];
      for (double& c : w) c = 2.0 * rnd();
      Frame Ef;
      exp_se3(w, Ef);
      frame_to4(Ef, &H4[16L * f]);
    }
    for (auto* a : {&an, &n, &v, &vd, &lam, &u})
      for (double& c : *a) c = rnd();
    for (double& c : G.law_out) c = rnd();  // (the user's laws: generic values, not called)
    G.law_probe = true;
    for (double& c : n) c *= 0.3;
    G.load_frames(H4.data());
    bool stab = index2 && nm > 0;
    Engine::Out o{r.data(), phi.data(), stab ? psi.data() : nullptr, al.data(), vals.data(),
                  nullptr};
    G.evaluate(an.data(), n.data(), v.data(), vd.data(), lam.data(), u.data(), 1.0, 0.7, 0.3,
               stab, 0.6, false, o);
    G.law_probe = false;
    apply_merges();
  }

  // Couplings (engine.hpp): the follower's column and row of the matrix added to the
  // leader's (columns first: the (b, b) entry reaches (a, a) with ratio^2), before the
  // identity replaces them (set_dropped); after every evaluation of the matrix, never on a
  // solver memory's values (merged already)
  void apply_merges() {
    const bool two = index2 && vals.size() == size_t(E->nvals2);
    const std::vector<long>& m = two ? E->merge2 : E->merge3;
    const std::vector<double>& f = two ? E->mfac2 : E->mfac3;
    for (size_t i = 0; i < f.size(); ++i) vals[m[2 * i + 1]] += f[i] * vals[m[2 * i]];
  }

  // The followers' increment, rate and acceleration from the leaders' (abelian joints:
  // alpha = alpha_n + n): alpha_b = ratio alpha_a + offset and its derivatives
  void follow(const double* alpha_n, double* n, double* v, double* vd) const {
    for (int i = 0; i < E->ncpl(); ++i) {
      const int a = E->cpl_lead[i], b = E->cpl_follow[i];
      const double r = E->cpl_ratio[i];
      n[b] = r * (alpha_n[a] + n[a]) + E->cpl_offset[i] - alpha_n[b];
      v[b] = r * v[a];
      vd[b] = r * vd[a];
    }
  }

  // dropped (redundant) equations: identity rows and columns
  void set_dropped() {
    for (int i : zero_at) vals[i] = 0.0;
    for (int i : one_at) vals[i] = 1.0;
  }

  // Factorise the matrix of `vals`: a refactorisation with the pivot sequence of the last full
  // factorisation when it succeeds, else a full one, whose values become the reference
  int factor() {
    set_dropped();
    int code = have_ref ? (full_mode ? luf.refactor(vals.data()) : lu_refactor()) : 1;
    if (code != 0) {
      code = full_mode ? luf.factor(vals.data()) : lu_factor();
      have_ref = code == 0;
      ref_probe = false;
      ref_vals.reset();  // (freed unless a State holds it)
      if (have_ref) {
        std::vector<double> m(vals);
        if (index2) m.push_back(split && !full_mode ? 0.0 : 1.0);  // the mode (see the header)
        ref_vals = std::make_shared<const std::vector<double>>(std::move(m));
      }
      ++ref_serial;
    }
    if (code == 0) factored_full = full_mode;
    return code;
  }

  // Entries of the solver memory: the matrix values, and for index 2 the mode (1: the full
  // matrix, 0: split)
  size_t memory_size() const { return vals.size() + (index2 ? 1 : 0); }

  // Restore the solver memory: a full factorisation of `ref` (memory_size() entries) in its
  // mode, or (nullptr) of the generic matrix, as a new stepper starts. Returns 0, or the LU's
  // nonzero status. (A memory of split factors given to a stepper that never splits, a run
  // continued in full Newton: its values lack the full matrix's blocks; the generic matrix's
  // factors serve instead, the same for every such continuation.)
  int restore(const double* ref) {
    if (!ref) return probe_reference();
    bool full = !index2 || ref[vals.size()] != 0.0;
    if (!split && !full) return probe_reference();
    have_ref = false;
    if (split && full) ensure_luf();
    full_mode = split && full;
    std::copy(ref, ref + vals.size(), vals.begin());
    return factor();
  }

  // Whether this stepper's memory is `ref` (nullptr: the generic matrix's)
  bool holds(const double* ref) const {
    if (!ref) return ref_probe;
    if (!have_ref) return false;
    return !ref_probe && (ref == ref_vals->data() ||
                          std::memcmp(ref, ref_vals->data(), memory_size() * sizeof(double)) == 0);
  }

  // Driven unknowns at the predictor (ModelBuilder.drive): the increment, rate and
  // acceleration of a position driver are its f(t_{n+1}) - alpha_n (abelian joints: alpha =
  // alpha_n + n), f'(t_{n+1}) and f''(t_{n+1}); a velocity driver's rate and acceleration are
  // g(t_{n+1}) and g'(t_{n+1}), its increment follows the rate as the scheme's recurrences
  // make it (Eqs. (41)-(43): dn = dv / gamma'). The rest of the model sees the prescribed
  // motion exactly at t_{n+1}, as a given input: no start-up transient of the accelerations
  // (which a driver's constraint row, or its index-3 position alone, would have), so the
  // efforts converge at order 2 from the first step. The identity rows and columns (init)
  // keep these values over the iterations.
  void prescribe(const double* alpha_n, const double* u, double gp, double* n, double* v,
                 double* vd) const {
    const int nd = E->ndrive();
    for (int i = 0; i < nd; ++i) {
      const int* dr = &E->drive[Engine::DRIVE * i];
      const int d = dr[0], pos = dr[2], rate = dr[3], acc = dr[4];
      if (dr[1] == 0) n[d] = u[pos] - alpha_n[d];
      else n[d] += (u[rate] - v[d]) / gp;
      v[d] = u[rate];
      vd[d] = u[acc];
    }
  }

  // The driven unknowns' residuals (the drivers' forces: Eq. (36) holds with the driver's
  // force added, effort = r_d) are taken out of the residual, whose rows there are the
  // identity's (init); the convergence test sees the others only.
  void take_efforts() {
    for (int i = 0; i < E->ncpl(); ++i) {  // the follower's equation added to the leader's
      const int a = E->cpl_lead[i], b = E->cpl_follow[i];
      cforce[i] = r[b];
      r[a] += E->cpl_ratio[i] * r[b];
      r[b] = 0.0;
    }
    const int nd = E->ndrive();
    for (int i = 0; i < nd; ++i) {
      const int d = E->drive[Engine::DRIVE * i];
      effort[i] = r[d];
      r[d] = 0.0;
    }
  }

  struct Params {
    double h, am, af, g, b, tol_r, ltol, lscale, kmax;
    int max_iter;
    bool reuse;  // modified Newton (else a factorisation at every iteration)
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
    prescribe(alpha_n, u, gp, n, v, vd);
    follow(alpha_n, n, v, vd);
    double cM = 1.0, cC = gp / bp, cK = 1.0 / bp, cv = 1.0 / gp;
    StepInfo info;
    int it = 0;
    double er0 = 1.0, er = 0.0, ep = 0.0, dn_prev = 0.0;
    double ec_prev = std::numeric_limits<double>::infinity();
    bool refac = true;
    auto measure = [&](double fs) {  // (a NaN anywhere makes er or ep NaN)
      fs = fs > 1e-300 ? fs : 1e-300;
      er = amax_nan(r.data(), nq) / fs;
      ep = amax_nan(phi.data(), nm);
      if (stab) {
        double ps = amax_nan(psi.data(), nm) / gp;
        ep = (ps > ep || ps != ps) ? ps : ep;
      }
    };
    // every residual evaluation also gives the energies and powers of its iterate: those of
    // the converged one are the new state's (no evaluation of its own)
    Engine::Out o{r.data(), phi.data(), stab ? psi.data() : nullptr, alpha, nullptr,
                  energy.data()};
    o.ctrl = ctrl_out.empty() ? nullptr : ctrl_out.data();
    o.split = split && !full_mode;
    // a split iteration that must be refactorised goes over to the full matrix (for the run)
    auto fall_back = [&]() {
      if (refac && split && !full_mode && it > 0) {
        ensure_luf();
        full_mode = true;
        have_ref = false;  // (a full factorisation of the full matrix: the new memory)
        o.split = false;
      }
    };
    while (true) {
      bool with_matrix = refac || !P.reuse;  // the matrix is evaluated with the residual
      o.vals = with_matrix ? vals.data() : nullptr;
      double fs = G.evaluate(alpha_n, n, v, vd, lam, u, cM, cC, cK, stab, cv, false, o);
      take_efforts();
      if (with_matrix) apply_merges();
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
      fall_back();
      if (refac || !P.reuse) {
        if (!with_matrix) {
          o.vals = vals.data();
          G.evaluate(alpha_n, n, v, vd, lam, u, cM, cC, cK, stab, cv, false, o);
          take_efforts();
          apply_merges();
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
      solve(rhs.data());
      double dnmax = 0.0, nmax = 0.0;
      for (int i = 0; i < nq; ++i) {
        n[i] += rhs[i];
        double d = std::fabs(rhs[i]), m = std::fabs(n[i]);
        dnmax = d > dnmax ? d : dnmax;
        nmax = m > nmax ? m : nmax;
      }
      if (stab) std::copy(dm.begin(), dm.end(), rhs.begin());  // dm = dn - B_n^T xi
      for (int i = 0; i < nq; ++i) {
        v[i] += gp * rhs[i];
        vd[i] += bp * rhs[i];
      }
      for (int i = 0; i < nm; ++i) lam[i] += bp * rhs[nq + i];
      follow(alpha_n, n, v, vd);
      ++it;
      if (dn_prev > 0 && dnmax > 1e-12 * nmax) {
        double theta = dnmax / dn_prev;
        if (theta >= 0.9) refac = true;
        else if (theta > 1e-3) {
          double lt = std::log(theta);
          double k_rem = std::log(P.tol_r / std::fmax(er * theta, P.tol_r)) / lt;
          if (nm > 0) k_rem = std::fmax(k_rem, std::log(P.ltol / std::fmax(ep * theta, P.ltol)) / lt);
          if (k_rem > P.kmax || (split && !full_mode && k_rem > KSPLIT)) refac = true;
        }
      }
      dn_prev = dnmax;
      fall_back();
      // (round-off of the positions: of the increment, or of the model's length scale when the
      // motion has come to rest and the forces with it)
      if (ep <= P.ltol && dnmax <= 4e-16 * std::fmax(nmax, P.lscale)) {
        double fs2 = G.evaluate(alpha_n, n, v, vd, lam, u, cM, cC, cK, stab, cv, false, o);
        take_efforts();
        measure(fs2);
        break;
      }
    }
    if (full_mode) ++full_steps;
    for (int i = 0; i < G.ndrive(); ++i)  // the drivers' power (their forces' work: reports)
      energy[P_ACTUATOR] += effort[i] * v[G.drive[Engine::DRIVE * i]];
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
  // The integration state carried between steps: frames (F, 16), alpha, v, vd, a, lam,
  // acc = (powers p_act, p_ext, p_diss, works W_act, W_ext, dissipated, h_last, t) and the
  // PID states ctrl (2 npid: z, e)
  struct Carry {
    double *H, *alpha, *v, *vd, *a, *lam, *acc, *ctrl;
  };

  // After a converged step: the sampled PID laws that sampled at its end (ctrl_out against
  // the step's ctrl_old: their held outputs change) switch their forces there, a jump of the
  // accelerations (the velocities and positions are continuous). The state at t_{n+1} is made
  // that after the switch, as a run would start from it: vd += dvd, a += dvd, lam += dlam with
  // [M Phi_q^T; Phi_q 0] (dvd, dlam) = (dtau on the controlled coordinates, 0), solved with
  // the step's last factorisation (M + O(h) there: dvd to O(h), so the next steps keep
  // order 2; without this, the generalized-alpha variable a lags the switch: order 1).
  // Returns the change of the actuators' power at t_{n+1}, sum dtau v.
  double sample_jump(const double* ctrl_old, const double* v, double* vd, double* a,
                     double* lam) {
    const int nq = E->nq, nm = E->nm;
    std::fill(rhs.begin(), rhs.end(), 0.0);
    double dp = 0.0;
    bool any = false;
    for (int i = 0; i < E->npid(); ++i) {
      if (E->ctrl_ts[i] <= 0) continue;
      const double du = ctrl_out[2 * i] - ctrl_old[2 * i];
      if (du == 0.0) continue;
      const int d = E->ctrl_dof[i];
      rhs[d] = du;
      dp += du * v[d];
      any = true;
    }
    if (!any) return 0.0;
    // (with the factors there are: a step's last iteration may have switched the mode for the
    // next factorisation, fall_back)
    const bool mode = full_mode;
    full_mode = factored_full;
    solve(rhs.data());
    full_mode = mode;
    const double* dvd = (index2 && nm > 0) ? dm.data() : rhs.data();  // (index 2: v follow m)
    for (int i = 0; i < nq; ++i) {
      vd[i] += dvd[i];
      a[i] += dvd[i];
    }
    for (int i = 0; i < nm; ++i) lam[i] += rhs[nq + i];
    return dp;
  }

  // The inputs of a step of size h to t1: u (nu) with the PID states in their slots
  // (joint_force.hpp), from ctrl (2 npid): (z_n, e_n, h/2) of a continuous law, (u_hold, I,
  // t1) of a sampled one
  void controller_inputs(const double* ctrl, double h, double t1, double* u) const {
    for (int i = 0; i < E->npid(); ++i) {
      double* z = u + E->ctrl_slot[i];
      z[0] = ctrl[2 * i];
      z[1] = ctrl[2 * i + 1];
      z[2] = E->ctrl_ts[i] > 0 ? t1 : 0.5 * h;
    }
    const double* cs = ctrl + 2L * E->npid();  // contacts: their states and h/2
    for (int i = 0; i < E->ncs(); ++i) {
      double* z = u + E->cs_slot[i];
      for (int j = 0; j < Engine::CSTATE; ++j) z[j] = cs[Engine::CSTATE * i + j];
      z[Engine::CSTATE] = 0.5 * h;
    }
  }
  struct RunResult {
    int status = 0, done = 0, iterations = 0, factorisations = 0;
    double residual = 0, constraint = 0;
  };

  // dst[0..n) = src[0..n), the same bits, with stores that bypass the caches where the
  // machine has them (SSE2): a stored row of a 1000-link chain is 390 KB, most of a core's L2,
  // and written through the caches it evicted the step's own working set at every step
  // (docs/performance.md). Nothing reads the rows until the run returns (the fence orders
  // the stores before that).
  static void stream_copy(const double* src, long n, double* dst) {
#if defined(__SSE2__)
    long k = 0;
    if (reinterpret_cast<std::uintptr_t>(dst) % 16 != 0 && n > 0) {
      dst[0] = src[0];
      k = 1;
    }
    for (; k + 2 <= n; k += 2) _mm_stream_pd(dst + k, _mm_loadu_pd(src + k));
    if (k < n) dst[k] = src[k];
    _mm_sfence();
#else
    std::copy(src, src + n, dst);
#endif
  }

  // Fixed-step loop over steps i0 <= i < i1 to the times[i], inputs U (nsteps, nu); stores
  // every output_every-th state (and the last one, i = last) into rows. Energies, powers
  // (trapezoidal works) and log coordinates of the stored states are computed here too. On a
  // failing step, returns its status with the carry at the last converged state.
  RunResult run(Params P, const double* times, int i0, int i1, int last, const double* U,
                int output_every, Carry c, Rows& rows) {
    Engine& G = *E;
    int nq = G.nq, nm = G.nm, F = G.T.F, nu = G.nu;
    std::vector<double> alpha(nq), v(nq), vd(nq), a(nq), lam(nm), n(nq), a_n(nq), ubuf(nu);
    RunResult R;
    for (int i = i0; i < i1; ++i) {
      double t1 = times[i], h = t1 - c.acc[7], h_last = c.acc[6];
      const double* u = U + (long)i * nu;
      if (G.nctrl() > 0) {  // (the table's rows stay as they are: a copy with the states)
        std::copy(u, u + nu, ubuf.begin());
        controller_inputs(c.ctrl, h, t1, ubuf.data());
        u = ubuf.data();
      }
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
      const std::vector<double>& en = energy;  // of the converged iterate: the new state's
      for (int k = 0; k < 3; ++k) {
        c.acc[3 + k] += 0.5 * h * (c.acc[k] + en[P_ACTUATOR + k]);
        c.acc[k] = en[P_ACTUATOR + k];
      }
      // (a sampled law switched at t1: the state after it, and its power)
      if (G.npid() > 0) c.acc[0] += sample_jump(c.ctrl, v.data(), vd.data(), a.data(), lam.data());
      c.acc[6] = h;
      c.acc[7] = t1;
      std::copy(alpha.begin(), alpha.end(), c.alpha);
      std::copy(v.begin(), v.end(), c.v);
      std::copy(vd.begin(), vd.end(), c.vd);
      std::copy(a.begin(), a.end(), c.a);
      std::copy(lam.begin(), lam.end(), c.lam);
      std::copy(ctrl_out.begin(), ctrl_out.end(), c.ctrl);
      if (((i + 1) % output_every == 0 || i == last) && rows.count < rows.cap) {
        long r = rows.count++;
        rows.t[r] = t1;
        stream_copy(c.H, 16L * rows.M, rows.H + r * 16L * rows.M);
        stream_copy(v.data(), nq, rows.v + r * nq);
        stream_copy(vd.data(), nq, rows.vd + r * nq);
        stream_copy(lam.data(), nm, rows.lam + r * nm);
        stream_copy(alpha.data(), nq, rows.alpha + r * nq);
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
