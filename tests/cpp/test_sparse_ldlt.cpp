// Standalone test of se3dyn::SparseLDLT (src/se3dyn/_core/sparse_ldlt.hpp).
//
// Build and run:
//
//   g++ -O2 -std=c++17 -pthread -I src/se3dyn/_core tests/cpp/test_sparse_ldlt.cpp -o test_sparse_ldlt
//   ./test_sparse_ldlt [SEED] [--no-timing]
//
// Checks
//   * random symmetric positive definite matrices: block-tridiagonal (blocks of 1 to 7
//     unknowns, grouped), tree-structured (random trees of blocks: the xi block of a mechanism
//     whose joints share bodies), random sparse B B^T + c I; given as both triangles, the lower
//     or the upper one only, with a shuffled value map; backward error
//     |A x - b|_inf / (|A|_inf |x|_inf + |b|_inf) <= 1e-14 for several right-hand sides, the
//     same after a second factor with other values, and a second factor of the same values
//     bit for bit equal;
//   * quasi-definite matrices [H B^T; B -G] with the pivot signs given (set_signs), and the
//     xi block of se3dyn's split iteration: -B B^T with identity rows of dropped equations;
//   * drop_zeros: entries zero in analyze's values (and not kept) are left out of L (fewer
//     entries), and a later factor with such an entry nonzero fails (kPatternChanged);
//   * an indefinite matrix, a singular one (a zero row, a rank-deficient B B^T), a negative
//     definite one without its signs and NaN/Inf values return a nonzero status, solve() then
//     gives NaN;
//   * the fill of block chains and trees grows linearly with their length, and nnz(L) and the
//     multiply-adds agree with a dense count of the same elimination;
//   * threads: the two parts of a two-way dissection (the xi block of a 1000-link chain, and a
//     diagonally dominant one for SparseLU) refactorised and solved on 1, 2 and 3 threads give
//     bit-identical solutions (tests/test_cpp_drivers.py runs this driver built with
//     ThreadSanitizer);
//   * timing (printed, not checked; build with the engine's flags, -O3 -march=native
//     -ffp-contract=off -fno-math-errno, for numbers like its): the xi block of the 1000-link
//     chain's split iteration, block tridiagonal with 1000 dense 6 x 6 blocks, SparseLU (the
//     stepper's options: refactorisation, solve) against SparseLDLT (factorisation, solve).
// The last line is "N passed, N failed"; the exit code is nonzero when a check failed.
#include "sparse_ldlt.hpp"
#include "check.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <functional>
#include <random>
#include <string>
#include <vector>

using se3dyn::SparseLDLT;
using se3dyn::SparseLU;

namespace {


// A symmetric matrix as a dense array (small sizes: the tests build it densely) and the blocks
// of its unknowns.
struct Sym {
  int n = 0;
  std::vector<double> a;  // n x n, row-major, symmetric
  std::vector<int> group;
  double& at(int i, int j) { return a[static_cast<std::size_t>(i) * n + j]; }
  double at(int i, int j) const { return a[static_cast<std::size_t>(i) * n + j]; }
};

// Which triangle(s) of the matrix the CSC pattern holds.
enum Tri { kBoth, kLower, kUpper };

struct Csc {
  int n = 0;
  std::vector<int> p, i, vmap;
  std::vector<double> vals;  // in the value-map order: entry q is vals[vmap[q]]
};

// The nonzero entries (and the explicit zeros in `zeros`) of the chosen triangle(s) in CSC, the
// values stored in a shuffled order (the engine's own order of the values).
Csc to_csc(const Sym& A, Tri tri, std::mt19937_64& rng, const std::vector<char>* zeros = nullptr) {
  Csc C;
  C.n = A.n;
  C.p.assign(A.n + 1, 0);
  std::vector<double> x;
  for (int j = 0; j < A.n; ++j) {
    for (int r = 0; r < A.n; ++r) {
      if ((tri == kLower && r < j) || (tri == kUpper && r > j)) continue;
      const bool z = zeros && (*zeros)[static_cast<std::size_t>(r) * A.n + j];
      if (A.at(r, j) == 0.0 && !z && r != j) continue;
      C.i.push_back(r);
      x.push_back(A.at(r, j));
    }
    C.p[j + 1] = static_cast<int>(C.i.size());
  }
  const int nz = static_cast<int>(x.size());
  C.vmap.resize(nz);
  for (int q = 0; q < nz; ++q) C.vmap[q] = q;
  std::shuffle(C.vmap.begin(), C.vmap.end(), rng);
  C.vals.assign(nz, 0.0);
  for (int q = 0; q < nz; ++q) C.vals[C.vmap[q]] = x[q];
  return C;
}

// New values of the same pattern (positions of the CSC) from another matrix.
void set_values(Csc& C, const Sym& A) {
  for (int j = 0; j < C.n; ++j)
    for (int q = C.p[j]; q < C.p[j + 1]; ++q) C.vals[C.vmap[q]] = A.at(C.i[q], j);
}

double backward_error(const Sym& A, const double* x, const double* b) {
  double rn = 0, an = 0, xn = 0, bn = 0;
  for (int i = 0; i < A.n; ++i) {
    double r = b[i], ra = 0;
    for (int j = 0; j < A.n; ++j) {
      r -= A.at(i, j) * x[j];
      ra += std::fabs(A.at(i, j));
    }
    rn = std::max(rn, std::fabs(r));
    an = std::max(an, ra);
    xn = std::max(xn, std::fabs(x[i]));
    bn = std::max(bn, std::fabs(b[i]));
  }
  if (!std::isfinite(rn) || !std::isfinite(xn)) return INFINITY;
  return rn / (an * xn + bn);
}

// Random symmetric positive definite matrices --------------------------------------------------

// blocks of 1..maxb unknowns; edges (a, b) between blocks: A = sum over the blocks' "joints" of
// B_e B_e^T, each joint e touching the blocks listed in touch[e] (so A is B B^T with B's rows
// the joints' couplings), plus shift * I
Sym from_couplings(const std::vector<int>& bsize, const std::vector<std::vector<int>>& touch,
                   std::mt19937_64& rng, double shift) {
  Sym A;
  std::vector<int> start(bsize.size() + 1, 0);
  for (std::size_t b = 0; b < bsize.size(); ++b) start[b + 1] = start[b] + bsize[b];
  A.n = start.back();
  A.a.assign(static_cast<std::size_t>(A.n) * A.n, 0.0);
  A.group.resize(A.n);
  for (std::size_t b = 0; b < bsize.size(); ++b)
    for (int t = start[b]; t < start[b + 1]; ++t) A.group[t] = static_cast<int>(b);
  std::normal_distribution<double> nd;
  for (const auto& e : touch) {
    // a coupling of k = 6 rows over the unknowns of the blocks it touches
    std::vector<int> cols;
    for (int b : e)
      for (int t = start[b]; t < start[b + 1]; ++t) cols.push_back(t);
    const int k = 6;
    std::vector<double> Bm(cols.size() * k);
    for (double& v : Bm) v = nd(rng);
    for (std::size_t u = 0; u < cols.size(); ++u)
      for (std::size_t v = 0; v < cols.size(); ++v) {
        double s = 0;
        for (int t = 0; t < k; ++t) s += Bm[u * k + t] * Bm[v * k + t];
        A.at(cols[u], cols[v]) += s;
      }
  }
  for (int i = 0; i < A.n; ++i) A.at(i, i) += shift;
  return A;
}

std::vector<int> random_sizes(int nb, int maxb, std::mt19937_64& rng) {
  std::uniform_int_distribution<int> ud(1, maxb);
  std::vector<int> s(nb);
  for (int& v : s) v = ud(rng);
  return s;
}

Sym block_tridiagonal(int nb, int maxb, std::mt19937_64& rng, double shift = 1e-3) {
  std::vector<std::vector<int>> touch;
  for (int b = 0; b < nb; ++b) touch.push_back({b});
  for (int b = 0; b + 1 < nb; ++b) touch.push_back({b, b + 1});
  return from_couplings(random_sizes(nb, maxb, rng), touch, rng, shift);
}

// a random tree of blocks (parent of block b among 0..b-1), couplings along the edges; the
// blocks numbered in a shuffled order
Sym tree(int nb, int maxb, std::mt19937_64& rng, double shift = 1e-3) {
  std::vector<int> lab(nb);
  for (int b = 0; b < nb; ++b) lab[b] = b;
  std::shuffle(lab.begin(), lab.end(), rng);
  std::vector<std::vector<int>> touch;
  for (int b = 0; b < nb; ++b) touch.push_back({lab[b]});
  for (int b = 1; b < nb; ++b) {
    std::uniform_int_distribution<int> ud(0, b - 1);
    touch.push_back({lab[ud(rng)], lab[b]});
  }
  return from_couplings(random_sizes(nb, maxb, rng), touch, rng, shift);
}

// random sparse: each coupling touches 1..3 random scalar unknowns
Sym random_sparse(int n, int ncoup, std::mt19937_64& rng) {
  std::vector<int> sizes(n, 1);
  std::vector<std::vector<int>> touch;
  std::uniform_int_distribution<int> ui(0, n - 1), uk(1, 3);
  for (int i = 0; i < n; ++i) touch.push_back({i});
  for (int e = 0; e < ncoup; ++e) {
    std::vector<int> t;
    const int k = uk(rng);
    for (int q = 0; q < k; ++q) t.push_back(ui(rng));
    std::sort(t.begin(), t.end());
    t.erase(std::unique(t.begin(), t.end()), t.end());
    touch.push_back(t);
  }
  Sym A = from_couplings(sizes, touch, rng, 1e-2);
  for (int i = 0; i < n; ++i) A.group[i] = i;
  return A;
}

// Checks --------------------------------------------------------------------------------------

// analyze + factor + solves; a second factor with the same values bit for bit equal, a factor
// with other values of the same pattern. Returns the worst backward error.
double accuracy(const Sym& A, const Sym& A2, Tri tri, bool grouped, std::mt19937_64& rng,
                const std::string& tag, const signed char* signs = nullptr,
                double tol = 1e-14) {
  Csc C = to_csc(A, tri, rng);
  SparseLDLT f;
  check(f.analyze(A.n, std::vector<int>(C.p), std::vector<int>(C.i), std::vector<int>(C.vmap),
                  grouped ? A.group.data() : nullptr, C.vals.data()) == 0,
        tag + ": analyze");
  f.set_signs(signs);
  const int st = f.factor(C.vals.data());
  check(st == 0, tag + ": factor status " + std::to_string(st) + " (" +
                     std::to_string(static_cast<int>(f.status())) + ")");
  std::normal_distribution<double> nd;
  double worst = 0;
  std::vector<double> b(A.n), x;
  for (int rep = 0; rep < 3; ++rep) {
    for (auto& v : b) v = nd(rng);
    x = b;
    f.solve(x.data());
    worst = std::max(worst, backward_error(A, x.data(), b.data()));
  }
  check(worst <= tol, tag + ": backward error " + sci(worst));
  // the same values again: bit for bit the same solution
  std::vector<double> x1 = x;
  x = b;
  check(f.factor(C.vals.data()) == 0, tag + ": second factor");
  f.solve(x.data());
  check(x == x1, tag + ": a second factor of the same values is bit for bit the same");
  // other values, the same pattern
  set_values(C, A2);
  check(f.factor(C.vals.data()) == 0, tag + ": factor of other values");
  x = b;
  f.solve(x.data());
  const double e2 = backward_error(A2, x.data(), b.data());
  check(e2 <= tol, tag + ": backward error, other values " + sci(e2));
  return std::max(worst, e2);
}

// nnz(L) and multiply-adds by a dense elimination in the factor's own order (symbolic: the
// fill of Gaussian elimination on the graph)
void dense_counts(const Sym& A, const std::vector<int>& perm, long long& nnz, long long& flops) {
  const int n = A.n;
  std::vector<char> s(static_cast<std::size_t>(n) * n, 0);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j)
      s[static_cast<std::size_t>(i) * n + j] = A.at(perm[i], perm[j]) != 0.0;
  nnz = flops = 0;
  for (int k = 0; k < n; ++k) {
    std::vector<int> rows;
    for (int r = k + 1; r < n; ++r)
      if (s[static_cast<std::size_t>(r) * n + k]) rows.push_back(r);
    nnz += 1 + static_cast<long long>(rows.size());
    const long long c = static_cast<long long>(rows.size());
    flops += c * (c + 1) / 2;
    for (int a : rows)
      for (int b : rows) s[static_cast<std::size_t>(a) * n + b] = 1;
  }
}

void test_random(std::mt19937_64& rng) {
  double worst = 0;
  for (int rep = 0; rep < 12; ++rep) {
    const std::string r = std::to_string(rep);
    const Tri tri = rep % 3 == 0 ? kBoth : (rep % 3 == 1 ? kLower : kUpper);
    {
      const int nb = 5 + rep * 7;
      std::mt19937_64 g(rng());
      std::mt19937_64 g2 = g;
      Sym A = block_tridiagonal(nb, 7, g);
      Sym A2 = block_tridiagonal(nb, 7, g2);  // the same sizes (same seed), other values
      worst = std::max(worst, accuracy(A, A2, tri, rep % 2 == 0, rng, "block tridiagonal " + r));
    }
    {
      const int nb = 4 + rep * 9;
      std::mt19937_64 g(rng());
      std::mt19937_64 g2 = g;
      Sym A = tree(nb, 6, g);
      Sym A2 = tree(nb, 6, g2);
      worst = std::max(worst, accuracy(A, A2, tri, rep % 2 == 1, rng, "tree " + r));
    }
    {
      const int n = 10 + rep * 15;
      std::mt19937_64 g(rng());
      std::mt19937_64 g2 = g;
      Sym A = random_sparse(n, n, g);
      Sym A2 = random_sparse(n, n, g2);
      worst = std::max(worst, accuracy(A, A2, tri, false, rng, "random sparse " + r));
    }
  }
  // ill-conditioned: tiny shifts (B B^T nearly singular where a block has more unknowns than
  // its couplings' rows), still SPD: backward stable
  for (int rep = 0; rep < 4; ++rep) {
    std::mt19937_64 g(rng());
    std::mt19937_64 g2 = g;
    Sym A = tree(30, 6, g, 1e-9);
    Sym A2 = tree(30, 6, g2, 1e-9);
    worst = std::max(worst, accuracy(A, A2, kBoth, true, rng, "ill-conditioned tree " +
                                                                  std::to_string(rep)));
  }
  std::printf("random SPD matrices: worst backward error %s\n", sci(worst).c_str());
}

// the factor's counts against a dense symbolic elimination in its order; fill per unknown
// bounded on chains and trees
void test_counts(std::mt19937_64& rng) {
  for (int rep = 0; rep < 6; ++rep) {
    std::mt19937_64 g(rng());
    Sym A = rep % 2 ? tree(20 + 10 * rep, 6, g) : random_sparse(30 + 20 * rep, 40 + 20 * rep, g);
    Csc C = to_csc(A, kBoth, rng);
    SparseLDLT f;
    f.analyze(A.n, std::vector<int>(C.p), std::vector<int>(C.i), std::vector<int>(C.vmap),
              A.group.data(), C.vals.data());
    long long nnz, flops;
    dense_counts(A, f.perm(), nnz, flops);
    check(nnz == f.nnz_L() && flops == f.factor_flops(),
          "counts " + std::to_string(rep) + ": nnz " + std::to_string(f.nnz_L()) + " vs " +
              std::to_string(nnz) + ", flops " + std::to_string(f.factor_flops()) + " vs " +
              std::to_string(flops));
  }
  // linear fill: per unknown about the same for 50 and 400 blocks
  for (int kind = 0; kind < 2; ++kind) {
    double per[2];
    for (int t = 0; t < 2; ++t) {
      const int nb = t ? 400 : 50;
      std::mt19937_64 g(1234 + kind);
      Sym A = kind ? tree(nb, 6, g) : block_tridiagonal(nb, 6, g);
      Csc C = to_csc(A, kLower, rng);
      SparseLDLT f;
      f.analyze(A.n, std::vector<int>(C.p), std::vector<int>(C.i), std::vector<int>(C.vmap),
                A.group.data(), C.vals.data());
      per[t] = static_cast<double>(f.nnz_L()) / A.n;
      if (t == 1 && kind == 0) {
        // a chain of blocks: supernodes about the blocks (mean width > 2)
        check(A.n / static_cast<double>(f.num_supernodes()) > 2.0,
              "block chain: supernodes " + std::to_string(f.num_supernodes()) + " for n " +
                  std::to_string(A.n));
      }
    }
    check(per[1] <= 1.5 * per[0] + 2,
          std::string(kind ? "tree" : "chain") + ": fill per unknown " + std::to_string(per[0]) +
              " -> " + std::to_string(per[1]));
  }
}

// [H B^T; B -G] with H, G SPD: quasi-definite, pivots of H's unknowns > 0, of G's < 0
void test_quasi_definite(std::mt19937_64& rng) {
  for (int rep = 0; rep < 6; ++rep) {
    std::mt19937_64 g(rng());
    std::mt19937_64 g2 = g;
    Sym H = tree(10 + 3 * rep, 4, g), H2 = tree(10 + 3 * rep, 4, g2);
    Sym G = block_tridiagonal(6 + rep, 3, g), G2 = block_tridiagonal(6 + rep, 3, g2);
    auto build = [&](const Sym& Hm, const Sym& Gm, std::mt19937_64& gg) {
      Sym K;
      K.n = Hm.n + Gm.n;
      K.a.assign(static_cast<std::size_t>(K.n) * K.n, 0.0);
      K.group.resize(K.n);
      for (int i = 0; i < Hm.n; ++i) {
        K.group[i] = Hm.group[i];
        for (int j = 0; j < Hm.n; ++j) K.at(i, j) = Hm.at(i, j);
      }
      const int gb = *std::max_element(Hm.group.begin(), Hm.group.end()) + 1;
      for (int i = 0; i < Gm.n; ++i) {
        K.group[Hm.n + i] = gb + Gm.group[i];
        for (int j = 0; j < Gm.n; ++j) K.at(Hm.n + i, Hm.n + j) = -Gm.at(i, j);
      }
      std::normal_distribution<double> nd;
      std::uniform_int_distribution<int> ui(0, Hm.n - 1);
      for (int i = 0; i < Gm.n; ++i)
        for (int t = 0; t < 3; ++t) {  // B: three entries per row
          const int j = ui(gg);
          const double v = nd(gg);
          K.at(Hm.n + i, j) += v;
          K.at(j, Hm.n + i) += v;
        }
      return K;
    };
    std::mt19937_64 gb(rng());
    std::mt19937_64 gb2 = gb;
    Sym K = build(H, G, gb), K2 = build(H2, G2, gb2);
    std::vector<signed char> sg(K.n, 1);
    for (int i = H.n; i < K.n; ++i) sg[i] = -1;
    accuracy(K, K2, rep % 2 ? kLower : kBoth, true, rng, "quasi-definite " + std::to_string(rep),
             sg.data(), 1e-13);
    // without the signs: a negative pivot, a nonzero status
    Csc C = to_csc(K, kBoth, rng);
    SparseLDLT f;
    f.analyze(K.n, std::vector<int>(C.p), std::vector<int>(C.i), std::vector<int>(C.vmap),
              K.group.data(), C.vals.data());
    check(f.factor(C.vals.data()) != 0 && f.status() == SparseLDLT::kNotDefinite,
          "quasi-definite without its signs: not definite");
  }
}

// se3dyn's xi block: -B B^T (negative definite) with the identity rows and columns of dropped
// equations (rows of B left out), drop_zeros with the keep mask of a generic matrix
void test_xi_block(std::mt19937_64& rng) {
  for (int rep = 0; rep < 4; ++rep) {
    std::mt19937_64 g(rng());
    std::mt19937_64 g2 = g;
    Sym A = tree(40, 6, g, 0.0), A2 = tree(40, 6, g2, 0.0);
    std::vector<char> dropped(A.n, 0);
    std::uniform_int_distribution<int> ui(0, A.n - 1);
    for (int t = 0; t < 5 + rep * 3; ++t) dropped[ui(rng)] = 1;
    // the pattern keeps the dropped rows' entries as explicit zeros (as the engine's does)
    std::vector<char> zeros(static_cast<std::size_t>(A.n) * A.n, 0);
    for (Sym* M : {&A, &A2}) {
      for (int i = 0; i < A.n; ++i)
        for (int j = 0; j < A.n; ++j) {
          double& v = M->at(i, j);
          if (v != 0.0 && (dropped[i] || dropped[j]))
            zeros[static_cast<std::size_t>(i) * A.n + j] = 1;
          v = (dropped[i] || dropped[j]) ? (i == j ? 1.0 : 0.0) : -v;
        }
      // B B^T is singular where a block has more unknowns than rows in its couplings: a tiny
      // definite shift keeps the test about the structure
      for (int i = 0; i < A.n; ++i)
        if (!dropped[i]) M->at(i, i) -= 1e-6;
    }
    std::vector<signed char> sg(A.n);
    for (int i = 0; i < A.n; ++i) sg[i] = dropped[i] ? 1 : -1;
    Csc C = to_csc(A, kBoth, rng, &zeros);
    std::vector<char> keep(C.i.size());
    for (std::size_t q = 0; q < keep.size(); ++q) keep[q] = C.vals[C.vmap[q]] != 0.0;
    SparseLDLT::Options o;
    o.drop_zeros = true;
    SparseLDLT f(o), full;
    check(f.analyze(A.n, std::vector<int>(C.p), std::vector<int>(C.i), std::vector<int>(C.vmap),
                    A.group.data(), C.vals.data(), keep.data()) == 0,
          "xi block: analyze");
    full.analyze(A.n, std::vector<int>(C.p), std::vector<int>(C.i), std::vector<int>(C.vmap),
                 A.group.data(), C.vals.data());
    check(f.nnz_L() < full.nnz_L(), "xi block: the explicit zeros are left out of L (" +
                                        std::to_string(f.nnz_L()) + " < " +
                                        std::to_string(full.nnz_L()) + ")");
    f.set_signs(sg.data());
    check(f.factor(C.vals.data()) == 0, "xi block: factor");
    std::normal_distribution<double> nd;
    std::vector<double> b(A.n), x;
    for (int i = 0; i < A.n; ++i) b[i] = dropped[i] ? 0.0 : nd(rng);
    x = b;
    f.solve(x.data());
    const double e = backward_error(A, x.data(), b.data());
    check(e <= 1e-14, "xi block: backward error " + sci(e));
    bool zero = true;
    for (int i = 0; i < A.n; ++i) zero = zero && (!dropped[i] || x[i] == 0.0);
    check(zero, "xi block: dropped equations' unknowns exactly zero");
    set_values(C, A2);
    check(f.factor(C.vals.data()) == 0, "xi block: factor of other values");
    x = b;
    f.solve(x.data());
    const double e2 = backward_error(A2, x.data(), b.data());
    check(e2 <= 1e-14, "xi block: backward error, other values " + sci(e2));
    // an entry left out turned nonzero: refused
    int q0 = -1;
    for (std::size_t q = 0; q < keep.size(); ++q)
      if (!keep[q]) {
        q0 = static_cast<int>(q);
        break;
      }
    if (q0 >= 0) {
      // (its transpose too: which one of the two is read is the factor's choice)
      int qt = -1;
      int j0 = 0;
      while (C.p[j0 + 1] <= q0) ++j0;
      const int i0 = C.i[q0];
      for (int q = C.p[i0]; q < C.p[i0 + 1]; ++q)
        if (C.i[q] == j0) qt = q;
      std::vector<double> v(C.vals);
      v[C.vmap[q0]] = 1e-3;
      if (qt >= 0) v[C.vmap[qt]] = 1e-3;
      check(f.factor(v.data()) != 0 && f.status() == SparseLDLT::kPatternChanged,
            "xi block: a left-out entry nonzero is refused");
      x = b;
      f.solve(x.data());
      check(std::isnan(x[0]), "xi block: solve after a failed factor gives NaN");
      v[C.vmap[q0]] = NAN;
      if (qt >= 0) v[C.vmap[qt]] = NAN;
      check(f.factor(v.data()) != 0 && f.status() == SparseLDLT::kNotFinite,
            "xi block: a left-out entry NaN is refused (not finite)");
    }
    // without the signs (all positive): refused at the first non-dropped pivot
    f.set_signs(nullptr);
    check(f.factor(C.vals.data()) != 0 && f.status() == SparseLDLT::kNotDefinite,
          "xi block without its signs: not definite");
  }
}

void test_failures(std::mt19937_64& rng) {
  std::normal_distribution<double> nd;
  // indefinite: a definite matrix with one diagonal entry made very negative, at every
  // position of a block chain
  {
    std::mt19937_64 g(rng());
    Sym A = block_tridiagonal(12, 5, g);
    for (int k = 0; k < A.n; k += 3) {
      Sym B = A;
      B.at(k, k) = -1.0;
      Csc C = to_csc(B, kBoth, rng);
      SparseLDLT f;
      f.analyze(B.n, std::vector<int>(C.p), std::vector<int>(C.i), std::vector<int>(C.vmap),
                B.group.data(), C.vals.data());
      const int st = f.factor(C.vals.data());
      check(st != 0 && f.status() == SparseLDLT::kNotDefinite && !f.ok(),
            "indefinite (a_kk = -1 at " + std::to_string(k) + "): status " + std::to_string(st));
      std::vector<double> x(B.n, 1.0);
      f.solve(x.data());
      check(std::isnan(x[0]) && std::isnan(x[B.n - 1]), "indefinite: solve gives NaN");
    }
  }
  // a saddle point matrix [I B^T; B 0] (indefinite, zero diagonal) without signs
  {
    Sym K;
    K.n = 6;
    K.a.assign(36, 0.0);
    for (int i = 0; i < 4; ++i) K.at(i, i) = 1.0;
    for (int i = 4; i < 6; ++i)
      for (int j = 0; j < 4; ++j) K.at(i, j) = K.at(j, i) = nd(rng);
    Csc C = to_csc(K, kBoth, rng);
    SparseLDLT f;
    f.analyze(K.n, std::vector<int>(C.p), std::vector<int>(C.i), std::vector<int>(C.vmap));
    check(f.factor(C.vals.data()) != 0, "saddle point matrix: nonzero status");
  }
  // singular: a zero row and column (structurally: no diagonal entry)
  {
    std::mt19937_64 g(rng());
    Sym A = tree(10, 4, g);
    const int k = A.n / 2;
    for (int j = 0; j < A.n; ++j) A.at(k, j) = A.at(j, k) = 0.0;
    Csc C = to_csc(A, kBoth, rng);
    // (to_csc keeps the diagonal as an explicit zero: remove it for the structural case)
    SparseLDLT f;
    f.analyze(A.n, std::vector<int>(C.p), std::vector<int>(C.i), std::vector<int>(C.vmap));
    check(f.factor(C.vals.data()) != 0 && f.status() == SparseLDLT::kNotDefinite,
          "zero row: not definite");
    Csc D;
    D.n = A.n;
    D.p.assign(A.n + 1, 0);
    std::vector<double> x;
    for (int j = 0; j < A.n; ++j) {
      for (int r = 0; r < A.n; ++r)
        if (A.at(r, j) != 0.0) {
          D.i.push_back(r);
          x.push_back(A.at(r, j));
        }
      D.p[j + 1] = static_cast<int>(D.i.size());
    }
    SparseLDLT f2;
    f2.analyze(A.n, D.p.data(), D.i.data(), nullptr, x.data());
    check(f2.factor(x.data()) == 1 + k, "structurally zero column: status 1 + its index");
  }
  // singular B B^T: 4 unknowns coupled by 3 rows only (exact zero up to round-off: a pivot
  // of round-off size, either sign; with pivot_tol it is refused)
  {
    Sym A;
    A.n = 4;
    A.a.assign(16, 0.0);
    double Bm[3][4];
    for (auto& row : Bm)
      for (double& v : row) v = nd(rng);
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j)
        for (int t = 0; t < 3; ++t) A.at(i, j) += Bm[t][i] * Bm[t][j];
    Csc C = to_csc(A, kBoth, rng);
    SparseLDLT::Options o;
    o.pivot_tol = 1e-12;
    SparseLDLT f(o);
    f.analyze(A.n, std::vector<int>(C.p), std::vector<int>(C.i), std::vector<int>(C.vmap));
    check(f.factor(C.vals.data()) != 0 && f.status() == SparseLDLT::kNotDefinite,
          "rank-deficient B B^T with pivot_tol 1e-12: refused");
  }
  // NaN and Inf values
  for (double bad : {NAN, INFINITY, -INFINITY}) {
    std::mt19937_64 g(rng());
    Sym A = block_tridiagonal(8, 4, g);
    for (int pos : {0, 1, 2}) {
      Sym B = A;
      const int i = pos == 0 ? 0 : B.n - 1, j = pos == 2 ? B.n - 2 : i;
      if (pos == 2 && B.at(i, j) == 0.0) continue;
      B.at(i, j) = bad;
      B.at(j, i) = bad;
      Csc C = to_csc(B, kBoth, rng);
      SparseLDLT f;
      f.analyze(B.n, std::vector<int>(C.p), std::vector<int>(C.i), std::vector<int>(C.vmap));
      const int st = f.factor(C.vals.data());
      check(st != 0 && (f.status() == SparseLDLT::kNotFinite ||
                        f.status() == SparseLDLT::kNotDefinite),
            "non-finite value " + std::to_string(bad) + " at " + std::to_string(pos) +
                ": status " + std::to_string(static_cast<int>(f.status())));
    }
  }
  // not analysed, invalid patterns
  {
    SparseLDLT f;
    double v = 1.0;
    check(f.factor(&v) != 0 && f.status() == SparseLDLT::kNotAnalyzed, "factor before analyze");
    const int cp[3] = {0, 1, 2}, ri[2] = {0, 5};
    check(f.analyze(2, cp, ri) == -1, "row index out of range: analyze -1");
    check(f.factor(&v) != 0 && f.status() == SparseLDLT::kNotAnalyzed,
          "factor after a failed analyze");
  }
  // empty matrix
  {
    SparseLDLT f;
    const int cp[1] = {0};
    check(f.analyze(0, cp, nullptr) == 0 && f.factor(nullptr) == 0, "empty matrix");
  }
}

// The xi block of a chain of nb links (built sparse): block tridiagonal, dense 6 x 6 blocks,
// B B^T of random couplings of neighbouring blocks (each link's joint shares a body with the
// next), both triangles in CSC, grouped by link.
// The xi block of an nb-link chain's split iteration: block tridiagonal with dense 6 x 6
// blocks, B B^T + shift I of random 12 x 6 joint blocks (n = 6 nb), both triangles in CSC form.
struct BlockCsc {
  std::vector<int> cp, ri, group;
  std::vector<double> x;
};
BlockCsc chain_xi_block(std::mt19937_64& rng, int nb, double shift = 1.0) {
  const int n = 6 * nb;
  std::normal_distribution<double> nd;
  std::vector<double> D(36 * static_cast<std::size_t>(nb), 0.0),
      O(36 * static_cast<std::size_t>(nb), 0.0);  // diagonal blocks; O[b]: block (b+1, b)
  for (int b = 0; b < nb; ++b)
    for (int i = 0; i < 6; ++i) D[36 * b + 7 * i] += shift;
  for (int b = 0; b + 1 < nb; ++b) {
    double C[12][6];
    for (auto& row : C)
      for (double& v : row) v = nd(rng);
    for (int i = 0; i < 6; ++i)
      for (int j = 0; j < 6; ++j) {
        double a = 0, c = 0, o = 0;
        for (int t = 0; t < 6; ++t) {
          a += C[i][t] * C[j][t];
          c += C[6 + i][t] * C[6 + j][t];
          o += C[6 + i][t] * C[j][t];
        }
        D[36 * b + 6 * i + j] += a;
        D[36 * (b + 1) + 6 * i + j] += c;
        O[36 * b + 6 * i + j] = o;
      }
  }
  BlockCsc M;
  std::vector<int>&cp = M.cp, &ri = M.ri, &group = M.group;
  std::vector<double>& x = M.x;
  cp.assign(n + 1, 0);
  group.resize(n);
  for (int j = 0; j < n; ++j) {
    const int b = j / 6, c = j % 6;
    group[j] = b;
    if (b > 0)
      for (int i = 0; i < 6; ++i) {  // block (b-1, b) = O[b-1]^T
        ri.push_back(6 * (b - 1) + i);
        x.push_back(O[36 * (b - 1) + 6 * c + i]);
      }
    for (int i = 0; i < 6; ++i) {
      ri.push_back(6 * b + i);
      x.push_back(D[36 * b + 6 * i + c]);
    }
    if (b + 1 < nb)
      for (int i = 0; i < 6; ++i) {
        ri.push_back(6 * (b + 1) + i);
        x.push_back(O[36 * b + 6 * i + c]);
      }
    cp[j + 1] = static_cast<int>(ri.size());
  }
  return M;
}

SparseLU::Options xi_lu_options() {
  SparseLU::Options lo;
  lo.drop_zeros = true;
  lo.refactor_tol = 1e-6;
  return lo;
}

// Refactorisations and solves of the two parts of a two-way dissection (n >= DISSECT_MIN) on
// 1, 2 and 3 threads, ten rounds each: the solutions must agree to the last bit (the parts run
// the same operations whatever runs them). SparseLDLT::solve failed this with two threads
// before issue 28's fix (its second part cleared the separator's rows while the first part
// still read them); a ThreadSanitizer build (tests/test_cpp_drivers.py) reports such a race
// even when the bits happen to agree.
void test_threads(std::mt19937_64& rng) {
  const int nb = 1000, n = 6 * nb;
  BlockCsc M = chain_xi_block(rng, nb);
  // (diagonally dominant for the LU: its partial pivoting keeps the pivots inside the parts)
  BlockCsc D = chain_xi_block(rng, nb, 100.0);
  SparseLU lu(xi_lu_options());
  lu.analyze(n, D.cp.data(), D.ri.data(), D.group.data(), D.x.data());
  SparseLDLT::Options o;
  o.drop_zeros = true;
  SparseLDLT ld(o);
  ld.analyze(n, M.cp.data(), M.ri.data(), M.group.data(), M.x.data());
  check(lu.factor(D.x.data()) == 0, "threads: LU factor");
  check(lu.parallel_parts().second > 0, "threads: the LU's refactor and solve take two parts");
  check(ld.parallel_parts().second > 0, "threads: the LDL^T takes two parts");
  std::normal_distribution<double> nd;
  std::vector<double> b(n);
  for (double& v : b) v = nd(rng);
  check(same_bits_on_any_threads(
            n, b.data(), [&] { return lu.refactor(D.x.data()); },
            [&](double* y) { lu.solve(y); }),
        "threads: SparseLU refactor + solve bit-identical on 1, 2, 3 threads");
  check(same_bits_on_any_threads(
            n, b.data(), [&] { return ld.factor(M.x.data()); },
            [&](double* y) { ld.solve(y); }),
        "threads: SparseLDLT factor + solve bit-identical on 1, 2, 3 threads");
}

void timing(std::mt19937_64& rng, int nb) {
  const int n = 6 * nb;
  BlockCsc M = chain_xi_block(rng, nb);
  std::vector<int>&cp = M.cp, &ri = M.ri, &group = M.group;
  std::vector<double>& x = M.x;
  std::normal_distribution<double> nd;
  SparseLU lu(xi_lu_options());
  lu.analyze(n, cp.data(), ri.data(), group.data(), x.data());
  SparseLDLT::Options o;
  o.drop_zeros = true;
  SparseLDLT ld(o);
  ld.analyze(n, cp.data(), ri.data(), group.data(), x.data());
  check(lu.factor(x.data()) == 0 && ld.factor(x.data()) == 0, "timing matrix: factor");
  std::vector<double> b(n), y(n);
  for (double& v : b) v = nd(rng);
  const double tr = timeit([&] { lu.refactor(x.data()); }, 20, 15);
  const double ts = timeit([&] { y = b; lu.solve(y.data()); }, 50, 15);
  const double tf = timeit([&] { ld.factor(x.data()); }, 20, 15);
  const double tl = timeit([&] { y = b; ld.solve(y.data()); }, 50, 15);
  check(ld.factor_flops() < lu.refactor_flops(), "timing matrix: fewer multiply-adds");
  std::printf("xi block of a %d-link chain (n = %d): SparseLU refactor %.1f us (%lld "
              "multiply-adds), solve %.1f us, nnz(L+U) %lld; SparseLDLT factor %.1f us (%lld "
              "multiply-adds), solve %.1f us, nnz(L) %lld, %d supernodes\n",
              nb, n, 1e6 * tr, lu.refactor_flops(), 1e6 * ts, lu.nnz_L() + lu.nnz_U() - n,
              1e6 * tf, ld.factor_flops(), 1e6 * tl, ld.nnz_L(), ld.num_supernodes());
}

}  // namespace

int main(int argc, char** argv) {
  bool timed = true;  // --no-timing: skip the timing (a sanitizer build, tests/test_cpp_drivers.py)
  unsigned long long seed = 20261124ull;
  for (int i = 1; i < argc; ++i) {
    if (std::string(argv[i]) == "--no-timing") timed = false;
    else seed = std::strtoull(argv[i], nullptr, 10);
  }
  std::mt19937_64 rng(seed);
  test_random(rng);
  test_counts(rng);
  test_quasi_definite(rng);
  test_xi_block(rng);
  test_failures(rng);
  test_threads(rng);
  if (timed) timing(rng, 1000);
  return report();
}
