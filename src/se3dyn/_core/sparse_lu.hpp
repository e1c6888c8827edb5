// Sparse LU of a general (unsymmetric) square matrix: generic, header-only, standard library only.
//
//   P A Q = L U      L unit lower triangular, U upper triangular
//
// * analyze: a fill-reducing symmetric ordering Q of the pattern of A + A^T by approximate
//   minimum degree (AMD: Amestoy, Davis & Duff, "An approximate minimum degree ordering
//   algorithm", SIAM J. Matrix Anal. Appl. 17 (1996) 886-905; the quotient-graph formulation of
//   Davis, "Direct Methods for Sparse Linear Systems", SIAM 2006, ch. 7), computed on the graph
//   of the caller's blocks ("groups": e.g. the 6 unknowns of a body) with the block sizes as the
//   initial supervariable weights, so each block stays contiguous in Q. Optionally with values:
//   blocks whose diagonal block is numerically singular (the zero diagonal of saddle-point
//   constraint rows, massless bodies) are not eligible as pivots until a neighbour has been
//   eliminated (a constrained minimum degree in the spirit of Bridson, "An ordering method for
//   the direct solution of saddle-point matrices", 2007): then their diagonal block has
//   received a Schur complement update and the pivots can stay inside it, which keeps the fill
//   close to the symmetric prediction. With drop_zeros the ordering also ignores zero entries.
// * factor: left-looking LU with threshold partial pivoting (Gilbert & Peierls, "Sparse partial
//   pivoting in time proportional to arithmetic operations", SIAM J. Sci. Stat. Comput. 9 (1988)
//   862-874; CSparse cs_lu, Davis 2006 ch. 6; KLU: Davis & Palamadai Natarajan, ACM TOMS 37
//   (2010) 36). Column k of L and U is one sparse triangular solve whose nonzero pattern is the
//   reach of the pattern of A(:, Q[k]) in the graph of the columns of L computed so far (a
//   depth-first search, on the patterns of L pruned by structural symmetry), then a pivot is
//   chosen among the rows not yet pivotal: the diagonal
//   (row Q[k]) when |a_kk| >= pivot_tol * max |a_ik| (KLU's rule; default 0.1, KLU's 1e-3
//   gives a little less fill on some matrices but backward errors up to 1e-11 on hard random
//   ones), else the largest candidate of the column's own block when >= block_pivot_tol * max,
//   else the largest. Afterwards the columns of L and U are sorted and the supernodes of L
//   are found (consecutive columns with nested structure).
// * refactor: new values, same pivot sequence and same L/U patterns (KLU's klu_refactor): no
//   graph search, a fixed sequence of sparse updates per column, applied a supernode (up to 4
//   columns) at a time, and a check of every pivot.
// * solve / solve_transposed / solve_refined: the two triangular solves (column oriented, L by
//   supernodes), the permutations, and optionally iterative refinement.
// * Two halves at once: a graph of 3000 unknowns or more that one level of a breadth-first
//   level structure splits into two parts of at least 30 % each by a separator of at most 2 %
//   (a chain, a long mechanism) is ordered part by part, the separator last (dissect, and
//   minimum degree in each part with the separator's blocks waiting, so that each part is
//   eliminated towards the separator). When the pivots of factor stay inside the parts
//   (split_plan), refactor and solve take the two parts at once on the pool of pool.hpp (the
//   second with its own work vector), then the separator: the same operations in the same
//   order whatever the number of threads.
//
// Data structure invariants after a successful factor (all indices 0-based):
//   Q_[k]      original column eliminated at step k; P_[k] original row pivotal at step k;
//   pinv_[i]   step at which original row i is pivotal (the inverse of P_).
//   L (CSC, strictly lower part, unit diagonal not stored): column k holds rows Li_[Lp_[k] ..
//              Lp_[k+1]) in pivot numbering, all > k, sorted ascending, values Lx_.
//   U (CSC, strictly upper part): column k holds rows Ui_[Up_[k] .. Up_[k+1]) in pivot numbering,
//              all < k, sorted ascending (an order in which the updates of refactor may be
//              applied: L(:, j) only touches rows > j), values Ux_; the diagonal is Ud_[k].
//   Value map: entry p of the pattern of analyze is values[vmap_[p]] in the caller's arrays
//              (empty: values[p], the CSC order).
//   Refactor scatter map: the entries of A(:, Q_[k]) that are in the factor pattern are
//              (value index Rv_[q], pivot row Rr_[q]) for q in [Rp_[k], Rp_[k+1]); the value
//              indices of its entries left out of the pattern (only with drop_zeros) are
//              Rz_[Rzp_[k] .. Rzp_[k+1]).
//   work_      n doubles, all zero between calls (every routine that scatters clears again);
//   work2_     the same, of the second part of the dissection.
//
// No exceptions are thrown by factor/refactor/solve (status codes); refactor and solve do not
// allocate (all memory is sized in analyze and factor). solve() is const but uses the mutable
// work vector: one SparseLU object must not be used by two threads at once.
//
// Test and benchmark: tests/cpp/test_sparse_lu.cpp (matrices from tests/cpp/make_lu_matrices.py).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "pool.hpp"

// The short loops of refactor and solve (trip counts of one to a few tens) run faster as scalar
// code than vectorised with the vector loops' prologues and epilogues (GCC 12, AVX-512:
// refactor -8 %, solve -6 % on the slider-crank's matrix); the arithmetic is the same.
#if defined(__GNUC__) && !defined(__clang__)
#define SE3DYN_LU_SCALAR __attribute__((optimize("no-tree-vectorize")))
#else
#define SE3DYN_LU_SCALAR
#endif

namespace se3dyn {

namespace sparse_lu_detail {

// Whether (colptr, rowind, vmap) is a valid n x n CSC pattern with its value map (empty: the
// CSC order), as analyze takes it (SparseLU and SparseLDLT)
inline bool valid_pattern(int n, const std::vector<int>& colptr, const std::vector<int>& rowind,
                          const std::vector<int>& vmap) {
  if (n < 0 || colptr.size() != static_cast<std::size_t>(n) + 1 || colptr[0] != 0) return false;
  for (int j = 0; j < n; ++j)
    if (colptr[j + 1] < colptr[j]) return false;
  const int nz = colptr[n];
  if (rowind.size() != static_cast<std::size_t>(nz)) return false;
  if (!vmap.empty() && vmap.size() != static_cast<std::size_t>(nz)) return false;
  for (int p = 0; p < nz; ++p)
    if (rowind[p] < 0 || rowind[p] >= n || (!vmap.empty() && vmap[p] < 0)) return false;
  return true;
}

// Refactor's unit lower triangular solve with the diagonal block of a whole supernode j..j+W-1
// of L (column t's entries below the diagonal first at Lx + Lp[t]) on x[j..j+W): the values of
// U(j..j+W-1, k) to u (their magnitudes added to usum and umax in order), x[j..j+W) cleared.
// The same operations in the same order as the loop on x in refactor, with the values in
// registers (that loop waits for every store to x to be read back): refactor -7 % on the
// slider-crank's matrix.
template <int W>
SE3DYN_LU_SCALAR inline void tri(const double* Lx, const int* Lp, int j, double* x, double* u,
                                 double& usum, double& umax) {
  double y[W];
  for (int i = 0; i < W; ++i) {
    y[i] = x[j + i];
    x[j + i] = 0.0;
  }
  for (int t = 0; t < W; ++t) {
    const double yt = y[t];
    u[t] = yt;
    const double ay = std::fabs(yt);
    usum += ay;
    umax = std::max(umax, ay);
    const double* a = Lx + Lp[j + t];
    for (int r = t + 1; r < W; ++r) y[r] -= a[r - t - 1] * yt;
  }
}
// tri for supernodes of one to six columns; false (nothing done) for wider ones
SE3DYN_LU_SCALAR inline bool tri_small(int w, const double* Lx, const int* Lp, int j, double* x,
                                       double* u, double& usum, double& umax) {
  switch (w) {
    case 1: tri<1>(Lx, Lp, j, x, u, usum, umax); return true;
    case 2: tri<2>(Lx, Lp, j, x, u, usum, umax); return true;
    case 3: tri<3>(Lx, Lp, j, x, u, usum, umax); return true;
    case 4: tri<4>(Lx, Lp, j, x, u, usum, umax); return true;
    case 5: tri<5>(Lx, Lp, j, x, u, usum, umax); return true;
    case 6: tri<6>(Lx, Lp, j, x, u, usum, umax); return true;
    default: return false;
  }
}

inline int flip(int i) { return -i - 2; }  // an involution marking "absorbed into i" (CSparse)

// Reset the marker array w (entries equal to 0 mean "dead", they stay 0) when mark + lemax would
// overflow; returns the new mark.
inline int wclear(int mark, int lemax, int* w, int n) {
  if (mark < 2 || mark >= std::numeric_limits<int>::max() - lemax - 2) {
    for (int k = 0; k < n; ++k)
      if (w[k] != 0) w[k] = 1;
    mark = 2;
  }
  return mark;
}

// Non-recursive depth-first search of the tree given by child lists (head/next) from root j,
// writing the postorder into post[k...]; returns the new k.
inline int tdfs(int j, int k, int* head, const int* next, int* post, int* stack) {
  int top = 0;
  stack[0] = j;
  while (top >= 0) {
    const int p = stack[top];
    const int i = head[p];
    if (i == -1) {
      --top;
      post[k++] = p;
    } else {
      head[p] = next[i];
      stack[++top] = i;
    }
  }
  return k;
}

// Approximate minimum degree ordering (Amestoy, Davis & Duff 1996) of a symmetric graph of n
// nodes given without self loops in CSC form (Cp: n+1 column pointers, Ci: the adjacency lists;
// both are destroyed). Node i is initially a supervariable of weight[i] >= 1 variables
// (nvar = sum of the weights): degrees, the dense-row threshold and the elimination count are in
// variables, so the ordering of a block graph is the one of the full graph with each block kept
// together. The implementation follows the quotient-graph algorithm as laid out in CSparse's
// cs_amd (Davis 2006, sec. 7.1): element absorption, mass elimination, supervariable detection
// by hashing, approximate external degrees |Le \ Lk| from one scan of the element lists,
// aggressive absorption, dense nodes (degree > 10 sqrt(nvar)) ordered last, and a final
// postorder of the assembly tree. On return perm[0..n) is the elimination order of the nodes.
//
// Quotient graph storage: each live object i (variable or element) has its list at
// Ci[Cp[i] .. Cp[i] + len[i]): for a variable, first its elen[i] adjacent elements, then its
// adjacent variables; for an element, its variables. Cp[i] = flip(e) marks i as absorbed into
// element e (or merged into supervariable e); nv[i] is the weight of supervariable i (0 for a
// non-principal variable, negated while i is in the pattern of the current pivot element);
// elen[i] = -2 marks an element, -1 a merged/dense/mass-eliminated variable. degree[] holds
// approximate external degrees (variables) or element sizes (elements); the lists head/next/last
// are the degree lists of the variables (head indexed by degree), hhead/next/last the hash
// buckets during supervariable detection; w[] the marker array of the set differences.
// The forward substitution of a two-way dissection (SparseLU::solve, SparseLDLT::solve): the
// permutation (step k takes b[perm[k]]) and the two parts' substitutions at once, fwd(0, w)
// on w and fwd(1, w2) on w2, whose separator rows collect the second part's updates; those are
// then added to w's after the first part's, and w2 is zero again. Steps [0, m1), [m1, m2) are
// the parts, [m2, n) the separator.
template <class Fwd>
inline void forward_two_parts(const double* b, const int* perm, int m1, int m2, int n,
                              double* w, double* w2, Fwd&& fwd) {
  Pool::get().run(2, [&](int p) {
    if (p == 0) {
      for (int k = 0; k < m1; ++k) w[k] = b[perm[k]];
      for (int k = m2; k < n; ++k) w[k] = b[perm[k]];
      fwd(0, w);
    } else {
      for (int k = m1; k < m2; ++k) w2[k] = b[perm[k]];
      fwd(1, w2);
    }
  });
  for (int k = m1; k < m2; ++k) {
    w[k] = w2[k];
    w2[k] = 0.0;
  }
  for (int k = m2; k < n; ++k) {
    w[k] += w2[k];
    w2[k] = 0.0;
  }
}

// Two-way dissection of a graph of n weighted nodes (Cp, Ci: adjacency lists without self
// loops) by one level of a breadth-first level structure from a pseudo-peripheral node (George
// & Liu, "Computer Solution of Large Sparse Positive Definite Systems", 1981, ch. 4 and 8):
// part[b] = 0 or 1 for the nodes before and after the separating level, 2 for the level
// itself; a constraint node (weak) none of whose neighbours lies in its own part joins the
// separator (it could not be a pivot inside its part). Only for graphs of at least
// DISSECT_MIN weight; false (part unset) unless both parts hold at least 30 % of the weight
// and the separator at most 2 %: a chain or a long mechanism, not a compact one.
constexpr int DISSECT_MIN = 3000;
inline bool dissect(int n, const std::vector<int>& Cp, const std::vector<int>& Ci,
                    const int* weight, const char* weak, std::vector<int>& part) {
  long total = 0;
  for (int b = 0; b < n; ++b) total += weight[b];
  if (total < DISSECT_MIN) return false;
  std::vector<int> level(n, -1), queue(n);
  // levels of the component of `root` from root (-1 elsewhere); returns the last node reached
  auto bfs = [&](int root, int base) {
    int head = 0, tail = 0;
    queue[tail++] = root;
    level[root] = base;
    while (head < tail) {
      const int u = queue[head++];
      for (int q = Cp[u]; q < Cp[u + 1]; ++q)
        if (level[Ci[q]] < 0) {
          level[Ci[q]] = level[u] + 1;
          queue[tail++] = Ci[q];
        }
    }
    return std::make_pair(tail, queue[tail - 1]);
  };
  // pseudo-peripheral root of the first component: repeat the search from its last node
  int root = 0, depth = -1;
  for (int it = 0; it < 4; ++it) {
    std::fill(level.begin(), level.end(), -1);
    const int last = bfs(root, 0).second;
    if (level[last] <= depth) break;
    depth = level[last];
    root = last;
  }
  std::fill(level.begin(), level.end(), -1);
  int base = level[bfs(root, 0).second] + 1;
  for (int b = 0; b < n; ++b)  // further components: their levels follow
    if (level[b] < 0) base = level[bfs(b, base).second] + 1;
  std::vector<long> lw(base, 0);
  for (int b = 0; b < n; ++b) lw[level[b]] += weight[b];
  long before = 0;
  int sep = 0;
  while (sep < base && 2 * (before + lw[sep]) <= total) before += lw[sep++];
  if (sep >= base) return false;
  part.assign(n, 0);
  for (int b = 0; b < n; ++b) part[b] = level[b] < sep ? 0 : level[b] > sep ? 1 : 2;
  if (weak)
    for (int b = 0; b < n; ++b) {
      if (!weak[b] || part[b] == 2) continue;
      bool own = false;
      for (int q = Cp[b]; q < Cp[b + 1] && !own; ++q) own = part[Ci[q]] == part[b];
      if (!own) part[b] = 2;
    }
  long w[3] = {0, 0, 0};
  for (int b = 0; b < n; ++b) w[part[b]] += weight[b];
  return 10 * w[0] >= 3 * total && 10 * w[1] >= 3 * total && 50 * w[2] <= total;
}

inline void amd_order(int n, int nvar, std::vector<int>& Cp, std::vector<int>& Ci,
                      const int* weight, int* perm, const char* weak = nullptr) {
  if (n == 0) return;
  int cnz = Cp[n];
  // elbow room for the new elements (an element's list is never longer than the weighted
  // degree of its pivot, which is at most nvar; the live storage never exceeds the initial one)
  const int nzmax = cnz + cnz / 5 + 2 * n + nvar + 1;
  Ci.resize(nzmax);
  int dense = std::max(16, static_cast<int>(10.0 * std::sqrt(static_cast<double>(nvar))));
  dense = std::min(nvar - 2, dense);
  const int nd = std::max(n, nvar) + 1;
  std::vector<int> len(n + 1), nv(n + 1), next(n + 1), head(nd, -1), elen(n + 1), degree(n + 1),
      w(n + 1), hhead(n + 1, -1), last(n + 1, -1), post(n + 1);
  Cp.resize(n + 1);
  for (int k = 0; k < n; ++k) len[k] = Cp[k + 1] - Cp[k];
  len[n] = 0;
  for (int i = 0; i <= n; ++i) {
    next[i] = -1;
    nv[i] = i < n ? weight[i] : 1;
    w[i] = 1;
    elen[i] = 0;
  }
  for (int i = 0; i < n; ++i) {
    int d = 0;
    for (int p = Cp[i]; p < Cp[i + 1]; ++p) d += weight[Ci[p]];
    degree[i] = d;
  }
  degree[n] = 0;
  int mark = wclear(0, 0, w.data(), n);
  elen[n] = -2;
  Cp[n] = -1;
  w[n] = 0;
  int nel = 0;  // variables eliminated so far (weighted)
  // waiting[i]: a weak node not yet in the degree lists (not eligible as a pivot until it is
  // adjacent to an element, i.e. until a neighbour has been eliminated)
  std::vector<char> waiting(n + 1, 0);
  int wscan = 0;
  for (int i = 0; i < n; ++i) {
    const int d = degree[i];
    if (weak && weak[i] && d > 0 && d <= dense) {
      waiting[i] = 1;
    } else if (d == 0) {  // isolated node: an element at once
      elen[i] = -2;
      nel += nv[i];
      Cp[i] = -1;
      w[i] = 0;
    } else if (d > dense && nv[i] > 0) {  // dense node: absorbed into the placeholder n, last
      nel += nv[i];
      nv[n] += nv[i];
      nv[i] = 0;
      elen[i] = -1;
      Cp[i] = flip(n);
    } else {
      if (head[d] != -1) last[head[d]] = i;
      next[i] = head[d];
      head[d] = i;
    }
  }
  int mindeg = 0, lemax = 0;
  while (nel < nvar) {
    // --- the variable k of minimum approximate degree
    int k = -1;
    for (; mindeg < nvar && (k = head[mindeg]) == -1; ++mindeg) {
    }
    if (k >= 0) {
      if (next[k] != -1) last[next[k]] = -1;
      head[mindeg] = next[k];
    } else {  // only waiting nodes are left: take the next one anyway
      while (wscan < n && !(waiting[wscan] && nv[wscan] > 0 && elen[wscan] >= 0)) ++wscan;
      if (wscan == n) break;  // cannot happen with consistent weights; keeps the loop finite
      k = wscan;
      waiting[k] = 0;
      mindeg = std::min(degree[k], nvar);
    }
    const int elenk = elen[k];
    int nvk = nv[k];
    nel += nvk;
    // --- garbage collection of the quotient graph storage
    if (elenk > 0 && cnz + mindeg >= nzmax) {
      for (int j = 0; j < n; ++j) {
        const int p = Cp[j];
        if (p >= 0) {  // j is a live object: remember its first entry, mark the list start
          Cp[j] = Ci[p];
          Ci[p] = flip(j);
        }
      }
      int q = 0;
      for (int p = 0; p < cnz;) {
        const int j = flip(Ci[p++]);
        if (j >= 0) {
          Ci[q] = Cp[j];
          Cp[j] = q++;
          for (int k3 = 0; k3 < len[j] - 1; ++k3) Ci[q++] = Ci[p++];
        }
      }
      cnz = q;
    }
    // --- new element Lk = (union of the variables of the elements adjacent to k) + (variables
    //     adjacent to k), minus k; the absorbed elements point to k
    int dk = 0;
    nv[k] = -nvk;
    int p = Cp[k];
    const int pk1 = (elenk == 0) ? p : cnz;
    int pk2 = pk1;
    for (int k1 = 1; k1 <= elenk + 1; ++k1) {
      int e, pj, ln;
      if (k1 > elenk) {
        e = k;
        pj = p;
        ln = len[k] - elenk;
      } else {
        e = Ci[p++];
        pj = Cp[e];
        ln = len[e];
      }
      for (int k2 = 1; k2 <= ln; ++k2) {
        const int i = Ci[pj++];
        const int nvi = nv[i];
        if (nvi <= 0) continue;  // not a principal variable, or already in Lk
        dk += nvi;
        nv[i] = -nvi;
        Ci[pk2++] = i;
        if (waiting[i]) {  // adjacent to an element now: eligible from here on
          waiting[i] = 0;
          continue;
        }
        if (next[i] != -1) last[next[i]] = last[i];  // out of its degree list
        if (last[i] != -1)
          next[last[i]] = next[i];
        else
          head[degree[i]] = next[i];
      }
      if (e != k) {
        Cp[e] = flip(k);
        w[e] = 0;
      }
    }
    if (elenk != 0) cnz = pk2;
    degree[k] = dk;
    Cp[k] = pk1;
    len[k] = pk2 - pk1;
    elen[k] = -2;
    // --- set differences: for every element e adjacent to a variable of Lk,
    //     w[e] - mark = |Le \ Lk| (weighted)
    mark = wclear(mark, lemax, w.data(), n);
    for (int pk = pk1; pk < pk2; ++pk) {
      const int i = Ci[pk];
      const int eln = elen[i];
      if (eln <= 0) continue;
      const int nvi = -nv[i];
      const int wnvi = mark - nvi;
      for (int q = Cp[i]; q <= Cp[i] + eln - 1; ++q) {
        const int e = Ci[q];
        if (w[e] >= mark)
          w[e] -= nvi;
        else if (w[e] != 0)
          w[e] = degree[e] + wnvi;
      }
    }
    // --- approximate degrees of the variables of Lk, element absorption, mass elimination,
    //     hash keys for the supervariable detection
    for (int pk = pk1; pk < pk2; ++pk) {
      const int i = Ci[pk];
      const int p1 = Cp[i];
      const int p2 = p1 + elen[i] - 1;
      int pn = p1;
      std::size_t h = 0;
      int d = 0;
      for (int q = p1; q <= p2; ++q) {
        const int e = Ci[q];
        if (w[e] != 0) {
          const int dext = w[e] - mark;
          if (dext > 0) {
            d += dext;
            Ci[pn++] = e;
            h += static_cast<std::size_t>(e);
          } else {  // Le is a subset of Lk: aggressive absorption
            Cp[e] = flip(k);
            w[e] = 0;
          }
        }
      }
      elen[i] = pn - p1 + 1;  // the elements kept, and k
      const int p3 = pn;
      const int p4 = p1 + len[i];
      for (int q = p2 + 1; q < p4; ++q) {
        const int j = Ci[q];
        const int nvj = nv[j];
        if (nvj <= 0) continue;  // j is in Lk or no longer a variable
        d += nvj;
        Ci[pn++] = j;
        h += static_cast<std::size_t>(j);
      }
      if (d == 0) {  // i is adjacent to k only: eliminated together with k
        Cp[i] = flip(k);
        const int nvi = -nv[i];
        dk -= nvi;
        nvk += nvi;
        nel += nvi;
        nv[i] = 0;
        elen[i] = -1;
      } else {
        degree[i] = std::min(degree[i], d);
        Ci[pn] = Ci[p3];  // k becomes the first element of i's list
        Ci[p3] = Ci[p1];
        Ci[p1] = k;
        len[i] = pn - p1 + 1;
        const int hb = static_cast<int>(h % static_cast<std::size_t>(n));
        next[i] = hhead[hb];
        hhead[hb] = i;
        last[i] = hb;
      }
    }
    degree[k] = dk;
    lemax = std::max(lemax, dk);
    mark = wclear(mark + lemax, lemax, w.data(), n);
    // --- supervariable detection: variables of Lk with identical lists are merged
    for (int pk = pk1; pk < pk2; ++pk) {
      int i = Ci[pk];
      if (nv[i] >= 0) continue;  // already merged, or mass eliminated
      const int hb = last[i];
      i = hhead[hb];
      hhead[hb] = -1;
      for (; i != -1 && next[i] != -1; i = next[i], ++mark) {
        const int ln = len[i];
        const int eln = elen[i];
        for (int q = Cp[i] + 1; q <= Cp[i] + ln - 1; ++q) w[Ci[q]] = mark;
        int jlast = i;
        for (int j = next[i]; j != -1;) {
          bool ok = (len[j] == ln) && (elen[j] == eln);
          for (int q = Cp[j] + 1; ok && q <= Cp[j] + ln - 1; ++q)
            if (w[Ci[q]] != mark) ok = false;
          if (ok) {  // j is indistinguishable from i: absorb j into i
            Cp[j] = flip(i);
            nv[i] += nv[j];
            nv[j] = 0;
            elen[j] = -1;
            j = next[j];
            next[jlast] = j;
          } else {
            jlast = j;
            j = next[j];
          }
        }
      }
    }
    // --- finalise Lk: back into the degree lists with degree = approximate external degree
    //     + |Lk \ i|
    int pf = pk1;
    for (int pk = pk1; pk < pk2; ++pk) {
      const int i = Ci[pk];
      const int nvi = -nv[i];
      if (nvi <= 0) continue;
      nv[i] = nvi;
      int d = degree[i] + dk - nvi;
      d = std::min(d, nvar - nel - nvi);
      d = std::max(d, 0);
      if (head[d] != -1) last[head[d]] = i;
      next[i] = head[d];
      last[i] = -1;
      head[d] = i;
      mindeg = std::min(mindeg, d);
      degree[i] = d;
      Ci[pf++] = i;
    }
    nv[k] = nvk;
    if ((len[k] = pf - pk1) == 0) {
      Cp[k] = -1;
      w[k] = 0;
    }
    if (elenk != 0) cnz = pf;
  }
  // --- postorder of the assembly tree (parent of i: flip(Cp[i]), -1 for a root); the
  //     non-principal variables come right before their principal variable
  for (int i = 0; i < n; ++i) Cp[i] = flip(Cp[i]);
  for (int j = 0; j <= n; ++j) head[j] = -1;
  for (int j = n; j >= 0; --j) {
    if (nv[j] > 0) continue;
    next[j] = head[Cp[j]];
    head[Cp[j]] = j;
  }
  for (int e = n; e >= 0; --e) {
    if (nv[e] <= 0) continue;
    if (Cp[e] != -1) {
      next[e] = head[Cp[e]];
      head[Cp[e]] = e;
    }
  }
  int k = 0;
  for (int i = 0; i <= n; ++i)
    if (Cp[i] == -1) k = tdfs(i, k, head.data(), next.data(), post.data(), w.data());
  int q = 0;
  for (int t = 0; t < k; ++t)
    if (post[t] < n) perm[q++] = post[t];
}

// Sort the row indices of every column of a CSC matrix (with its values; no index twice in a
// column) in place, a column at a time: workspace of the longest column only (called by factor
// only; a sort by transposing twice would need a copy of the whole matrix).
inline void sort_columns(int n, const std::vector<int>& Ap, std::vector<int>& Ai,
                         std::vector<double>& Ax) {
  std::vector<std::pair<int, double>> col;
  for (int j = 0; j < n; ++j) {
    const int p0 = Ap[j], p1 = Ap[j + 1];
    if (std::is_sorted(Ai.begin() + p0, Ai.begin() + p1)) continue;
    col.clear();
    for (int p = p0; p < p1; ++p) col.emplace_back(Ai[p], Ax[p]);
    std::sort(col.begin(), col.end());
    for (int p = p0; p < p1; ++p) {
      Ai[p] = col[p - p0].first;
      Ax[p] = col[p - p0].second;
    }
  }
}

}  // namespace sparse_lu_detail

class SparseLU {
 public:
  struct Options {
    // factor: the diagonal entry is the pivot when |a_kk| >= pivot_tol * max_i |a_ik| (KLU's
    // default 1e-3); pivot_tol = 1 is plain partial pivoting.
    double pivot_tol = 0.1;
    // factor, when the diagonal is not usable and unknowns are grouped: the largest candidate
    // of the column's own block (a pivot inside the diagonal block keeps the block structure
    // the ordering assumed) when it is >= block_pivot_tol * max_i |a_ik| (a stricter threshold
    // than the diagonal's: these pivots are not the ones the ordering was made for).
    double block_pivot_tol = 0.1;
    // refactor fails (kSmallPivot; the caller then calls factor, which pivots anew) when a
    // pivot is smaller than refactor_tol times the largest entry of its column of candidates,
    // |u_kk| < refactor_tol * max(|u_kk|, max_i |l_ik u_kk|), or not finite. factor chose each
    // pivot >= pivot_tol of its column; a ratio fallen to 1e-5 means element growth up to 1e5
    // in that column (measured on a 10000-link chain three steps later: backward error 4e-13
    // with 1e-6, the refactor refused with 1e-5; the 1000-link chains keep refactoring).
    double refactor_tol = 1e-5;
    // factor: leave the entries of A that are zero in the values given to factor out of the
    // L/U patterns (an iteration matrix whose pattern holds many entries that are zero in a
    // given configuration, or always). "Zero": |a_ij| <= drop_tol * max_i |a_ij| (drop_tol = 0:
    // exact zeros only; a positive drop_tol also drops round-off residues like 1e-40 next to
    // O(1) entries, at the price of a backward error of that order, but an entry that is tiny
    // at factor time only because the motion has just started grows later and makes refactor
    // fail). refactor checks that the entries left out still are "zero" in this sense and
    // fails (kPatternChanged) otherwise. With values given to analyze, the ordering also
    // ignores them.
    bool drop_zeros = false;
    double drop_tol = 0.0;
    // analyze without values: the ordering is computed by the first factor, with its values
    // (weak blocks, see analyze). Off: analyze computes the pattern-only ordering.
    bool order_with_values = true;
  };

  // Status of the last factor / refactor.
  enum Status : int {
    kOk = 0,
    kNotAnalyzed = 1,       // analyze not called (or failed); refactor without a successful factor
    kStructurallyZero = 2,  // no candidate pivot row in a column: structurally singular
    kNumericallyZero = 3,   // all candidate pivots exactly zero
    kNotFinite = 4,         // a value of the factors is Inf or NaN
    kSmallPivot = 5,        // refactor: pivot below refactor_tol of its column
    kPatternChanged = 6,    // refactor (drop_zeros): an entry left out by factor is nonzero now
  };

  SparseLU() = default;
  explicit SparseLU(const Options& opt) : opt_(opt) {}
  void set_options(const Options& opt) { opt_ = opt; }
  // drop_zeros: entries (CSC positions of analyze's pattern) that factor keeps in the patterns
  // even when they are zero in the values it is given (e.g. those nonzero in some state of the
  // problem, so that later refactorisations never meet a left-out entry turned nonzero); nullptr
  // clears the mask.
  void set_keep(const char* mask) {
    if (mask) keep_.assign(mask, mask + (analyzed_ ? colptr_[n_] : 0));
    else keep_.clear();
  }
  const Options& options() const { return opt_; }

  // Pattern of an n x n matrix in CSC (colptr: n+1, rowind: nnz; rows sorted or not; duplicates
  // are summed). `group` (n ints, or nullptr): unknowns with equal ids form a block kept
  // contiguous in the ordering, which is computed on the (smaller) block graph. `values`
  // (optional, in CSC order: typical values, e.g. those of the first factor): blocks with a
  // numerically singular diagonal block wait in the ordering until a neighbour is eliminated
  // (see above), and with drop_zeros the zero entries are left out of the ordering's graph.
  // Without values (and Options::order_with_values, the default) the ordering is left to the
  // first factor, which does the same with its values. The pattern is copied. Returns 0, or -1
  // for an invalid pattern (then factor fails with kNotAnalyzed).
  int analyze(int n, const int* colptr, const int* rowind, const int* group = nullptr,
              const double* values = nullptr);
  // The same with the pattern's arrays taken over (not copied) and the caller's own order of
  // the values: entry p of the pattern is values[vmap[p]] here and in every later call that
  // takes values (the refactorisations read them in place; empty vmap: the CSC order).
  int analyze(int n, std::vector<int>&& colptr, std::vector<int>&& rowind,
              std::vector<int>&& vmap, const int* group = nullptr,
              const double* values = nullptr);

  // Numeric LU with threshold partial pivoting; values in the CSC order of analyze. Returns 0,
  // or 1 + the original column index of the first column without a usable pivot (structurally
  // or numerically zero, or non-finite values); status() tells which.
  int factor(const double* values);

  // New values, the pivot sequence and the patterns of the last factor, which must have
  // succeeded (else kNotAnalyzed: a failed factor leaves no patterns). Returns 0,
  // or 1 + the original column index of the first failing pivot (zero, non-finite, smaller than
  // refactor_tol of its column) or of a column whose left-out entry became nonzero
  // (drop_zeros); after a failure the factors are invalid until the next successful factor or
  // refactor. No allocation.
  int refactor(const double* values);

  // Solve A x = b in place (b: n entries). Requires a successful factor/refactor; otherwise b is
  // filled with NaN. No allocation.
  void solve(double* b) const;
  // Solve A^T x = b in place.
  void solve_transposed(double* b) const;
  // Solve A x = b in place with `iters` steps of iterative refinement in working precision
  // (x += A^-1 (b - A x); Skeel, Math. Comp. 35 (1980) 817-832: one step makes LU with a
  // moderately unstable pivot sequence backward stable). `values` are those of the last
  // factor/refactor (all entries of the pattern are used for the residual). No allocation.
  void solve_refined(const double* values, double* b, int iters = 1) const;

  int n() const { return n_; }
  bool ok() const { return valid_; }
  // Steps of the two parts of the ordering's two-way dissection ([0, n1), [n1, n2); 0, 0:
  // none), after analyze (with values or without, order_with_values off) or factor
  std::pair<int, int> ordering_parts() const { return {split_n1_, split_n2_}; }
  // Steps of the two parts of a two-way dissection that refactor and solve take at once
  // (0, 0: none, or the pivots of the last factor left a part)
  std::pair<int, int> parallel_parts() const {
    return split_ ? std::make_pair(split_n1_, split_n2_) : std::make_pair(0, 0);
  }
  Status status() const { return status_; }
  // Ordering (column order Q: step k eliminates column col_perm()[k]; computed by analyze, or
  // by the first factor when analyze had no values and order_with_values is set) and the row
  // pivots of the last factor.
  const std::vector<int>& col_perm() const { return Q_; }
  const std::vector<int>& row_perm() const { return P_; }
  // Number of entries of L and of U including their diagonals (as SuperLU counts them):
  // nnz(L + U) = nnz_L() + nnz_U() - n().
  long long nnz_L() const { return static_cast<long long>(Li_.size()) + n_; }
  long long nnz_U() const { return static_cast<long long>(Ui_.size()) + n_; }
  // Multiply-add pairs of one refactor (the sum over the U entries of the lengths of the L
  // columns they update).
  long long refactor_flops() const { return flops_; }
  // Number of supernodes of L (n() / num_supernodes() is their mean width).
  int num_supernodes() const {
    if (static_cast<int>(snend_.size()) != n_) return 0;
    int c = 0;
    for (int j = 0; j < n_; j = snend_[j]) ++c;
    return c;
  }
  // Reciprocal pivot growth of the last factor/refactor, min_k max|A(:, Q_k)| / max|U(:, k)|
  // (KLU's rgrowth; close to 1 is good, tiny means an unstable factorisation).
  double rgrowth() const { return rgrowth_; }
  // Crude reciprocal condition estimate min|u_kk| / max|u_kk| (KLU's klu_rcond).
  double rcond_pivots() const { return rcond_piv_; }
  // 1-norm condition estimate ||A||_1 ||A^-1||_1 (Hager 1984 / Higham 1988, as LAPACK's dlacon:
  // a few solves with A and A^T). Allocates; not for the hot path. Inf when not factored.
  double condest() const;

 private:
  int dfs(int j, int stamp, int top, int* xi, int* pstack);
  void compute_ordering(const double* values);
  void find_supernodes();
  void count_flops() {
    flops_ = 0;
    for (int k = 0; k < n_; ++k)
      for (int q = Up_[k]; q < Up_[k + 1]; ++q) flops_ += Lp_[Ui_[q] + 1] - Lp_[Ui_[q]];
  }
  // x(R) -= L(R, j..e-1) u for columns j..e-1 of the supernode ending at l = snend_[j]
  // (e <= l), R its rows below l, given the final values u[0..e-j) of those columns (the rows
  // inside the supernode are updated by the caller, a small unit triangular solve)
  inline void supernode_update(int j, int e, int l, const double* u, double* x) const;
  // the position of pattern entry p in the caller's values, and its value there
  int vidx(int p) const { return vmap_.empty() ? p : vmap_[p]; }
  double at(const double* values, int p) const { return values[vidx(p)]; }

  Options opt_;
  int n_ = 0;
  bool analyzed_ = false, valid_ = false, have_pattern_ = false;
  Status status_ = kNotAnalyzed;
  std::vector<int> colptr_, rowind_;  // the pattern of analyze
  std::vector<int> vmap_;             // value map (see the invariants)
  std::vector<int> blk_;              // block of every unknown (0..nb_-1; unknown i without groups)
  std::vector<int> bp_, bm_;          // members of block b: bm_[bp_[b] .. bp_[b+1]), increasing
  int nb_ = 0;
  bool grouped_ = false;              // groups given: pivots inside the block are preferred
  bool ordered_with_values_ = false;  // the ordering has seen values (see order_with_values)
  std::vector<char> keep_;            // set_keep
  std::vector<int> Q_, P_, pinv_;
  std::vector<int> Lp_, Li_, Up_, Ui_;
  std::vector<double> Lx_, Ux_, Ud_;
  std::vector<int> Rp_, Rv_, Rr_, Rz_, Rzp_;  // refactor scatter map (see the invariants)
  std::vector<int> snend_;               // supernode of L containing column j: [.., snend_[j])
  std::vector<int> mark_, xi_, pstack_;  // factor workspace
  std::vector<int> Lpend_;               // factor: end of the pruned pattern of L(:, j), or -1
  mutable std::vector<double> work_;     // zero between calls
  // Two-way dissection (compute_ordering): steps [0, n1) and [n1, n2) eliminate the two parts,
  // [n2, n) the separator; 0, 0 without. split_ (set by factor when the pivots stayed inside
  // the parts, see split_plan): refactor and solve take the two parts at once on the pool of
  // pool.hpp, the second with work2_; the same operations in the same order for any number of
  // threads.
  int split_n1_ = 0, split_n2_ = 0;
  bool split_ = false;
  mutable std::vector<double> work2_;  // zero between calls
  struct RefactorStats {
    double rg = std::numeric_limits<double>::infinity(), anorm = 0.0;
    double dmin = std::numeric_limits<double>::infinity(), dmax = 0.0;
  };
  int refactor_columns(int k0, int k1, const double* values, double* x, RefactorStats& st,
                       Status& status);
  void split_plan();
  void forward(int j0, int j1, double* w) const;
  void backward(int j1, int j0, double* w) const;
  mutable std::vector<double> xwork_, rwork_;  // solve_refined
  double anorm1_ = 0.0, rgrowth_ = 0.0, rcond_piv_ = 0.0;
  long long flops_ = 0;
};

// ---------------------------------------------------------------------------------------------
// analyze
// ---------------------------------------------------------------------------------------------
inline int SparseLU::analyze(int n, const int* colptr, const int* rowind, const int* group,
                             const double* values) {
  if (n < 0 || colptr == nullptr || (n > 0 && rowind == nullptr && colptr[n] > 0)) {
    analyzed_ = valid_ = have_pattern_ = false;
    status_ = kNotAnalyzed;
    n_ = 0;
    return -1;
  }
  return analyze(n, std::vector<int>(colptr, colptr + n + 1),
                 std::vector<int>(rowind, rowind + colptr[n]), {}, group, values);
}

inline int SparseLU::analyze(int n, std::vector<int>&& colptr, std::vector<int>&& rowind,
                             std::vector<int>&& vmap, const int* group, const double* values) {
  analyzed_ = valid_ = have_pattern_ = false;
  status_ = kNotAnalyzed;
  n_ = 0;
  if (!sparse_lu_detail::valid_pattern(n, colptr, rowind, vmap)) return -1;
  n_ = n;
  colptr_.swap(colptr);
  rowind_.swap(rowind);
  vmap_.swap(vmap);

  // --- blocks: the distinct ids renumbered 0..nb-1 in increasing order
  std::vector<int> blk(n);
  int nb = 0;
  if (group) {
    // sort the distinct ids (they may be any ints) to renumber them
    std::vector<int> ids(group, group + n);
    std::sort(ids.begin(), ids.end());
    ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
    nb = static_cast<int>(ids.size());
    for (int i = 0; i < n; ++i) {
      const int b = static_cast<int>(std::lower_bound(ids.begin(), ids.end(), group[i]) -
                                     ids.begin());
      blk[i] = b;
    }
  } else {
    nb = n;
    for (int i = 0; i < n; ++i) blk[i] = i;
  }
  // members of every block, in increasing index order
  std::vector<int> bp(nb + 1, 0), bm(n);
  for (int i = 0; i < n; ++i) ++bp[blk[i] + 1];
  for (int b = 0; b < nb; ++b) bp[b + 1] += bp[b];
  {
    std::vector<int> c(bp.begin(), bp.end() - 1);
    for (int i = 0; i < n; ++i) bm[c[blk[i]]++] = i;
  }
  blk_.swap(blk);
  bp_.swap(bp);
  bm_.swap(bm);
  nb_ = nb;
  grouped_ = group != nullptr;
  ordered_with_values_ = false;
  if (values || !opt_.order_with_values) {
    compute_ordering(values);
  } else {  // deferred to the first factor, which has values
    Q_.resize(n);
    for (int k = 0; k < n; ++k) Q_[k] = k;
  }
  // --- storage of the numeric phases
  P_.assign(n, -1);
  pinv_.assign(n, -1);
  Lp_.assign(n + 1, 0);
  Up_.assign(n + 1, 0);
  Ud_.assign(n, 0.0);
  Rp_.assign(n + 1, 0);
  mark_.assign(n, -1);
  xi_.assign(n, 0);
  pstack_.assign(n, 0);
  work_.assign(n, 0.0);
  work2_.assign(n, 0.0);
  xwork_.assign(n, 0.0);
  rwork_.assign(n, 0.0);
  analyzed_ = true;
  return 0;
}

// The ordering Q (called by analyze, and by the first factor when analyze had no values and
// Options::order_with_values is set): AMD on the block graph of A + A^T, see analyze.
inline void SparseLU::compute_ordering(const double* values) {
  const int n = n_;
  const int nb = nb_;
  const int* cp = colptr_.data();
  const int* ri = rowind_.data();
  const int nz = cp[n];
  const std::vector<int>& blk = blk_;
  const std::vector<int>& bp = bp_;
  const std::vector<int>& bm = bm_;
  // --- block graph of A + A^T without self loops: pattern of A^T first (row lists)
  std::vector<int> Tp(n + 1, 0), Ti(nz), Tv(values ? nz : 0);  // Tv: position in A's arrays
  for (int p = 0; p < nz; ++p) ++Tp[ri[p] + 1];
  for (int i = 0; i < n; ++i) Tp[i + 1] += Tp[i];
  {
    std::vector<int> c(Tp.begin(), Tp.end() - 1);
    for (int j = 0; j < n; ++j)
      for (int p = cp[j]; p < cp[j + 1]; ++p) {
        const int q = c[ri[p]]++;
        Ti[q] = j;
        if (values) Tv[q] = p;
      }
  }
  std::vector<double> colmax;  // analyze with values and drop_zeros: max |A(:, j)|
  if (values && opt_.drop_zeros) {
    colmax.assign(n, 0.0);
    for (int j = 0; j < n; ++j)
      for (int p = cp[j]; p < cp[j + 1]; ++p)
        colmax[j] = std::max(colmax[j], std::fabs(at(values, p)));
  }
  const double dtol = opt_.drop_tol;
  std::vector<int> Cp(nb + 1, 0), Ci, seen(nb, -1);
  Ci.reserve(static_cast<std::size_t>(2) * nz + 1);
  for (int b = 0; b < nb; ++b) {
    seen[b] = b;
    for (int t = bp[b]; t < bp[b + 1]; ++t) {
      const int j = bm[t];
      for (int p = cp[j]; p < cp[j + 1]; ++p) {
        if (!colmax.empty() && std::fabs(at(values, p)) <= dtol * colmax[j]) continue;
        const int c = blk[ri[p]];
        if (seen[c] != b) {
          seen[c] = b;
          Ci.push_back(c);
        }
      }
      for (int p = Tp[j]; p < Tp[j + 1]; ++p) {
        if (!colmax.empty() && std::fabs(at(values, Tv[p])) <= dtol * colmax[Ti[p]]) continue;
        const int c = blk[Ti[p]];
        if (seen[c] != b) {
          seen[c] = b;
          Ci.push_back(c);
        }
      }
    }
    Cp[b + 1] = static_cast<int>(Ci.size());
  }
  std::vector<int>().swap(Tp);
  std::vector<int>().swap(Ti);
  std::vector<int>().swap(Tv);
  std::vector<int> weight(nb), bperm(nb);
  for (int b = 0; b < nb; ++b) weight[b] = bp[b + 1] - bp[b];
  std::vector<char> weak;
  if (values) {
    // weak blocks: numerically singular diagonal block (dense LU with partial pivoting of the
    // block, a pivot <= 1e-10 of the block's largest entry); they wait in the ordering until
    // a neighbour has been eliminated (saddle-point constraint rows, massless bodies)
    weak.assign(nb, 0);
    std::vector<int> loc(n);
    for (int b = 0; b < nb; ++b)
      for (int q = bp[b]; q < bp[b + 1]; ++q) loc[bm[q]] = q - bp[b];
    std::vector<double> D;
    for (int b = 0; b < nb; ++b) {
      const int sb = bp[b + 1] - bp[b];
      if (sb > 64) {
        for (int q = bp[b]; q < bp[b + 1] && !weak[b]; ++q) {
          const int j = bm[q];
          double d = 0.0;
          for (int p = cp[j]; p < cp[j + 1]; ++p)
            if (ri[p] == j) d += at(values, p);
          if (d == 0.0) weak[b] = 1;
        }
        continue;
      }
      D.assign(static_cast<std::size_t>(sb) * sb, 0.0);
      double dmax = 0.0;
      for (int q = bp[b]; q < bp[b + 1]; ++q) {
        const int j = bm[q];
        for (int p = cp[j]; p < cp[j + 1]; ++p)
          if (blk[ri[p]] == b) D[loc[ri[p]] * sb + loc[j]] += at(values, p);
      }
      for (const double v : D) dmax = std::max(dmax, std::fabs(v));
      bool singular = !(dmax > 0.0);
      for (int c = 0; c < sb && !singular; ++c) {
        int ip = c;
        for (int r = c + 1; r < sb; ++r)
          if (std::fabs(D[r * sb + c]) > std::fabs(D[ip * sb + c])) ip = r;
        if (!(std::fabs(D[ip * sb + c]) > 1e-10 * dmax)) {
          singular = true;
          break;
        }
        if (ip != c)
          for (int t = 0; t < sb; ++t) std::swap(D[c * sb + t], D[ip * sb + t]);
        for (int r = c + 1; r < sb; ++r) {
          const double l = D[r * sb + c] / D[c * sb + c];
          if (l != 0.0)
            for (int t = c + 1; t < sb; ++t) D[r * sb + t] -= l * D[c * sb + t];
        }
      }
      weak[b] = singular;
    }
  }
  // --- two-way dissection (Engine threads: refactor and solve take the two parts at once),
  // else minimum degree on the whole graph
  std::vector<int> part;
  split_n1_ = split_n2_ = 0;
  if (sparse_lu_detail::dissect(nb, Cp, Ci, weight.data(), weak.empty() ? nullptr : weak.data(),
                                part)) {
    int t0 = 0;
    for (int p = 0; p < 3; ++p) {
      // minimum degree on the graph of part p's blocks with the separator's (for p = 2: the
      // separator's alone), whose blocks wait as constraint blocks do (below): they count in
      // their neighbours' degrees, so the part is eliminated towards the separator, not from
      // it (which would fill the separator's rows of every column); the part's blocks in that
      // order. The separator's constraint blocks with a neighbour in a part are eligible at
      // once (that neighbour is eliminated before).
      std::vector<int> idx(nb, -1), mem;
      for (int b = 0; b < nb; ++b)
        if (part[b] == p || part[b] == 2) {
          idx[b] = int(mem.size());
          mem.push_back(b);
        }
      const int m = int(mem.size());
      std::vector<int> sp(m + 1, 0), si, sw(m), sperm(m);
      std::vector<char> sweak(m, 0);
      int nvar = 0, own = 0;
      for (int i = 0; i < m; ++i) {
        const int b = mem[i];
        bool outside = false;
        for (int q = Cp[b]; q < Cp[b + 1]; ++q) {
          if (idx[Ci[q]] >= 0) si.push_back(idx[Ci[q]]);
          else outside = true;
        }
        sp[i + 1] = int(si.size());
        sw[i] = weight[b];
        nvar += weight[b];
        const bool w = !weak.empty() && weak[b];
        sweak[i] = part[b] == p ? w : p < 2 || (w && !outside);
        if (part[b] == p) own += weight[b];
      }
      sparse_lu_detail::amd_order(m, nvar, sp, si, sw.data(), sperm.data(), sweak.data());
      for (int i = 0; i < m; ++i)
        if (part[mem[sperm[i]]] == p) bperm[t0++] = mem[sperm[i]];
      if (p == 0) split_n1_ = own;
      if (p == 1) split_n2_ = split_n1_ + own;
    }
  } else {
    sparse_lu_detail::amd_order(nb, n, Cp, Ci, weight.data(), bperm.data(),
                                weak.empty() ? nullptr : weak.data());
  }
  // --- expand the block order
  Q_.resize(n);
  int k = 0;
  for (int t = 0; t < nb; ++t) {
    const int b = bperm[t];
    for (int q = bp[b]; q < bp[b + 1]; ++q) Q_[k++] = bm[q];
  }
  ordered_with_values_ = values != nullptr;
}

// ---------------------------------------------------------------------------------------------
// factor (Gilbert-Peierls)
// ---------------------------------------------------------------------------------------------

// Depth-first search of the graph of L from original row j (during factor: L's row indices are
// original rows; row i has out-edges to the rows of L(:, pinv[i]) when it is pivotal). Nodes
// are finished onto xi[--top], so xi[top..n) is a topological order of the reach. Non-recursive
// (stack xi[0..head], pstack the position in each list).
inline int SparseLU::dfs(int j, int stamp, int top, int* xi, int* pstack) {
  int head = 0;
  int* stack = xi;  // xi[0..head] is free while top > head (the reach has at most n nodes)
  stack[0] = j;
  while (head >= 0) {
    j = stack[head];
    const int jnew = pinv_[j];
    if (mark_[j] != stamp) {
      mark_[j] = stamp;
      pstack[head] = (jnew < 0) ? 0 : Lp_[jnew];
    }
    bool done = true;
    const int p2 = (jnew < 0) ? 0 : (Lpend_[jnew] >= 0 ? Lpend_[jnew] : Lp_[jnew + 1]);
    for (int p = pstack[head]; p < p2; ++p) {
      const int i = Li_[p];
      if (mark_[i] == stamp) continue;
      pstack[head] = p + 1;
      stack[++head] = i;
      done = false;
      break;
    }
    if (done) {
      --head;
      xi[--top] = j;
    }
  }
  return top;
}

inline int SparseLU::factor(const double* values) {
  valid_ = false;
  have_pattern_ = false;  // the patterns are rebuilt below; kept only if this factor succeeds
  if (!analyzed_) {
    status_ = kNotAnalyzed;
    return 1;
  }
  if (!ordered_with_values_ && opt_.order_with_values) compute_ordering(values);
  const int n = n_;
  const bool drop = opt_.drop_zeros;
  const double tol = opt_.pivot_tol;
  const double dtol = opt_.drop_tol;
  std::fill(pinv_.begin(), pinv_.end(), -1);
  std::fill(mark_.begin(), mark_.end(), -1);
  Lpend_.assign(n, -1);
  Li_.clear();
  Lx_.clear();
  Ui_.clear();
  Ux_.clear();
  Rz_.clear();
  Lp_[0] = Up_[0] = 0;
  double* x = work_.data();
  int* xi = xi_.data();
  int* pstack = pstack_.data();
  double rg = std::numeric_limits<double>::infinity();
  double anorm = 0.0;
  for (int k = 0; k < n; ++k) {
    const int c = Q_[k];
    const int pa = colptr_[c], pb = colptr_[c + 1];
    double cth = 0.0;  // entries with |a| <= cth are left out (drop_zeros)
    if (drop) {
      for (int p = pa; p < pb; ++p) cth = std::max(cth, std::fabs(at(values, p)));
      cth *= dtol;
    }
    // --- reach of the pattern of A(:, c) in the graph of L: xi[top..n), topological order
    int top = n;
    const bool kp = !keep_.empty();
    for (int p = pa; p < pb; ++p) {
      if (drop && std::fabs(at(values, p)) <= cth && !(kp && keep_[p])) continue;
      const int i = rowind_[p];
      if (mark_[i] != k) top = dfs(i, k, top, xi, pstack);
    }
    // --- sparse triangular solve x = L \ A(:, c) on the reach
    double amax = 0.0, asum = 0.0;
    for (int p = pa; p < pb; ++p) {
      const double v = at(values, p);
      asum += std::fabs(v);
      if (drop && std::fabs(v) <= cth && !(kp && keep_[p])) continue;
      x[rowind_[p]] += v;
      amax = std::max(amax, std::fabs(v));
    }
    anorm = std::max(anorm, asum);
    for (int q = top; q < n; ++q) {
      const int i = xi[q];
      const int j = pinv_[i];
      if (j < 0) continue;
      const double xj = x[i];
      for (int p = Lp_[j]; p < Lp_[j + 1]; ++p) x[Li_[p]] -= Lx_[p] * xj;
    }
    // --- pivot: the diagonal row c if large enough, else the largest candidate
    int ipiv = -1;
    double cmax = -1.0, usum = 0.0, umax = 0.0;
    for (int q = top; q < n; ++q) {
      const int i = xi[q];
      const double v = x[i];
      if (pinv_[i] < 0) {
        const double av = std::fabs(v);
        if (av > cmax || ipiv < 0) {
          cmax = av;
          ipiv = i;
        }
        usum += av;
      } else {
        Ui_.push_back(pinv_[i]);
        Ux_.push_back(v);
        usum += std::fabs(v);
        umax = std::max(umax, std::fabs(v));
      }
    }
    Status bad = kOk;
    if (ipiv < 0)
      bad = kStructurallyZero;
    else if (!std::isfinite(usum + asum))
      bad = kNotFinite;
    else if (cmax == 0.0)
      bad = kNumericallyZero;
    if (bad != kOk) {
      for (int q = top; q < n; ++q) x[xi[q]] = 0.0;
      status_ = bad;
      return 1 + c;
    }
    if (pinv_[c] < 0 && mark_[c] == k && std::fabs(x[c]) >= tol * cmax) {
      ipiv = c;
    } else if (grouped_) {
      // no usable diagonal: prefer the largest candidate of the column's own block (a pivot
      // inside the diagonal block keeps the block structure that the ordering assumed)
      const int bc = blk_[c];
      int ib = -1;
      double bmax = -1.0;
      for (int q = top; q < n; ++q) {
        const int i = xi[q];
        if (pinv_[i] < 0 && blk_[i] == bc && std::fabs(x[i]) > bmax) {
          bmax = std::fabs(x[i]);
          ib = i;
        }
      }
      if (ib >= 0 && bmax >= opt_.block_pivot_tol * cmax) ipiv = ib;
    }
    const double piv = x[ipiv];
    umax = std::max(umax, std::fabs(piv));
    if (umax > 0.0) rg = std::min(rg, amax / umax);
    Ud_[k] = piv;
    pinv_[ipiv] = k;
    P_[k] = ipiv;
    const double inv = 1.0 / piv;
    for (int q = top; q < n; ++q) {
      const int i = xi[q];
      if (pinv_[i] < 0) {
        Li_.push_back(i);
        Lx_.push_back(x[i] * inv);
      }
      x[i] = 0.0;
    }
    Lp_[k + 1] = static_cast<int>(Li_.size());
    Up_[k + 1] = static_cast<int>(Ui_.size());
    // symmetric pruning (Eisenstat & Liu, "Exploiting structural symmetry in unsymmetric sparse
    // symbolic factorization", SIAM J. Matrix Anal. Appl. 13 (1992) 202-211; as in KLU): when
    // U(j, k) and L(k, j) are both nonzero, the rows of L(:, j) not yet pivotal are reached
    // through column k, so the depth-first searches of later columns need only its pivotal
    // rows (moved to its front; Lpend_[j] ends them)
    for (int q = Up_[k]; q < Up_[k + 1]; ++q) {
      const int j = Ui_[q];
      if (Lpend_[j] >= 0) continue;
      int pe = Lp_[j + 1];
      bool found = false;
      for (int p = Lp_[j]; p < pe; ++p)
        if (Li_[p] == ipiv) {
          found = true;
          break;
        }
      if (!found) continue;
      int ph = Lp_[j];
      while (ph < pe) {
        if (pinv_[Li_[ph]] >= 0) {
          ++ph;
        } else {
          --pe;
          std::swap(Li_[ph], Li_[pe]);
          std::swap(Lx_[ph], Lx_[pe]);
        }
      }
      Lpend_[j] = pe;
    }
  }
  // --- rows of L in pivot numbering; columns sorted (refactor applies U(:, k) in this order)
  for (int& i : Li_) i = pinv_[i];
  sparse_lu_detail::sort_columns(n, Lp_, Li_, Lx_);
  sparse_lu_detail::sort_columns(n, Up_, Ui_, Ux_);
  // --- refactor scatter map
  Rv_.clear();
  Rr_.clear();
  Rp_[0] = 0;
  Rzp_.assign(n + 1, 0);
  for (int k = 0; k < n; ++k) {
    const int c = Q_[k];
    double cth = 0.0;
    if (drop) {
      for (int p = colptr_[c]; p < colptr_[c + 1]; ++p) cth = std::max(cth, std::fabs(at(values, p)));
      cth *= dtol;
    }
    for (int p = colptr_[c]; p < colptr_[c + 1]; ++p) {
      if (drop && std::fabs(at(values, p)) <= cth && !(!keep_.empty() && keep_[p])) {
        Rz_.push_back(vidx(p));
        continue;
      }
      Rv_.push_back(vidx(p));
      Rr_.push_back(pinv_[rowind_[p]]);
    }
    Rp_[k + 1] = static_cast<int>(Rv_.size());
    Rzp_[k + 1] = static_cast<int>(Rz_.size());
  }
  find_supernodes();
  double dmin = std::numeric_limits<double>::infinity(), dmax = 0.0;
  for (int k = 0; k < n; ++k) {
    dmin = std::min(dmin, std::fabs(Ud_[k]));
    dmax = std::max(dmax, std::fabs(Ud_[k]));
  }
  rcond_piv_ = n ? dmin / dmax : 1.0;
  rgrowth_ = n ? rg : 1.0;
  anorm1_ = anorm;
  have_pattern_ = valid_ = true;
  count_flops();
  split_plan();
  have_pattern_ = valid_ = true;
  status_ = kOk;
  return 0;
}

// Supernodes of L (Davis 2006 sec. 4.13 for Cholesky; SuperLU's for LU): maximal ranges of
// consecutive columns [f, l) with struct(L(:, j)) = {j+1, ..., l-1} + R for every j in the range,
// R = struct(L(:, l-1)) (rows >= l) the rows common to all. Since the columns are sorted, L(:, j)
// holds the l-1-j rows inside the supernode first, then R in the same order for every column.
// If U(j, k) is (structurally) nonzero for some j of a supernode then so is U(j', k) for every
// later j' < k of it (L(j', j) != 0 fills it), so the U(:, k) entries in a supernode form a
// range j..min(l, k)-1: refactor and solve then apply the updates of those columns to R together (one pass
// over R for up to four columns instead of one per column). The suffix property is checked here
// (a violated one would mean a bug; then no supernodes are used). No supernode crosses a
// boundary of the two-way dissection's parts (split_plan).
inline void SparseLU::find_supernodes() {
  const int n = n_;
  snend_.assign(n, 0);
  int j = n - 1;
  int l = n;
  for (; j >= 0; --j) {
    // does column j start a supernode ending at l (i.e. continue the one of column j+1)?
    bool joins = false;
    if (j + 1 < n && l > j + 1) {
      const int c0 = Lp_[j], c1 = Lp_[j + 1], c2 = Lp_[j + 2];
      if (c1 - c0 == c2 - c1 + 1 && Li_[c0] == j + 1) {
        joins = true;
        for (int t = 1; t < c1 - c0; ++t)
          if (Li_[c0 + t] != Li_[c1 + t - 1]) {
            joins = false;
            break;
          }
      }
    }
    // (a supernode ends at a boundary of the dissection's parts, so that refactor and solve
    // may take the parts at once: a cut supernode is still one, its rows and U's ranges are
    // subsets of the whole one's)
    if (!joins || (split_n2_ > 0 && (j + 1 == split_n1_ || j + 1 == split_n2_))) l = j + 1;
    snend_[j] = l;
  }
  // verify the suffix property of U(:, k) in every supernode
  for (int k = 0; k < n; ++k) {
    for (int q = Up_[k]; q < Up_[k + 1];) {
      const int jj = Ui_[q];
      const int w = std::min(snend_[jj], k) - jj;
      if (q + w > Up_[k + 1] || Ui_[q + w - 1] != jj + w - 1) {
        for (int t = 0; t < n; ++t) snend_[t] = t + 1;
        return;
      }
      q += w;
    }
  }
}

SE3DYN_LU_SCALAR inline void SparseLU::supernode_update(int j, int e, int l, const double* u, double* x) const {
  const int* R = Li_.data() + Lp_[l - 1];
  const int nr = Lp_[l] - Lp_[l - 1];
  const double* Lx = Lx_.data();
  int t = j;
  for (; t + 4 <= e; t += 4) {
    const double* a0 = Lx + Lp_[t] + (l - 1 - t);
    const double* a1 = Lx + Lp_[t + 1] + (l - 2 - t);
    const double* a2 = Lx + Lp_[t + 2] + (l - 3 - t);
    const double* a3 = Lx + Lp_[t + 3] + (l - 4 - t);
    const double u0 = u[t - j], u1 = u[t + 1 - j], u2 = u[t + 2 - j], u3 = u[t + 3 - j];
    for (int r = 0; r < nr; ++r) x[R[r]] -= (a0[r] * u0 + a1[r] * u1) + (a2[r] * u2 + a3[r] * u3);
  }
  if (t + 2 <= e) {
    const double* a0 = Lx + Lp_[t] + (l - 1 - t);
    const double* a1 = Lx + Lp_[t + 1] + (l - 2 - t);
    const double u0 = u[t - j], u1 = u[t + 1 - j];
    for (int r = 0; r < nr; ++r) x[R[r]] -= a0[r] * u0 + a1[r] * u1;
    t += 2;
  }
  if (t < e) {
    const double* a0 = Lx + Lp_[t] + (l - 1 - t);
    const double u0 = u[t - j];
    for (int r = 0; r < nr; ++r) x[R[r]] -= a0[r] * u0;
  }
}

// ---------------------------------------------------------------------------------------------
// refactor (same pivots and patterns)
// ---------------------------------------------------------------------------------------------
SE3DYN_LU_SCALAR inline int SparseLU::refactor(const double* values) {
  valid_ = false;
  if (!have_pattern_) {
    status_ = kNotAnalyzed;
    return 1;
  }
  const int n = n_;
  RefactorStats st;
  int code = 0;
  if (split_) {  // the two parts at once, then the separator
    RefactorStats s2;
    Status st1 = kOk, st2 = kOk;
    int c1 = 0, c2 = 0;
    Pool::get().run(2, [&](int p) {
      if (p == 0) c1 = refactor_columns(0, split_n1_, values, work_.data(), st, st1);
      else c2 = refactor_columns(split_n1_, split_n2_, values, work2_.data(), s2, st2);
    });
    // (the first failing step's column, as one pass would report it)
    code = c1 ? c1 : c2;
    status_ = c1 ? st1 : st2;
    st.rg = std::min(st.rg, s2.rg);
    st.anorm = std::max(st.anorm, s2.anorm);
    st.dmin = std::min(st.dmin, s2.dmin);
    st.dmax = std::max(st.dmax, s2.dmax);
    if (!code) code = refactor_columns(split_n2_, n, values, work_.data(), st, status_);
  } else {
    code = refactor_columns(0, n, values, work_.data(), st, status_);
  }
  if (code) return code;
  rcond_piv_ = n ? st.dmin / st.dmax : 1.0;
  rgrowth_ = n ? st.rg : 1.0;
  anorm1_ = st.anorm;
  valid_ = true;
  status_ = kOk;
  return 0;
}

// Steps k0 .. k1-1 of refactor with the work vector x (all zero before and after)
SE3DYN_LU_SCALAR inline int SparseLU::refactor_columns(int k0, int k1, const double* values,
                                                      double* x, RefactorStats& st,
                                                      Status& status) {
  const double dtol = opt_.drop_tol;
  const int* Lp = Lp_.data();
  const int* Li = Li_.data();
  double* Lx = Lx_.data();
  const double rtol = opt_.refactor_tol;
  for (int k = k0; k < k1; ++k) {
    // scatter A(:, Q[k]) in pivot numbering
    double amax = 0.0, asum = 0.0;
    for (int q = Rp_[k]; q < Rp_[k + 1]; ++q) {
      const double v = values[Rv_[q]];
      x[Rr_[q]] += v;
      const double av = std::fabs(v);
      asum += av;
      amax = std::max(amax, av);
    }
    if (Rzp_[k + 1] > Rzp_[k]) {  // entries left out by factor must still be "zero"
      double zmax = 0.0;
      bool znan = false;  // (a NaN kept apart: max() would let a later entry replace it)
      for (int q = Rzp_[k]; q < Rzp_[k + 1]; ++q) {
        const double az = std::fabs(values[Rz_[q]]);
        znan |= az != az;
        zmax = std::max(zmax, az);
      }
      if (znan) zmax = std::numeric_limits<double>::quiet_NaN();
      asum += zmax;
      if (!(zmax <= dtol * std::max(amax, zmax))) {
        for (int q = Rp_[k]; q < Rp_[k + 1]; ++q) x[Rr_[q]] = 0.0;
        status = std::isfinite(zmax) ? kPatternChanged : kNotFinite;
        return 1 + Q_[k];
      }
    }
    st.anorm = std::max(st.anorm, asum);
    // U(:, k) in increasing order, a supernode suffix j..l-1 at a time: the values inside the
    // supernode by a unit lower triangular solve, then the update of the rows below
    double usum = 0.0, umax = 0.0;
    for (int q = Up_[k]; q < Up_[k + 1];) {
      const int j = Ui_[q];
      const int l = snend_[j];
      const int e = std::min(l, k);
      double* u = Ux_.data() + q;
      if (!(e == l && sparse_lu_detail::tri_small(l - j, Lx, Lp, j, x, u, usum, umax))) {
        for (int t = j; t < e; ++t) {
          const double xt = x[t];
          x[t] = 0.0;
          u[t - j] = xt;
          const double axt = std::fabs(xt);
          usum += axt;
          umax = std::max(umax, axt);
          const double* a = Lx + Lp[t];
          for (int r = t + 1; r < l; ++r) x[r] -= a[r - t - 1] * xt;
        }
      }
      supernode_update(j, e, l, u, x);
      q += e - j;
    }
    const double piv = x[k];
    x[k] = 0.0;
    double cmax = std::fabs(piv), csum = cmax;
    for (int p = Lp[k]; p < Lp[k + 1]; ++p) {
      const double av = std::fabs(x[Li[p]]);
      cmax = std::max(cmax, av);
      csum += av;  // a NaN survives a sum, not a max
    }
    const bool finite = std::isfinite(usum + csum + asum);
    if (!finite || !(std::fabs(piv) > rtol * cmax) || piv == 0.0) {
      for (int p = Lp[k]; p < Lp[k + 1]; ++p) x[Li[p]] = 0.0;
      status = finite ? (piv == 0.0 ? kNumericallyZero : kSmallPivot) : kNotFinite;
      return 1 + Q_[k];
    }
    Ud_[k] = piv;
    const double inv = 1.0 / piv;
    for (int p = Lp[k]; p < Lp[k + 1]; ++p) {
      Lx[p] = x[Li[p]] * inv;
      x[Li[p]] = 0.0;
    }
    umax = std::max(umax, std::fabs(piv));
    st.rg = std::min(st.rg, amax / umax);
    st.dmin = std::min(st.dmin, std::fabs(piv));
    st.dmax = std::max(st.dmax, std::fabs(piv));
  }
  return 0;
}

// Whether refactor and solve may take the two parts of the dissection at once: no step of the
// second part updates from a step of the first (U(:, k), k in [n1, n2), has no row < n1), no
// column of the first part reaches a row of the second (L(:, j), j < n1, has no row in
// [n1, n2)), and no supernode crosses a boundary. Partial pivoting outside a part's own rows
// would break it; then both go in one pass, as without dissection.
inline void SparseLU::split_plan() {
  const int n1 = split_n1_, n2 = split_n2_;
  split_ = n1 > 0 && n2 > n1 && n2 <= n_;
  for (int k = n1; k < n2 && split_; ++k)
    for (int q = Up_[k]; q < Up_[k + 1] && split_; ++q) split_ = Ui_[q] >= n1;
  for (int j = 0; j < n1 && split_; ++j) {
    for (int p = Lp_[j]; p < Lp_[j + 1] && split_; ++p) split_ = Li_[p] < n1 || Li_[p] >= n2;
    split_ = split_ && snend_[j] <= n1;
  }
  for (int j = n1; j < n2 && split_; ++j) split_ = snend_[j] <= n2;
}

// ---------------------------------------------------------------------------------------------
// solves
// ---------------------------------------------------------------------------------------------
SE3DYN_LU_SCALAR inline void SparseLU::solve(double* b) const {
  const int n = n_;
  if (!valid_) {
    for (int i = 0; i < n; ++i) b[i] = std::numeric_limits<double>::quiet_NaN();
    return;
  }
  double* w = work_.data();
  if (!split_) {
    for (int k = 0; k < n; ++k) w[k] = b[P_[k]];
    forward(0, n, w);
    backward(n, 0, w);
  } else {
    // L y = P b: the parts at once (the second in work2_, whose separator rows then hold its
    // updates, added after the first part's), then the separator; U z = y: the separator,
    // then the parts at once (their rows are disjoint)
    const int n1 = split_n1_, n2 = split_n2_;
    sparse_lu_detail::forward_two_parts(b, P_.data(), n1, n2, n, w, work2_.data(),
                                        [&](int p, double* x) {
                                          if (p == 0) forward(0, n1, x);
                                          else forward(n1, n2, x);
                                        });
    forward(n2, n, w);
    backward(n, n2, w);
    Pool::get().run(2, [&](int p) {
      const int k0 = p == 0 ? 0 : n1, k1 = p == 0 ? n1 : n;
      if (p == 0) backward(n1, 0, w);
      else backward(n2, n1, w);
      for (int k = k0; k < k1; ++k) {  // x = Q z
        b[Q_[k]] = w[k];
        w[k] = 0.0;
      }
    });
    return;
  }
  for (int k = 0; k < n; ++k) {  // x = Q z
    b[Q_[k]] = w[k];
    w[k] = 0.0;
  }
}

// w = L^-1 w on the steps j0 .. j1-1 (L y = P b), a supernode at a time (a supernode starting
// in the range ends in it)
SE3DYN_LU_SCALAR inline void SparseLU::forward(int j0, int j1, double* w) const {
  const int* Lp = Lp_.data();
  const double* Lx = Lx_.data();
  for (int j = j0; j < j1;) {
    const int l = snend_[j];
    for (int t = j; t < l; ++t) {
      const double xt = w[t];
      const double* a = Lx + Lp[t];
      for (int r = t + 1; r < l; ++r) w[r] -= a[r - t - 1] * xt;
    }
    supernode_update(j, l, l, w + j, w);
    j = l;
  }
}

// U z = y on the steps j1-1 down to j0 (their columns' updates of the rows above)
SE3DYN_LU_SCALAR inline void SparseLU::backward(int j1, int j0, double* w) const {
  const int* Up = Up_.data();
  const int* Ui = Ui_.data();
  const double* Ux = Ux_.data();
  for (int j = j1 - 1; j >= j0; --j) {
    const double xj = (w[j] /= Ud_[j]);
    if (xj == 0.0) continue;
    for (int p = Up[j]; p < Up[j + 1]; ++p) w[Ui[p]] -= Ux[p] * xj;
  }
}

inline void SparseLU::solve_transposed(double* b) const {
  // A^T = Q U^T L^T P: U^T y = Q^T b, L^T z = y, x = P^T z
  const int n = n_;
  if (!valid_) {
    for (int i = 0; i < n; ++i) b[i] = std::numeric_limits<double>::quiet_NaN();
    return;
  }
  double* w = work_.data();
  for (int k = 0; k < n; ++k) w[k] = b[Q_[k]];
  for (int j = 0; j < n; ++j) {
    double s = w[j];
    for (int p = Up_[j]; p < Up_[j + 1]; ++p) s -= Ux_[p] * w[Ui_[p]];
    w[j] = s / Ud_[j];
  }
  for (int j = n - 1; j >= 0; --j) {
    double s = w[j];
    for (int p = Lp_[j]; p < Lp_[j + 1]; ++p) s -= Lx_[p] * w[Li_[p]];
    w[j] = s;
  }
  for (int k = 0; k < n; ++k) {
    b[P_[k]] = w[k];
    w[k] = 0.0;
  }
}

inline void SparseLU::solve_refined(const double* values, double* b, int iters) const {
  const int n = n_;
  if (!valid_) {
    for (int i = 0; i < n; ++i) b[i] = std::numeric_limits<double>::quiet_NaN();
    return;
  }
  double* x = xwork_.data();
  double* r = rwork_.data();
  std::copy(b, b + n, x);
  solve(x);
  for (int it = 0; it < iters; ++it) {
    std::copy(b, b + n, r);
    for (int j = 0; j < n; ++j) {
      const double xj = x[j];
      for (int p = colptr_[j]; p < colptr_[j + 1]; ++p) r[rowind_[p]] -= at(values, p) * xj;
    }
    solve(r);
    for (int i = 0; i < n; ++i) x[i] += r[i];
  }
  std::copy(x, x + n, b);
}

inline double SparseLU::condest() const {
  // Hager's method with Higham's refinements (LAPACK dlacon): estimate ||A^-1||_1 as the max of
  // ||A^-1 x||_1 over a few vectors x on the vertices of the unit 1-norm ball.
  const int n = n_;
  if (!valid_) return std::numeric_limits<double>::infinity();
  if (n == 0) return 0.0;
  std::vector<double> x(n, 1.0 / n), y(n);
  double est = 0.0;
  int jlast = -1;
  for (int it = 0; it < 5; ++it) {
    y = x;
    solve(y.data());
    double e = 0.0;
    for (double v : y) e += std::fabs(v);
    if (it > 0 && e <= est) break;
    est = e;
    for (int i = 0; i < n; ++i) y[i] = y[i] >= 0.0 ? 1.0 : -1.0;
    solve_transposed(y.data());
    int j = 0;
    for (int i = 1; i < n; ++i)
      if (std::fabs(y[i]) > std::fabs(y[j])) j = i;
    if (j == jlast) break;
    jlast = j;
    std::fill(x.begin(), x.end(), 0.0);
    x[j] = 1.0;
  }
  // Higham's extra test vector with alternating signs
  for (int i = 0; i < n; ++i) x[i] = (i % 2 ? -1.0 : 1.0) * (1.0 + static_cast<double>(i) / std::max(n - 1, 1));
  solve(x.data());
  double e2 = 0.0;
  for (double v : x) e2 += std::fabs(v);
  e2 = 2.0 * e2 / (3.0 * n);
  est = std::max(est, e2);
  return est * anorm1_;
}

}  // namespace se3dyn
