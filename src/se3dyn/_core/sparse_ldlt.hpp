// Sparse LDL^T of a symmetric matrix with prescribed pivot signs (symmetric positive definite,
// or quasi-definite with known inertia): generic, header-only, standard library only.
//
//   P A P^T = L D L^T      L unit lower triangular, D diagonal, sign(D_kk) = sign_k
//
// No pivoting: the factorisation of a symmetric positive definite matrix in any symmetric order
// is backward stable (Higham, "Accuracy and Stability of Numerical Algorithms", 2002, thm.
// 10.5), and so is that of a quasi-definite one [H A^T; A -G] (H, G positive definite) whose
// pivots have the signs of its blocks (Vanderbei, "Symmetric quasidefinite matrices", SIAM J.
// Optim. 5 (1995) 100-113; Gill, Saunders & Shinnerl, SIAM J. Matrix Anal. Appl. 17 (1996)
// 35-46). A pivot of the wrong sign, zero or not finite means the matrix is not what the caller
// said (singular, indefinite, NaN/Inf values): factor stops with a nonzero status, never a
// silent result.
//
// * analyze: the ordering P is the one SparseLU computes for the same pattern (approximate
//   minimum degree on the graph of the caller's blocks, zero entries left out of the graph with
//   drop_zeros; sparse_lu.hpp), followed by a postorder of the elimination tree (the same fill;
//   the columns of a supernode become contiguous). Then the elimination tree (Liu, "A compact
//   row storage scheme for Cholesky factors using elimination trees", ACM TOMS 12 (1986)
//   127-148; CSparse cs_etree), the column counts of L by row subtrees (Davis, "Direct Methods
//   for Sparse Linear Systems", SIAM 2006, sec. 4.4: O(nnz(L)), which is small here), the
//   supernodes (maximal runs of columns j, j+1 with parent(j) = j+1 and |L(:, j)| =
//   |L(:, j+1)| + 1: nested structure) and their row structures (the union of the rows of A's
//   columns and of the child supernodes' structures; Liu, Ng & Peyton, SIAM J. Matrix Anal.
//   Appl. 14 (1993) 242-252), and the scatter map of the values.
// * factor: left-looking supernodal (Ng & Peyton, "Block sparse Cholesky algorithms on advanced
//   uniprocessor computers", SIAM J. Sci. Comput. 14 (1993) 1034-1056; as CHOLMOD's
//   super_numeric, Chen, Davis, Hager & Rajamanickam, ACM TOMS 35 (2008) 22): for every
//   supernode, its columns of A scattered into a dense panel, the updates of the descendant
//   supernodes that touch it subtracted (a linked list per supernode of the descendants still
//   to apply, advanced as they are used), then a dense LDL^T of the diagonal block and the
//   rows below it. Every factor is a full numeric factorisation (nothing like a pivot sequence
//   is kept between them: the result depends only on the values).
// * solve: the permutation, L y = P b and L^T z = D^-1 y a supernode at a time, and back.
// * Two runs at once: when the ordering is SparseLU's two-way dissection, the postorder keeps
//   each part's steps together and no supernode crosses a part boundary; factor and solve then
//   take the two parts' supernodes at once on the pool of pool.hpp (split_plan), then the
//   separator's, with the same operations as one pass.
//
// Only one triangle is read: of an entry (i, j) of the pattern and its transpose (j, i), the one
// in the lower triangle of P A P^T (when the pattern has only the other one, that one). The
// caller's matrix must be symmetric; the other triangle is never looked at.
//
// Data structure invariants after analyze (0-based; "step k" is row/column k of P A P^T):
//   perm_[k]   original index eliminated at step k; pinv_ its inverse.
//   Supernode s holds the steps [Sp_[s], Sp_[s+1]) (width w); its rows are those w steps and
//              then the rows below, Ri_[Rp_[s] .. Rp_[s+1]) (steps >= Sp_[s+1], increasing).
//              Panel s: (w + nR) x w, row-major, at Lx_[Lxp_[s]]: row i (i < w) holds
//              L(f+i, f..f+i-1) and D(f+i) at column i (the columns after it are unused), row
//              w+r holds L(Ri_[Rp_[s]+r], f..f+w-1) (f = Sp_[s]).
//   Value map: entry p of the pattern is values[vmap[p]] (empty vmap: values[p], CSC order).
//   Scatter map of supernode s (P its panel, zeroed first): P[Sx_[q]] = values[Sv_[q]] for q
//              in [Sq_[2s], Sq_[2s+1]) (one record per position), then P[Sx_[q]] += values[Sv_[q]]
//              for q in [Sq_[2s+1], Sq_[2s+2]) (duplicate entries of a position);
//              the entries left out of the pattern (drop_zeros) whose column is in s: value
//              indices Zv_[Zq_[s] .. Zq_[s+1]) (they must stay zero).
//   work_      n doubles, all zero between calls.
//
// No exceptions are thrown by factor/solve (status codes); factor and solve do not allocate
// (all memory is sized in analyze). solve() is const but uses the mutable work vector: one
// SparseLDLT object must not be used by two threads at once.
//
// Test: tests/cpp/test_sparse_ldlt.cpp.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <vector>

#include "sparse_lu.hpp"

namespace se3dyn {

namespace sparse_ldlt_detail {

// sum_t a[t] * b[t], t < w, in increasing t (the same operations whether w is known at compile
// time or not: the kernels specialised for some widths give the results of the generic ones)
template <int W>
SE3DYN_LU_SCALAR inline double dotw(const double* a, const double* b) {
  double s = 0.0;
  for (int t = 0; t < W; ++t) s += a[t] * b[t];
  return s;
}
SE3DYN_LU_SCALAR inline double dot(const double* a, const double* b, int w) {
  double s = 0.0;
  for (int t = 0; t < w; ++t) s += a[t] * b[t];
  return s;
}

}  // namespace sparse_ldlt_detail

class SparseLDLT {
 public:
  struct Options {
    // leave the entries of A that are zero in the values given to analyze (and not marked in
    // its keep mask) out of the pattern of L; "zero": |a_ij| <= drop_tol * max_i |a_ij|
    // (drop_tol = 0: exact zeros only). factor checks that they still are: |a| <= drop_tol *
    // max |a| over the entries of the supernode's columns read by that factor, else
    // kPatternChanged (kNotFinite for NaN/Inf).
    bool drop_zeros = false;
    double drop_tol = 0.0;
    // factor fails (kNotDefinite) when a pivot is not sign_k * d_k > pivot_tol * |a_kk|
    // (pivot_tol = 0: a pivot of the wrong sign or zero). A positive value also refuses
    // pivots that have lost all but -log10(pivot_tol) digits to cancellation (a numerically
    // singular matrix).
    double pivot_tol = 0.0;
  };

  // Status of the last factor.
  enum Status : int {
    kOk = 0,
    kNotAnalyzed = 1,     // analyze not called, or failed
    kNotDefinite = 3,     // a pivot zero or of the wrong sign (or below pivot_tol)
    kNotFinite = 4,       // a value of the factor is Inf or NaN
    kPatternChanged = 6,  // (drop_zeros) an entry left out by analyze is nonzero now
  };

  SparseLDLT() = default;
  explicit SparseLDLT(const Options& opt) : opt_(opt) {}
  void set_options(const Options& opt) { opt_ = opt; }
  const Options& options() const { return opt_; }

  // Pattern of an n x n symmetric matrix in CSC (colptr: n+1, rowind: nnz; rows sorted or not;
  // both triangles or one; duplicates are summed; the arrays are consumed, only the scatter map
  // made of them is kept) and the caller's order of the values: entry p is values[vmap[p]] here
  // and in every factor (empty vmap: the CSC order).
  // `group` (n ints, or nullptr): unknowns with equal ids form a block kept contiguous in the
  // ordering (see SparseLU::analyze). `values` (optional: typical values, e.g. of a generic
  // state): with drop_zeros, their zero entries are left out of the ordering and of the pattern
  // of L. `keep` (optional, one char per entry p): with drop_zeros, the entries kept in the
  // pattern whatever their values (with values: those marked or nonzero; without: those
  // marked). Returns 0, or -1 for an invalid pattern (then factor fails with kNotAnalyzed).
  int analyze(int n, std::vector<int>&& colptr, std::vector<int>&& rowind,
              std::vector<int>&& vmap, const int* group = nullptr,
              const double* values = nullptr, const char* keep = nullptr);
  // The same with the pattern copied, values in CSC order.
  int analyze(int n, const int* colptr, const int* rowind, const int* group = nullptr,
              const double* values = nullptr, const char* keep = nullptr) {
    if (n < 0 || colptr == nullptr || (n > 0 && rowind == nullptr && colptr[n] > 0)) {
      reset();
      return -1;
    }
    return analyze(n, std::vector<int>(colptr, colptr + n + 1),
                   std::vector<int>(rowind, rowind + colptr[n]), {}, group, values, keep);
  }
  // The sign of every pivot (n entries in the original numbering, +1 or -1; nullptr: all +1,
  // positive definite), after analyze (which sets all +1).
  void set_signs(const signed char* sign) {
    for (int k = 0; k < n_; ++k) sgn_[k] = (sign && sign[perm_[k]] < 0) ? -1.0 : 1.0;
  }

  // Numeric factorisation of the values (through the value map). Returns 0, or 1 + the original
  // index of the column whose pivot failed (status() tells why) or of a column whose left-out
  // entry became nonzero; the factor is then invalid until the next successful one. No
  // allocation.
  int factor(const double* values);

  // Solve A x = b in place (b: n entries). Requires a successful factor; otherwise b is filled
  // with NaN. No allocation.
  void solve(double* b) const;

  int n() const { return n_; }
  bool ok() const { return valid_; }
  Status status() const { return status_; }
  // step k eliminates original unknown perm()[k]
  const std::vector<int>& perm() const { return perm_; }
  // entries of L including its unit diagonal (the factor stores them and D)
  long long nnz_L() const { return nnzL_; }
  // multiply-adds of one factor: over the columns j of L, c_j (c_j + 1) / 2 with c_j the
  // entries below the diagonal (the updates L(r, j) d_j L(k, j), r >= k, of the later columns)
  long long factor_flops() const { return flops_; }
  int num_supernodes() const { return ns_; }
  // Steps of the two runs that factor and solve take at once ([0, m1), [m1, m2); 0, 0: none)
  std::pair<int, int> parallel_parts() const { return {split_m1_, split_m2_}; }
  // pivot D_kk of step k after a successful factor (row and column k - f of the panel of its
  // supernode, f its first step)
  double pivot(int k) const {
    const int s = sn_[k], i = k - Sp_[s];
    return Lx_[Lxp_[s] + static_cast<long long>(i) * (Sp_[s + 1] - Sp_[s] + 1)];
  }

 private:
  void reset() {
    analyzed_ = valid_ = false;
    status_ = kNotAnalyzed;
    n_ = ns_ = 0;
  }
  void update(int d, int s, int p0, int p1, const int* map, double* dlu);
  int factor_panel(int s, double* dl, Status& status);

  Options opt_;
  int n_ = 0, ns_ = 0, maxw_ = 0;
  bool analyzed_ = false, valid_ = false;
  Status status_ = kNotAnalyzed;
  std::vector<int> perm_, pinv_;
  std::vector<int> Sp_, sn_;       // supernode s: steps [Sp_[s], Sp_[s+1]); sn_[k]: k's supernode
  std::vector<int> Rp_, Ri_;       // rows below supernode s: Ri_[Rp_[s] .. Rp_[s+1])
  std::vector<long long> Lxp_;     // panel of supernode s at Lx_[Lxp_[s]]
  std::vector<double> Lx_;
  std::vector<double> invd_, sgn_, adiag_;  // 1 / D_kk; sign of D_kk; |A_kk| of the factor
  std::vector<int> Sq_, Sv_, Sx_;           // scatter map (see the invariants)
  std::vector<int> Zq_, Zv_;                // left-out entries per supernode
  // factor workspace: row map of the current supernode, descendant lists, buffers
  std::vector<int> map_, head_, next_, lpos_;
  std::vector<double> dl_, dlu_;
  mutable std::vector<double> work_;  // zero between calls
  // Two runs of supernodes that factor and solve take at once (split_plan): [0, s1) and
  // [s1, s2), steps [0, m1) and [m1, m2); the rest after them. The second run has its own
  // workspace (map2_, head2_: its links to the separator's supernodes, put in front of the
  // first run's before those are factorised, as one pass would have linked them).
  int split_s1_ = 0, split_s2_ = 0, split_m1_ = 0, split_m2_ = 0;
  std::vector<int> map2_, head2_;
  std::vector<double> dl2_, dlu2_;
  mutable std::vector<double> work2_;  // zero between calls
  void split_plan(const std::vector<int>& part);
  int factor_supernodes(int s0, int s1, const double* values, int* map, int* head, double* dl,
                        double* dlu, Status& status);
  void forward(int s0, int s1, double* y) const;
  void backward(int s1, int s0, double* y) const;
  long long nnzL_ = 0, flops_ = 0;
};

// ---------------------------------------------------------------------------------------------
// analyze
// ---------------------------------------------------------------------------------------------
inline int SparseLDLT::analyze(int n, std::vector<int>&& colptr, std::vector<int>&& rowind,
                               std::vector<int>&& vmap, const int* group, const double* values,
                               const char* keep) {
  reset();
  if (!sparse_lu_detail::valid_pattern(n, colptr, rowind, vmap)) return -1;
  const int nz = colptr[n];
  auto vidx = [&](int p) { return vmap.empty() ? p : vmap[p]; };

  // --- the ordering of SparseLU for this pattern (its analyze, without the numeric storage
  //     mattering: a temporary), pattern-only when there are no values; the part of its
  //     dissection each unknown is in (0, 1; 2: the separator or none)
  std::vector<int> perm, part;
  {
    SparseLU::Options lo;
    lo.drop_zeros = opt_.drop_zeros;
    lo.drop_tol = opt_.drop_tol;
    lo.order_with_values = false;
    SparseLU lu(lo);
    if (lu.analyze(n, std::vector<int>(colptr), std::vector<int>(rowind), std::vector<int>(vmap),
                   group, values) != 0)
      return -1;
    perm = lu.col_perm();
    auto [n1, n2] = lu.ordering_parts();
    part.assign(n, 2);
    for (int k = 0; k < n2; ++k) part[perm[k]] = k < n1 ? 0 : 1;
  }
  std::vector<int> pinv(n);
  for (int k = 0; k < n; ++k) pinv[perm[k]] = k;

  // --- the entries in the lower triangle of P A P^T: (column c, row r >= c, from the upper
  //     triangle?, entry p), and whether each is in the pattern of L
  std::vector<double> colmax;
  const bool drop = opt_.drop_zeros && (values || keep);
  if (drop && values) {
    colmax.assign(n, 0.0);
    for (int j = 0; j < n; ++j)
      for (int p = colptr[j]; p < colptr[j + 1]; ++p)
        colmax[j] = std::max(colmax[j], std::fabs(values[vidx(p)]));
  }
  // (an entry: key (r << 32) | (up << 31) | p, r >= c its row in the lower triangle, up set
  // when it is the transpose of the caller's entry p)
  std::vector<char> kept(nz, 1);
  std::vector<int> cstart(n + 1, 0);
  for (int j = 0; j < n; ++j)
    for (int p = colptr[j]; p < colptr[j + 1]; ++p) {
      ++cstart[1 + std::min(pinv[rowind[p]], pinv[j])];
      if (drop) {
        const bool nonzero = values && std::fabs(values[vidx(p)]) > opt_.drop_tol * colmax[j];
        kept[p] = (keep && keep[p]) || nonzero;
      }
    }
  for (int c = 0; c < n; ++c) cstart[c + 1] += cstart[c];
  // by column (a counting sort), then in a column by row, lower-triangle entries before upper
  // ones of the same position: the position's representatives (the lower ones if any) are the
  // first entries with its `up`
  std::vector<std::uint64_t> ent(nz);
  {
    std::vector<int> cur(cstart.begin(), cstart.end() - 1);
    for (int j = 0; j < n; ++j) {
      const int b = pinv[j];
      for (int p = colptr[j]; p < colptr[j + 1]; ++p) {
        const int a = pinv[rowind[p]];
        const std::uint64_t key = a >= b ? (static_cast<std::uint64_t>(a) << 32) | p
                                         : (static_cast<std::uint64_t>(b) << 32) | (1u << 31) | p;
        ent[cur[std::min(a, b)]++] = key;
      }
    }
  }
  for (int c = 0; c < n; ++c) std::sort(ent.begin() + cstart[c], ent.begin() + cstart[c + 1]);
  auto ent_r = [&](int e) { return static_cast<int>(ent[e] >> 32); };
  auto ent_up = [&](int e) { return static_cast<int>((ent[e] >> 31) & 1u); };
  auto ent_p = [&](int e) { return static_cast<int>(ent[e] & 0x7fffffffu); };
  // positions of the pattern of L's input (c, r, r >= c), each with the range of its
  // representative entries; the left-out representatives
  struct Pos {
    int c, r, e0, e1;
  };
  std::vector<Pos> pos;
  pos.reserve(nz / 2 + n);
  std::vector<std::pair<int, int>> zero;  // (column c, entry p) left out
  for (int c = 0; c < n; ++c) {
    const int cend = cstart[c + 1];
    for (int e = cstart[c]; e < cend;) {
      const int r = ent_r(e), up = ent_up(e);
      int e1 = e;
      bool in = false;
      while (e1 < cend && ent_r(e1) == r && ent_up(e1) == up) {
        in = in || kept[ent_p(e1)];
        ++e1;
      }
      if (in || r == c) {
        pos.push_back({c, r, e, e1});
      } else {
        for (int q = e; q < e1; ++q) zero.emplace_back(c, ent_p(q));
      }
      while (e1 < cend && ent_r(e1) == r) ++e1;  // (the upper duplicates)
      e = e1;
    }
  }

  // --- elimination tree of the pattern (rows of the lower triangle: row r holds c < r)
  auto rows_of = [&](std::vector<int>& Tp, std::vector<int>& Ti) {
    Tp.assign(n + 1, 0);
    for (const Pos& q : pos)
      if (q.r > q.c) ++Tp[q.r + 1];
    for (int i = 0; i < n; ++i) Tp[i + 1] += Tp[i];
    Ti.resize(Tp[n]);
    std::vector<int> cur(Tp.begin(), Tp.end() - 1);
    for (const Pos& q : pos)
      if (q.r > q.c) Ti[cur[q.r]++] = q.c;
  };
  auto etree = [&](const std::vector<int>& Tp, const std::vector<int>& Ti,
                   std::vector<int>& parent) {
    parent.assign(n, -1);
    std::vector<int> anc(n, -1);
    for (int k = 0; k < n; ++k)
      for (int t = Tp[k]; t < Tp[k + 1]; ++t)
        for (int i = Ti[t]; i != -1 && i < k;) {
          const int inext = anc[i];
          anc[i] = k;
          if (inext == -1) parent[i] = k;
          i = inext;
        }
  };
  std::vector<int> Tp, Ti, parent;
  rows_of(Tp, Ti);
  etree(Tp, Ti, parent);
  // --- postorder (children in increasing order; the identity when the order is one already)
  {
    std::vector<int> head(n, -1), next(n, -1), post(n), stack(n);
    for (int j = n - 1; j >= 0; --j)
      if (parent[j] != -1) {
        next[j] = head[parent[j]];
        head[parent[j]] = j;
      }
    int k = 0;
    for (int j = 0; j < n; ++j)
      if (parent[j] == -1) k = sparse_lu_detail::tdfs(j, k, head.data(), next.data(), post.data(),
                                                       stack.data());
    bool identity = true;
    for (int i = 0; i < n; ++i) identity = identity && post[i] == i;
    if (!identity) {
      std::vector<int> pi(n);  // old step -> new step
      for (int i = 0; i < n; ++i) pi[post[i]] = i;
      std::vector<int> perm2(n), parent2(n);
      for (int i = 0; i < n; ++i) {
        perm2[i] = perm[post[i]];
        parent2[pi[i]] = parent[i] == -1 ? -1 : pi[parent[i]];
      }
      perm.swap(perm2);
      parent.swap(parent2);
      for (int k2 = 0; k2 < n; ++k2) pinv[perm[k2]] = k2;
      // an entry (r, c) of the pattern has r an ancestor of c: it stays in the lower triangle
      for (Pos& q : pos) {
        q.c = pi[q.c];
        q.r = pi[q.r];
      }
      for (auto& z : zero) z.first = pi[z.first];
      std::sort(pos.begin(), pos.end(), [](const Pos& x, const Pos& y) {
        return x.c != y.c ? x.c < y.c : x.r < y.r;
      });
      rows_of(Tp, Ti);
    }
  }
  // --- column counts of L (including the diagonal), by the row subtrees
  std::vector<int> cc(n, 1);
  {
    std::vector<int> flag(n, -1);
    for (int k = 0; k < n; ++k) {
      flag[k] = k;
      for (int t = Tp[k]; t < Tp[k + 1]; ++t)
        for (int j = Ti[t]; flag[j] != k; j = parent[j]) {
          flag[j] = k;
          ++cc[j];
        }
    }
  }
  // --- supernodes (none across the boundary of two parts of the dissection: split_plan)
  std::vector<int> Sp{0}, sn(n);
  auto same_part = [&](int j) { return part.empty() || part[perm[j - 1]] == part[perm[j]]; };
  for (int j = 1; j <= n; ++j)
    if (j == n || !(parent[j - 1] == j && cc[j - 1] == cc[j] + 1 && same_part(j)))
      Sp.push_back(j);
  const int ns = static_cast<int>(Sp.size()) - 1;
  int maxw = 0;
  for (int s = 0; s < ns; ++s) {
    maxw = std::max(maxw, Sp[s + 1] - Sp[s]);
    for (int j = Sp[s]; j < Sp[s + 1]; ++j) sn[j] = s;
  }
  // --- row structures: A's rows of the supernode's columns below it, and the rows of the
  //     child supernodes (whose first row below lies in it) below it
  std::vector<int> Cp(n + 1, 0);  // pattern positions by column
  for (const Pos& q : pos) ++Cp[q.c + 1];
  for (int j = 0; j < n; ++j) Cp[j + 1] += Cp[j];
  std::vector<int> Rp(ns + 1, 0), Ri, mark(n, -1), chead(ns, -1), cnext(ns, -1), rows;
  for (int s = 0; s < ns; ++s) {
    const int l = Sp[s + 1];
    rows.clear();
    for (int t = Cp[Sp[s]]; t < Cp[l]; ++t) {
      const int r = pos[t].r;
      if (r >= l && mark[r] != s) {
        mark[r] = s;
        rows.push_back(r);
      }
    }
    for (int c = chead[s]; c != -1; c = cnext[c])
      for (int t = Rp[c]; t < Rp[c + 1]; ++t) {
        const int r = Ri[t];
        if (r >= l && mark[r] != s) {
          mark[r] = s;
          rows.push_back(r);
        }
      }
    std::sort(rows.begin(), rows.end());
    if (static_cast<int>(rows.size()) != cc[l - 1] - 1) return -1;  // (cannot happen)
    Ri.insert(Ri.end(), rows.begin(), rows.end());
    Rp[s + 1] = static_cast<int>(Ri.size());
    if (!rows.empty()) {
      const int ps = sn[rows[0]];
      cnext[s] = chead[ps];
      chead[ps] = s;
    }
  }
  // --- panels, the scatter map (records of a supernode ordered by value index), counts
  std::vector<long long> Lxp(ns + 1, 0);
  for (int s = 0; s < ns; ++s) {
    const long long w = Sp[s + 1] - Sp[s];
    const long long size = w * (w + Rp[s + 1] - Rp[s]);
    if (size > std::numeric_limits<int>::max()) return -1;  // (offsets in a panel are ints)
    Lxp[s + 1] = Lxp[s] + size;
  }
  std::vector<int> Sq(2 * ns + 1, 0), Sv, Sx;
  Sv.reserve(nz);
  Sx.reserve(nz);
  {
    std::vector<std::pair<int, int>> rec, dup;
    for (int s = 0; s < ns; ++s) {
      const int f = Sp[s], l = Sp[s + 1], w = l - f;
      rec.clear();
      dup.clear();
      for (int t = Cp[f]; t < Cp[l]; ++t) {
        const Pos& q = pos[t];
        int row;
        if (q.r < l) {
          row = q.r - f;
        } else {
          row = w + static_cast<int>(std::lower_bound(Ri.begin() + Rp[s], Ri.begin() + Rp[s + 1],
                                                      q.r) - (Ri.begin() + Rp[s]));
        }
        const int x = row * w + (q.c - f);
        rec.emplace_back(vidx(ent_p(q.e0)), x);
        for (int e = q.e0 + 1; e < q.e1; ++e) dup.emplace_back(vidx(ent_p(e)), x);
      }
      std::sort(rec.begin(), rec.end());
      std::sort(dup.begin(), dup.end());
      for (const auto& [v, x] : rec) {
        Sv.push_back(v);
        Sx.push_back(x);
      }
      Sq[2 * s + 1] = static_cast<int>(Sv.size());
      for (const auto& [v, x] : dup) {
        Sv.push_back(v);
        Sx.push_back(x);
      }
      Sq[2 * s + 2] = static_cast<int>(Sv.size());
    }
  }
  std::vector<int> Zq(ns + 1, 0), Zv;
  std::sort(zero.begin(), zero.end());
  {
    std::size_t z = 0;
    for (int s = 0; s < ns; ++s) {
      for (; z < zero.size() && zero[z].first < Sp[s + 1]; ++z) Zv.push_back(vidx(zero[z].second));
      Zq[s + 1] = static_cast<int>(Zv.size());
    }
  }
  long long nnzL = 0, flops = 0;
  for (int j = 0; j < n; ++j) {
    const long long c = cc[j] - 1;
    nnzL += cc[j];
    flops += c * (c + 1) / 2;
  }

  n_ = n;
  ns_ = ns;
  maxw_ = maxw;
  perm_.swap(perm);
  pinv_.swap(pinv);
  Sp_.swap(Sp);
  sn_.swap(sn);
  Rp_.swap(Rp);
  Ri_.swap(Ri);
  Lxp_.swap(Lxp);
  Lx_.assign(Lxp_[ns], 0.0);
  invd_.assign(n, 0.0);
  sgn_.assign(n, 1.0);
  adiag_.assign(n, 0.0);
  Sq_.swap(Sq);
  Sv_.swap(Sv);
  Sx_.swap(Sx);
  Zq_.swap(Zq);
  Zv_.swap(Zv);
  map_.assign(n, 0);
  head_.assign(ns, -1);
  next_.assign(ns, -1);
  lpos_.assign(ns, 0);
  dl_.assign(static_cast<std::size_t>(maxw) * maxw, 0.0);
  dlu_.assign(static_cast<std::size_t>(maxw) * maxw, 0.0);
  work_.assign(n, 0.0);
  nnzL_ = nnzL;
  flops_ = flops;
  split_plan(part);
  if (split_s2_ > 0) {
    map2_.assign(n, 0);
    head2_.assign(ns, -1);
    dl2_.assign(dl_.size(), 0.0);
    dlu2_.assign(dlu_.size(), 0.0);
    work2_.assign(n, 0.0);
  }
  analyzed_ = true;
  return 0;
}

// The supernodes of the two parts of the ordering's dissection (part: of every unknown), when
// after the postorder they are two runs of whole supernodes followed by the separator's, and
// no supernode of the first run has rows in the second: then factor and solve take the two
// runs at once (as SparseLU's refactor and solve).
inline void SparseLDLT::split_plan(const std::vector<int>& part) {
  split_s1_ = split_s2_ = split_m1_ = split_m2_ = 0;
  const int n = n_;
  if (part.empty() || n == 0 || part[perm_[0]] == 2) return;
  const int a = part[perm_[0]];
  int m1 = 0;
  while (m1 < n && part[perm_[m1]] == a) ++m1;
  int m2 = m1;
  while (m2 < n && part[perm_[m2]] == 1 - a) ++m2;
  for (int k = m2; k < n; ++k)
    if (part[perm_[k]] != 2) return;
  if (m1 == 0 || m2 == m1 || m1 >= n || Sp_[sn_[m1]] != m1 || (m2 < n && Sp_[sn_[m2]] != m2))
    return;
  const int s1 = sn_[m1], s2 = m2 < n ? sn_[m2] : ns_;
  for (int s = 0; s < s1; ++s)
    for (int t = Rp_[s]; t < Rp_[s + 1]; ++t)
      if (Ri_[t] >= m1 && Ri_[t] < m2) return;
  split_s1_ = s1;
  split_s2_ = s2;
  split_m1_ = m1;
  split_m2_ = m2;
}

// ---------------------------------------------------------------------------------------------
// factor
// ---------------------------------------------------------------------------------------------

namespace sparse_ldlt_detail {

// Subtract the update of descendant supernode d from the panel of supernode s: its rows
// Ri(d)[p0 .. p1) are steps of s (the columns updated), Ri(d)[p0 ..) the rows updated;
// map_ holds the panel rows of s. For row r and updated column c (c <= r):
//   panel_s(map(R[r]), R[c] - f_s) -= sum_t L_d(R[r], t) D_t L_d(R[c], t)
// (the sum in increasing t; WD = the width of d when it is known at compile time, else 0).
template <int WD>
SE3DYN_LU_SCALAR inline void ldlt_update(const double* __restrict Ld, const double* __restrict dl,
                                         const int* __restrict R, const int* __restrict map,
                                         double* __restrict Ls, int ws, int fs, int wdyn, int p0,
                                         int nc, int nr) {
  const int wd = WD > 0 ? WD : wdyn;
  for (int r = p0; r < nr; ++r) {
    const double* lr = Ld + static_cast<long long>(r) * wd;
    double* tr = Ls + static_cast<long long>(map[R[r]]) * ws - fs;
    const int cm = std::min(r - p0 + 1, nc);
    if (WD > 0) {
      double l[WD > 0 ? WD : 1];
      for (int t = 0; t < WD; ++t) l[t] = lr[t];
      for (int c = 0; c < cm; ++c) {
        const double* q = dl + c * WD;
        double acc = 0.0;
        for (int t = 0; t < WD; ++t) acc += l[t] * q[t];
        tr[R[p0 + c]] -= acc;
      }
    } else {
      for (int c = 0; c < cm; ++c)
        tr[R[p0 + c]] -= dot(lr, dl + c * wd, wd);
    }
  }
}

}  // namespace sparse_ldlt_detail

SE3DYN_LU_SCALAR inline void SparseLDLT::update(int d, int s, int p0, int p1, const int* map,
                                                double* dlu) {
  const int fd = Sp_[d], wd = Sp_[d + 1] - fd;
  const int fs = Sp_[s], ws = Sp_[s + 1] - fs;
  const int* R = Ri_.data() + Rp_[d];
  const int nr = Rp_[d + 1] - Rp_[d];
  const double* Pd = Lx_.data() + Lxp_[d];
  const double* Ld = Pd + static_cast<long long>(wd) * wd;  // the rows below d
  double* Ls = Lx_.data() + Lxp_[s];
  // D L(c, :)^T of the updated columns
  double* dl = dlu;
  const int nc = p1 - p0;
  for (int c = 0; c < nc; ++c) {
    const double* row = Ld + static_cast<long long>(p0 + c) * wd;
    for (int t = 0; t < wd; ++t) dl[c * wd + t] = row[t] * Pd[t * (wd + 1)];
  }
  namespace dt = sparse_ldlt_detail;
  switch (wd) {
    case 1: dt::ldlt_update<1>(Ld, dl, R, map, Ls, ws, fs, wd, p0, nc, nr); break;
    case 2: dt::ldlt_update<2>(Ld, dl, R, map, Ls, ws, fs, wd, p0, nc, nr); break;
    case 3: dt::ldlt_update<3>(Ld, dl, R, map, Ls, ws, fs, wd, p0, nc, nr); break;
    case 4: dt::ldlt_update<4>(Ld, dl, R, map, Ls, ws, fs, wd, p0, nc, nr); break;
    case 5: dt::ldlt_update<5>(Ld, dl, R, map, Ls, ws, fs, wd, p0, nc, nr); break;
    case 6: dt::ldlt_update<6>(Ld, dl, R, map, Ls, ws, fs, wd, p0, nc, nr); break;
    default: dt::ldlt_update<0>(Ld, dl, R, map, Ls, ws, fs, wd, p0, nc, nr);
  }
}

namespace sparse_ldlt_detail {

// Dense LDL^T of a panel of width W (0: w, known at run time only) and nrow rows: its
// diagonal block row by row, then the rows below, each a forward substitution with L D of the
// block; dl (W x W) receives D_u L(t, u), u < t. Returns -1, or the row whose pivot is not
// sgn * d > ptol * adiag or not finite (its d in *dbad).
template <int W>
SE3DYN_LU_SCALAR inline int ldlt_panel(double* __restrict P, int nrow, int wdyn,
                                       double* __restrict dl, double* __restrict invd,
                                       const double* sgn, const double* adiag, double ptol,
                                       double* dbad) {
  const int w = W > 0 ? W : wdyn;
  for (int i = 0; i < w; ++i) {
    double* row = P + static_cast<long long>(i) * w;
    for (int t = 0; t < i; ++t)
      row[t] = (row[t] - dot(row, dl + t * w, t)) * invd[t];
    double* dli = dl + i * w;
    for (int u = 0; u < i; ++u) dli[u] = row[u] * P[static_cast<long long>(u) * (w + 1)];
    const double d = row[i] - dot(row, dli, i);
    if (!(sgn[i] * d > ptol * adiag[i]) || !std::isfinite(d)) {
      *dbad = d;
      return i;
    }
    row[i] = d;
    invd[i] = 1.0 / d;
  }
  for (int r = w; r < nrow; ++r) {
    double* row = P + static_cast<long long>(r) * w;
    double x[W > 0 ? W : 1];
    if (W > 0) {
      for (int t = 0; t < W; ++t) x[t] = row[t];
      for (int t = 0; t < W; ++t) x[t] = (x[t] - dot(x, dl + t * W, t)) * invd[t];
      for (int t = 0; t < W; ++t) row[t] = x[t];
    } else {
      for (int t = 0; t < w; ++t)
        row[t] = (row[t] - dot(row, dl + t * w, t)) * invd[t];
    }
  }
  return -1;
}

}  // namespace sparse_ldlt_detail

// The panel of supernode s (ldlt_panel). Returns 0, or 1 + the step whose pivot failed
// (status_ set).
inline int SparseLDLT::factor_panel(int s, double* dl, Status& status) {
  const int f = Sp_[s], w = Sp_[s + 1] - f;
  const int nrow = w + Rp_[s + 1] - Rp_[s];
  double* P = Lx_.data() + Lxp_[s];
  double* invd = invd_.data() + f;
  const double* sg = sgn_.data() + f;
  const double* ad = adiag_.data() + f;
  const double ptol = opt_.pivot_tol;
  double d = 0.0;
  int bad;
  namespace dt = sparse_ldlt_detail;
  switch (w) {
    case 1: bad = dt::ldlt_panel<1>(P, nrow, w, dl, invd, sg, ad, ptol, &d); break;
    case 2: bad = dt::ldlt_panel<2>(P, nrow, w, dl, invd, sg, ad, ptol, &d); break;
    case 3: bad = dt::ldlt_panel<3>(P, nrow, w, dl, invd, sg, ad, ptol, &d); break;
    case 4: bad = dt::ldlt_panel<4>(P, nrow, w, dl, invd, sg, ad, ptol, &d); break;
    case 5: bad = dt::ldlt_panel<5>(P, nrow, w, dl, invd, sg, ad, ptol, &d); break;
    case 6: bad = dt::ldlt_panel<6>(P, nrow, w, dl, invd, sg, ad, ptol, &d); break;
    default: bad = dt::ldlt_panel<0>(P, nrow, w, dl, invd, sg, ad, ptol, &d);
  }
  if (bad < 0) return 0;
  status = std::isfinite(d) ? kNotDefinite : kNotFinite;
  return 1 + f + bad;
}

inline int SparseLDLT::factor(const double* values) {
  valid_ = false;
  if (!analyzed_) {
    status_ = kNotAnalyzed;
    return 1;
  }
  std::fill(head_.begin(), head_.end(), -1);
  int code = 0;
  if (split_s2_ > 0) {
    std::fill(head2_.begin(), head2_.end(), -1);
    Status st1 = kOk, st2 = kOk;
    int c1 = 0, c2 = 0;
    Pool::get().run(2, [&](int p) {
      if (p == 0)
        c1 = factor_supernodes(0, split_s1_, values, map_.data(), head_.data(), dl_.data(),
                               dlu_.data(), st1);
      else
        c2 = factor_supernodes(split_s1_, split_s2_, values, map2_.data(), head2_.data(),
                               dl2_.data(), dlu2_.data(), st2);
    });
    code = c1 ? c1 : c2;
    status_ = c1 ? st1 : st2;
    if (code) return code;
    for (int t = split_s2_; t < ns_; ++t) {  // the second run's links first
      if (head2_[t] < 0) continue;
      int d = head2_[t];
      while (next_[d] >= 0) d = next_[d];
      next_[d] = head_[t];
      head_[t] = head2_[t];
    }
    code = factor_supernodes(split_s2_, ns_, values, map_.data(), head_.data(), dl_.data(),
                             dlu_.data(), status_);
  } else {
    code = factor_supernodes(0, ns_, values, map_.data(), head_.data(), dl_.data(), dlu_.data(),
                             status_);
  }
  if (code) return code;
  valid_ = true;
  status_ = kOk;
  return 0;
}

// Supernodes s0 .. s1-1 of factor, with the workspace map, head (descendant lists), dl, dlu
inline int SparseLDLT::factor_supernodes(int s0, int s1, const double* values, int* map,
                                         int* head, double* dl, double* dlu, Status& status) {
  const double dtol = opt_.drop_tol;
  double* Lx = Lx_.data();
  for (int s = s0; s < s1; ++s) {
    const int f = Sp_[s], l = Sp_[s + 1], w = l - f;
    double* P = Lx + Lxp_[s];
    std::fill(P, Lx + Lxp_[s + 1], 0.0);
    // --- A's columns of s
    {
      const int* Sv = Sv_.data();
      const int* Sx = Sx_.data();
      const int q1 = Sq_[2 * s + 1], q2 = Sq_[2 * s + 2];
      for (int q = Sq_[2 * s]; q < q1; ++q) P[Sx[q]] = values[Sv[q]];
      for (int q = q1; q < q2; ++q) P[Sx[q]] += values[Sv[q]];
    }
    if (Zq_[s + 1] > Zq_[s]) {  // the entries left out must still be "zero"
      // (first whether all are +-0, an OR of their bits without the sign: no dependency chain
      // of maxima through the loop)
      std::uint64_t bits = 0;
      for (int q = Zq_[s]; q < Zq_[s + 1]; ++q) {
        std::uint64_t u;
        std::memcpy(&u, values + Zv_[q], sizeof u);
        bits |= u << 1;
      }
      if (bits != 0) {
        double amax = 0.0, zmax = 0.0;
        bool nan = false;
        for (int q = Sq_[2 * s]; q < Sq_[2 * s + 2]; ++q)
          amax = std::max(amax, std::fabs(values[Sv_[q]]));
        for (int q = Zq_[s]; q < Zq_[s + 1]; ++q) {
          const double az = std::fabs(values[Zv_[q]]);
          zmax = std::max(zmax, az);
          nan |= az != az;
        }
        if (nan || !(zmax <= dtol * std::max(amax, zmax))) {
          status = std::isfinite(zmax) && !nan ? kPatternChanged : kNotFinite;
          return 1 + perm_[f];
        }
      }
    }
    for (int i = 0; i < w; ++i) adiag_[f + i] = std::fabs(P[static_cast<long long>(i) * (w + 1)]);
    // --- the updates of the descendants with rows in s
    for (int i = 0; i < w; ++i) map[f + i] = i;
    for (int t = Rp_[s]; t < Rp_[s + 1]; ++t) map[Ri_[t]] = w + (t - Rp_[s]);
    for (int d = head[s]; d != -1;) {
      const int dn = next_[d];
      const int* R = Ri_.data() + Rp_[d];
      const int nr = Rp_[d + 1] - Rp_[d];
      const int p0 = lpos_[d];
      int p1 = p0 + 1;
      while (p1 < nr && R[p1] < l) ++p1;
      update(d, s, p0, p1, map, dlu);
      lpos_[d] = p1;
      if (p1 < nr) {
        const int t = sn_[R[p1]];
        next_[d] = head[t];
        head[t] = d;
      }
      d = dn;
    }
    // --- the panel's own LDL^T
    const int bad = factor_panel(s, dl, status);
    if (bad) return 1 + perm_[bad - 1];
    if (Rp_[s + 1] > Rp_[s]) {
      lpos_[s] = 0;
      const int t = sn_[Ri_[Rp_[s]]];
      next_[s] = head[t];
      head[t] = s;
    }
  }
  return 0;
}

// ---------------------------------------------------------------------------------------------
// solve
// ---------------------------------------------------------------------------------------------
namespace sparse_ldlt_detail {

// The forward (L y = b) and backward (L^T x = y) substitutions with the panel of one
// supernode of width W (0: w at run time): its steps y[0..w) (at ys), its rows below R[0..nr)
// in y.
template <int W>
SE3DYN_LU_SCALAR inline void ldlt_forward(const double* __restrict P, int wdyn, const int* R,
                                          int nr, double* __restrict ys, double* __restrict y) {
  const int w = W > 0 ? W : wdyn;
  for (int i = 1; i < w; ++i) ys[i] -= dot(P + i * w, ys, i);
  const double* Pb = P + static_cast<long long>(w) * w;
  if (W > 0) {
    double x[W > 0 ? W : 1];
    for (int t = 0; t < W; ++t) x[t] = ys[t];
    for (int r = 0; r < nr; ++r) y[R[r]] -= dotw<W>(Pb + static_cast<long long>(r) * W, x);
  } else {
    for (int r = 0; r < nr; ++r) y[R[r]] -= dot(Pb + static_cast<long long>(r) * w, ys, w);
  }
}
template <int W>
SE3DYN_LU_SCALAR inline void ldlt_backward(const double* __restrict P, int wdyn, const int* R,
                                           int nr, double* __restrict ys,
                                           const double* __restrict y) {
  const int w = W > 0 ? W : wdyn;
  const double* Pb = P + static_cast<long long>(w) * w;
  if (W > 0) {
    double x[W > 0 ? W : 1];
    for (int t = 0; t < W; ++t) x[t] = ys[t];
    for (int r = 0; r < nr; ++r) {
      const double yr = y[R[r]];
      const double* row = Pb + static_cast<long long>(r) * W;
      for (int t = 0; t < W; ++t) x[t] -= row[t] * yr;
    }
    for (int i = W - 1; i > 0; --i) {
      const double* row = P + static_cast<long long>(i) * W;
      for (int t = 0; t < i; ++t) x[t] -= row[t] * x[i];
    }
    for (int t = 0; t < W; ++t) ys[t] = x[t];
  } else {
    for (int r = 0; r < nr; ++r) {
      const double yr = y[R[r]];
      const double* row = Pb + static_cast<long long>(r) * w;
      for (int t = 0; t < w; ++t) ys[t] -= row[t] * yr;
    }
    for (int i = w - 1; i > 0; --i) {
      const double yi = ys[i];
      const double* row = P + static_cast<long long>(i) * w;
      for (int t = 0; t < i; ++t) ys[t] -= row[t] * yi;
    }
  }
}

}  // namespace sparse_ldlt_detail

inline void SparseLDLT::solve(double* b) const {
  const int n = n_;
  if (!valid_) {
    for (int i = 0; i < n; ++i) b[i] = std::numeric_limits<double>::quiet_NaN();
    return;
  }
  double* y = work_.data();
  if (split_s2_ == 0) {
    for (int k = 0; k < n; ++k) y[k] = b[perm_[k]];
    forward(0, ns_, y);
    for (int k = 0; k < n; ++k) y[k] *= invd_[k];
    backward(ns_, 0, y);
    for (int k = 0; k < n; ++k) {
      b[perm_[k]] = y[k];
      y[k] = 0.0;
    }
    return;
  }
  // the two runs at once (the second in work2_, whose separator rows then hold its updates,
  // added after the first run's), the separator; backwards the separator, then the runs
  const int m1 = split_m1_, m2 = split_m2_;
  sparse_lu_detail::forward_two_parts(b, perm_.data(), m1, m2, n, y, work2_.data(),
                                      [&](int p, double* x) {
                                        if (p == 0) forward(0, split_s1_, x);
                                        else forward(split_s1_, split_s2_, x);
                                      });
  forward(split_s2_, ns_, y);
  for (int k = m2; k < n; ++k) y[k] *= invd_[k];
  backward(ns_, split_s2_, y);
  // Each run's backward substitution reads the separator's rows of y (L^T: the rows below its
  // supernodes), so they are written out and cleared only after both runs (a run clearing
  // them while the other still reads them was the race of issue 28).
  Pool::get().run(2, [&](int p) {
    const int k0 = p == 0 ? 0 : m1, k1 = p == 0 ? m1 : m2;
    for (int k = k0; k < k1; ++k) y[k] *= invd_[k];
    backward(p == 0 ? split_s1_ : split_s2_, p == 0 ? 0 : split_s1_, y);
    for (int k = k0; k < k1; ++k) {
      b[perm_[k]] = y[k];
      y[k] = 0.0;
    }
  });
  for (int k = m2; k < n; ++k) {
    b[perm_[k]] = y[k];
    y[k] = 0.0;
  }
}

// L y = P b over the supernodes s0 .. s1-1 (their steps and the rows below them in y)
inline void SparseLDLT::forward(int s0, int s1, double* y) const {
  const double* Lx = Lx_.data();
  namespace dt = sparse_ldlt_detail;
  for (int s = s0; s < s1; ++s) {
    const int f = Sp_[s], w = Sp_[s + 1] - f;
    const double* P = Lx + Lxp_[s];
    const int* R = Ri_.data() + Rp_[s];
    const int nr = Rp_[s + 1] - Rp_[s];
    switch (w) {
      case 1: dt::ldlt_forward<1>(P, w, R, nr, y + f, y); break;
      case 2: dt::ldlt_forward<2>(P, w, R, nr, y + f, y); break;
      case 3: dt::ldlt_forward<3>(P, w, R, nr, y + f, y); break;
      case 6: dt::ldlt_forward<6>(P, w, R, nr, y + f, y); break;
      default: dt::ldlt_forward<0>(P, w, R, nr, y + f, y);
    }
  }
}

// L^T z = D^-1 y over the supernodes s1-1 down to s0
inline void SparseLDLT::backward(int s1, int s0, double* y) const {
  const double* Lx = Lx_.data();
  namespace dt = sparse_ldlt_detail;
  for (int s = s1 - 1; s >= s0; --s) {
    const int f = Sp_[s], w = Sp_[s + 1] - f;
    const double* P = Lx + Lxp_[s];
    const int* R = Ri_.data() + Rp_[s];
    const int nr = Rp_[s + 1] - Rp_[s];
    switch (w) {
      case 1: dt::ldlt_backward<1>(P, w, R, nr, y + f, y); break;
      case 2: dt::ldlt_backward<2>(P, w, R, nr, y + f, y); break;
      case 3: dt::ldlt_backward<3>(P, w, R, nr, y + f, y); break;
      case 6: dt::ldlt_backward<6>(P, w, R, nr, y + f, y); break;
      default: dt::ldlt_backward<0>(P, w, R, nr, y + f, y);
    }
  }
}

}  // namespace se3dyn
