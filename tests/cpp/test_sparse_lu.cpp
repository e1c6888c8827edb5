// Standalone test and benchmark of se3dyn::SparseLU (src/se3dyn/_core/sparse_lu.hpp).
//
// Build and run (matrices from tests/cpp/make_lu_matrices.py, written outside the repository):
//
//   python tests/cpp/make_lu_matrices.py /work/scratch-lu/matrices [--big]
//   g++ -O2 -std=c++17 -pthread -I src/se3dyn/_core tests/cpp/test_sparse_lu.cpp -o test_sparse_lu
//   ./test_sparse_lu [MATRIX_DIR]          (default /work/scratch-lu/matrices; missing: skipped)
//
// Checks
//   * random sparse unsymmetric matrices (zero diagonals, needing pivoting), random KKT
//     matrices [[K, B^T], [C, 0]], block chains and binary trees of bodies and joints:
//     backward error |A x - b|_inf / (|A|_inf |x|_inf + |b|_inf) <= 1e-13 after factor, after
//     refactor with perturbed values, and for the transposed solve;
//   * singular matrices (structurally, numerically, NaN/Inf values) return the right status and
//     solve() then gives NaN, not a silent result;
//   * nnz(L + U) grows linearly on chains and binary trees (fill per unknown bounded);
//   * the dumped se3dyn iteration matrices: the same accuracy checks, and a table of timings
//     (analyze / factor / refactor / solve) and nnz(L + U) next to SciPy's splu (COLAMD), whose
//     numbers make_lu_matrices.py measured.
// The last line is "N passed, N failed"; the exit code is nonzero when a check failed.
#include "sparse_lu.hpp"
#include "check.hpp"

#include <chrono>
#include <ctime>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <random>
#include <string>
#include <vector>

using se3dyn::SparseLU;

namespace {


struct Csc {
  int n = 0;
  std::vector<int> p, i, group, group2;
  std::vector<double> x, x2, b;
  long long splu_nnz = -1;
  double splu_fac = -1, splu_sol = -1, splu_berr = -1;
};

// Build a CSC matrix from triplets (duplicates summed; explicit zeros kept in the pattern).
Csc from_triplets(int n, const std::vector<int>& r, const std::vector<int>& c,
                  const std::vector<double>& v) {
  Csc A;
  A.n = n;
  std::vector<std::vector<std::pair<int, double>>> cols(n);
  for (std::size_t t = 0; t < r.size(); ++t) cols[c[t]].push_back({r[t], v[t]});
  A.p.assign(n + 1, 0);
  for (int j = 0; j < n; ++j) {
    auto& col = cols[j];
    std::sort(col.begin(), col.end(),
              [](const auto& a, const auto& b) { return a.first < b.first; });
    for (std::size_t t = 0; t < col.size(); ++t) {
      if (t > 0 && col[t].first == col[t - 1].first) {
        A.x.back() += col[t].second;
        continue;
      }
      A.i.push_back(col[t].first);
      A.x.push_back(col[t].second);
    }
    A.p[j + 1] = static_cast<int>(A.i.size());
  }
  return A;
}

double backward_error(const Csc& A, const std::vector<double>& vals, const double* x,
                      const double* b) {
  const int n = A.n;
  std::vector<double> r(b, b + n), rowabs(n, 0.0);
  for (int j = 0; j < n; ++j)
    for (int p = A.p[j]; p < A.p[j + 1]; ++p) {
      r[A.i[p]] -= vals[p] * x[j];
      rowabs[A.i[p]] += std::fabs(vals[p]);
    }
  double rn = 0, an = 0, xn = 0, bn = 0;
  for (int i = 0; i < n; ++i) {
    rn = std::max(rn, std::fabs(r[i]));
    an = std::max(an, rowabs[i]);
    xn = std::max(xn, std::fabs(x[i]));
    bn = std::max(bn, std::fabs(b[i]));
  }
  if (!std::isfinite(rn) || !std::isfinite(xn)) return INFINITY;
  return rn / (an * xn + bn);
}

double backward_error_t(const Csc& A, const std::vector<double>& vals, const double* x,
                        const double* b) {  // for A^T x = b
  const int n = A.n;
  double rn = 0, an = 0, xn = 0, bn = 0;
  for (int j = 0; j < n; ++j) {
    double s = b[j], ca = 0;
    for (int p = A.p[j]; p < A.p[j + 1]; ++p) {
      s -= vals[p] * x[A.i[p]];
      ca += std::fabs(vals[p]);
    }
    rn = std::max(rn, std::fabs(s));
    an = std::max(an, ca);
    xn = std::max(xn, std::fabs(x[j]));
    bn = std::max(bn, std::fabs(b[j]));
  }
  if (!std::isfinite(rn) || !std::isfinite(xn)) return INFINITY;
  return rn / (an * xn + bn);
}


// Factor, solve, refactor with other values, solve again; solve_transposed. Returns the worst
// backward error; `tag` names the checks.
double accuracy_checks(const Csc& A, const int* group, const std::string& tag, std::mt19937_64& rng,
                       const SparseLU::Options& opt = SparseLU::Options(), double tol = 1e-13,
                       bool values_in_analyze = false) {
  SparseLU lu(opt);
  check(lu.analyze(A.n, A.p.data(), A.i.data(), group,
                   values_in_analyze ? A.x.data() : nullptr) == 0,
        tag + ": analyze");
  const int st = lu.factor(A.x.data());
  check(st == 0, tag + ": factor status " + std::to_string(st) + " (" +
                     std::to_string(static_cast<int>(lu.status())) + ")");
  std::normal_distribution<double> nd;
  std::vector<double> b(A.n), x(A.n);
  for (auto& v : b) v = nd(rng);
  x = b;
  lu.solve(x.data());
  double worst = backward_error(A, A.x, x.data(), b.data());
  check(worst <= tol, tag + ": backward error after factor " + sci(worst));
  x = b;
  lu.solve_transposed(x.data());
  const double et = backward_error_t(A, A.x, x.data(), b.data());
  check(et <= tol, tag + ": backward error of the transposed solve " + sci(et));
  worst = std::max(worst, et);
  // refactor with values perturbed by up to 1 % (the same pattern)
  std::uniform_real_distribution<double> ud(-0.01, 0.01);
  std::vector<double> v2(A.x);
  for (auto& v : v2) v *= 1.0 + ud(rng);
  const int rs = lu.refactor(v2.data());
  if (rs != 0) {  // a pivot degraded too much: the documented fallback
    check(lu.factor(v2.data()) == 0, tag + ": factor after a failed refactor");
  }
  x = b;
  lu.solve(x.data());
  const double e2 = backward_error(A, v2, x.data(), b.data());
  check(e2 <= tol, tag + ": backward error after refactor " + sci(e2));
  worst = std::max(worst, e2);
  // refactor back to the original values: the same solution as the factor
  check(lu.refactor(A.x.data()) == 0, tag + ": refactor with the factor's values");
  x = b;
  lu.solve(x.data());
  const double e3 = backward_error(A, A.x, x.data(), b.data());
  check(e3 <= tol, tag + ": backward error after refactor (original values) " +
                       sci(e3));
  x = b;
  lu.solve_refined(A.x.data(), x.data(), 1);
  const double e4 = backward_error(A, A.x, x.data(), b.data());
  check(e4 <= std::max(e3, 1e-15), tag + ": backward error with one refinement step " +
                                       sci(e4));
  return std::max(worst, e3);
}

// ---------------------------------------------------------------------------------------------
// random matrices

// Random sparse unsymmetric matrix: a random permutation matrix (structural full rank), ~deg
// random entries per column, diagonal entries present (and possibly tiny or zero) for a part of
// the columns only.
Csc random_unsym(int n, int deg, double zero_diag_frac, std::mt19937_64& rng) {
  std::vector<int> r, c;
  std::vector<double> v;
  std::normal_distribution<double> nd;
  std::uniform_real_distribution<double> u01;
  std::vector<int> perm(n);
  for (int i = 0; i < n; ++i) perm[i] = i;
  std::shuffle(perm.begin(), perm.end(), rng);
  for (int j = 0; j < n; ++j) {
    r.push_back(perm[j]);
    c.push_back(j);
    v.push_back(nd(rng));
    for (int t = 0; t < deg; ++t) {
      const int i = static_cast<int>(rng() % n);
      if (i == j) continue;
      r.push_back(i);
      c.push_back(j);
      v.push_back(nd(rng));
    }
    const double q = u01(rng);
    if (q >= zero_diag_frac) {
      r.push_back(j);
      c.push_back(j);
      v.push_back(q < zero_diag_frac + 0.1 ? 1e-6 * nd(rng) : nd(rng));
    } else if (q < 0.5 * zero_diag_frac) {  // explicit zero on the diagonal
      r.push_back(j);
      c.push_back(j);
      v.push_back(0.0);
    }
  }
  return from_triplets(n, r, c, v);
}

// Random KKT matrix [[K, B^T], [C, 0]]: K sparse unsymmetric with a dominant diagonal, B (m x n1)
// sparse with full row rank (row i has an entry in column i * n1 / m), C = B + a perturbation
// on B's pattern; the (2,2) block is an explicit zero diagonal.
Csc random_kkt(int n1, int m, int deg, std::mt19937_64& rng, std::vector<int>* group) {
  std::vector<int> r, c;
  std::vector<double> v;
  std::normal_distribution<double> nd;
  const int n = n1 + m;
  for (int j = 0; j < n1; ++j) {
    r.push_back(j);
    c.push_back(j);
    v.push_back(2.0 * deg + std::fabs(nd(rng)));
    for (int t = 0; t < deg; ++t) {
      const int i = static_cast<int>(rng() % n1);
      const double a = nd(rng);
      r.push_back(i);
      c.push_back(j);
      v.push_back(a);
      r.push_back(j);
      c.push_back(i);
      v.push_back(a + 0.3 * nd(rng));
    }
  }
  for (int i = 0; i < m; ++i) {
    std::vector<int> cols = {static_cast<int>(static_cast<long long>(i) * n1 / m)};
    for (int t = 0; t < 3; ++t) cols.push_back(static_cast<int>(rng() % n1));
    for (const int j : cols) {
      const double bij = nd(rng);
      r.push_back(n1 + i);  // C
      c.push_back(j);
      v.push_back(bij + 0.1 * nd(rng));
      r.push_back(j);  // B^T
      c.push_back(n1 + i);
      v.push_back(bij);
    }
    r.push_back(n1 + i);
    c.push_back(n1 + i);
    v.push_back(0.0);
  }
  if (group) {  // blocks of 3 primal unknowns, blocks of 2 multipliers
    group->resize(n);
    for (int j = 0; j < n1; ++j) (*group)[j] = j / 3;
    for (int i = 0; i < m; ++i) (*group)[n1 + i] = n1 + i / 2;
  }
  return from_triplets(n, r, c, v);
}

// Random orthogonal 6x6 matrix (Gram-Schmidt of a Gaussian matrix), row-major.
void random_orthogonal(std::mt19937_64& rng, double* Q) {
  std::normal_distribution<double> nd;
  for (int i = 0; i < 6; ++i) {
    double* q = Q + 6 * i;
    for (int t = 0; t < 6; ++t) q[t] = nd(rng);
    for (int k = 0; k < i; ++k) {
      double d = 0;
      for (int t = 0; t < 6; ++t) d += q[t] * Q[6 * k + t];
      for (int t = 0; t < 6; ++t) q[t] -= d * Q[6 * k + t];
    }
    double nrm = 0;
    for (int t = 0; t < 6; ++t) nrm += q[t] * q[t];
    nrm = std::sqrt(nrm);
    for (int t = 0; t < 6; ++t) q[t] /= nrm;
  }
}

// Block-structured multibody-like KKT matrix [[M, B^T], [B, 0]]: nb bodies (6 unknowns each,
// SPD mass block, or an explicit zero block for "massless" bodies), joints from body parent[i]
// (-1: ground) to body i with `nc` constraint rows coupling both bodies (the first nc rows of
// random orthogonal 6x6 blocks, like the adjoint matrices of real joints: a chain of them stays
// well conditioned), optional loop joints (only for nc < 6: with nc = 6 a loop is redundant).
// Unknowns numbered body by body then joint by joint (the blocks shuffled when `shuffle`).
// group: one id per body and one per joint.
Csc body_kkt(const std::vector<int>& parent, int nc, double massless_frac,
             const std::vector<std::pair<int, int>>& loops, bool shuffle, std::mt19937_64& rng,
             std::vector<int>& group) {
  std::normal_distribution<double> nd;
  std::uniform_real_distribution<double> u01;
  const int nb = static_cast<int>(parent.size());
  std::vector<std::pair<int, int>> joints;
  for (int i = 0; i < nb; ++i) joints.push_back({parent[i], i});
  for (auto& l : loops) joints.push_back(l);
  const int nj = static_cast<int>(joints.size());
  const int n = 6 * nb + nc * nj;
  std::vector<int> border(nb + nj);
  for (int t = 0; t < nb + nj; ++t) border[t] = t;
  if (shuffle) std::shuffle(border.begin(), border.end(), rng);
  std::vector<int> start(nb + nj);
  int off = 0;
  for (int t = 0; t < nb + nj; ++t) {
    const int blk = border[t];
    start[blk] = off;
    off += blk < nb ? 6 : nc;
  }
  group.assign(n, 0);
  for (int blk = 0; blk < nb + nj; ++blk)
    for (int q = 0; q < (blk < nb ? 6 : nc); ++q) group[start[blk] + q] = blk;
  std::vector<int> r, c;
  std::vector<double> v;
  auto add = [&](int i, int j, double a) {
    r.push_back(i);
    c.push_back(j);
    v.push_back(a);
  };
  for (int i = 0; i < nb; ++i) {
    const bool massless = u01(rng) < massless_frac;
    double G[36];
    for (double& g : G) g = nd(rng);
    for (int a = 0; a < 6; ++a)
      for (int b = 0; b < 6; ++b) {
        double sum = 0;
        for (int k = 0; k < 6; ++k) sum += G[a * 6 + k] * G[b * 6 + k];
        add(start[i] + a, start[i] + b, massless ? 0.0 : sum / 6.0 + (a == b ? 0.5 : 0.0));
      }
  }
  for (int t = 0; t < nj; ++t) {
    const int jr = start[nb + t];
    double sign = 1.0;
    for (const int body : {joints[t].first, joints[t].second}) {
      if (body >= 0) {
        double Q[36];
        random_orthogonal(rng, Q);
        for (int a = 0; a < nc; ++a)
          for (int b = 0; b < 6; ++b) {
            const double x = sign * Q[6 * a + b];
            add(jr + a, start[body] + b, x);
            add(start[body] + b, jr + a, x);
          }
      }
      sign = -1.0;
    }
    for (int a = 0; a < nc; ++a) add(jr + a, jr + a, 0.0);
  }
  return from_triplets(n, r, c, v);
}

std::vector<int> chain_parent(int nb) {
  std::vector<int> p(nb);
  for (int i = 0; i < nb; ++i) p[i] = i - 1;
  return p;
}
std::vector<int> tree_parent(int nb) {
  std::vector<int> p(nb);
  for (int i = 0; i < nb; ++i) p[i] = i == 0 ? -1 : (i - 1) / 2;
  return p;
}

// ---------------------------------------------------------------------------------------------
bool load(const std::string& path, Csc& A) {
  FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return false;
  int64_t hdr[2];
  bool ok = std::fread(hdr, 8, 2, f) == 2;
  if (ok) {
    const int n = static_cast<int>(hdr[0]);
    const std::size_t nz = static_cast<std::size_t>(hdr[1]);
    A.n = n;
    A.p.resize(n + 1);
    A.i.resize(nz);
    A.group.resize(n);
    A.group2.resize(n);
    A.x.resize(nz);
    A.x2.resize(nz);
    A.b.resize(n);
    ok = std::fread(A.p.data(), 4, n + 1, f) == static_cast<std::size_t>(n + 1) &&
         std::fread(A.i.data(), 4, nz, f) == nz &&
         std::fread(A.group.data(), 4, n, f) == static_cast<std::size_t>(n) &&
         std::fread(A.group2.data(), 4, n, f) == static_cast<std::size_t>(n) &&
         std::fread(A.x.data(), 8, nz, f) == nz && std::fread(A.x2.data(), 8, nz, f) == nz &&
         std::fread(A.b.data(), 8, n, f) == static_cast<std::size_t>(n);
  }
  std::fclose(f);
  const std::string sp = path.substr(0, path.size() - 4) + ".splu";
  if (FILE* g = std::fopen(sp.c_str(), "r")) {
    if (std::fscanf(g, "%lld %lf %lf %lf", &A.splu_nnz, &A.splu_fac, &A.splu_sol,
                    &A.splu_berr) != 4)
      A.splu_nnz = -1;
    std::fclose(g);
  }
  return ok;
}

void test_random(std::mt19937_64& rng) {
  std::printf("== random sparse unsymmetric matrices (zero diagonals, pivoting)\n");
  double worst = 0;
  for (int t = 0; t < 60; ++t) {
    const int n = 5 + static_cast<int>(rng() % (t < 40 ? 60 : 3000));
    const int deg = 1 + static_cast<int>(rng() % 5);
    Csc A = random_unsym(n, deg, 0.4, rng);
    std::vector<int> group(n);
    for (int i = 0; i < n; ++i) group[i] = i / (1 + t % 4);
    worst = std::max(worst, accuracy_checks(A, t % 2 ? group.data() : nullptr,
                                            "random unsym #" + std::to_string(t), rng));
    SparseLU::Options o;
    o.pivot_tol = 1.0;  // plain partial pivoting
    worst = std::max(worst, accuracy_checks(A, nullptr, "random unsym ppiv #" + std::to_string(t),
                                            rng, o));
  }
  std::printf("   worst backward error %.2e\n", worst);
  std::printf("== random KKT matrices [[K, B^T], [C, 0]]\n");
  worst = 0;
  for (int t = 0; t < 40; ++t) {
    const int n1 = 4 + static_cast<int>(rng() % (t < 30 ? 80 : 4000));
    const int m = 1 + static_cast<int>(rng() % (n1 / 2 + 1));
    std::vector<int> group;
    Csc A = random_kkt(n1, m, 1 + static_cast<int>(rng() % 4), rng, &group);
    worst = std::max(worst, accuracy_checks(A, t % 2 ? group.data() : nullptr,
                                            "random KKT #" + std::to_string(t), rng,
                                            SparseLU::Options(), 1e-13, t % 3 == 0));
    SparseLU::Options o;
    o.drop_zeros = true;
    worst = std::max(worst, accuracy_checks(A, group.data(), "random KKT dz #" + std::to_string(t),
                                            rng, o, 1e-13, t % 2 == 0));
  }
  std::printf("   worst backward error %.2e\n", worst);
  std::printf("== block KKT chains / trees (massless bodies, loops, shuffled numbering)\n");
  worst = 0;
  for (int t = 0; t < 32; ++t) {
    const int nb = 2 + static_cast<int>(rng() % 200);
    auto par = t % 2 ? tree_parent(nb) : chain_parent(nb);
    const int nc = t % 4 < 2 ? 6 : 3;  // rigid-like (massless bodies allowed), spherical-like
    std::vector<std::pair<int, int>> loops;
    if (nc == 3 && t % 3 == 0) loops.push_back({-1, nb - 1});
    std::vector<int> group;
    Csc A = body_kkt(par, nc, nc == 6 ? 0.5 : 0.0, loops, t % 5 == 0, rng, group);
    worst = std::max(worst, accuracy_checks(A, group.data(), "block KKT #" + std::to_string(t),
                                            rng, SparseLU::Options(), 1e-13, t % 8 >= 4));
  }
  std::printf("   worst backward error %.2e\n", worst);
}

void test_singular(std::mt19937_64& rng) {
  std::printf("== singular matrices\n");
  {  // structurally singular: column 2 empty
    Csc A = from_triplets(4, {0, 1, 3, 0, 3}, {0, 1, 3, 3, 0}, {1, 2, 3, 4, 5});
    SparseLU lu;
    lu.analyze(A.n, A.p.data(), A.i.data());
    const int s = lu.factor(A.x.data());
    check(s == 1 + 2 && lu.status() == SparseLU::kStructurallyZero,
          "empty column: status " + std::to_string(s));
    std::vector<double> b(4, 1.0);
    lu.solve(b.data());
    check(std::isnan(b[0]), "solve after a failed factor gives NaN");
  }
  {  // structurally singular: two columns with their entries in the same single row
    Csc A = from_triplets(3, {0, 1, 1, 2}, {0, 1, 2, 0}, {1, 1, 1, 1});
    SparseLU lu;
    lu.analyze(A.n, A.p.data(), A.i.data());
    const int s = lu.factor(A.x.data());
    check(s > 0 && lu.status() == SparseLU::kStructurallyZero,
          "structural rank 2: status " + std::to_string(s));
  }
  {  // numerically singular: two equal columns (exact arithmetic on small integers)
    Csc A = from_triplets(3, {0, 1, 0, 1, 2}, {0, 0, 1, 1, 2}, {1, 2, 1, 2, 3});
    SparseLU lu;
    lu.analyze(A.n, A.p.data(), A.i.data());
    const int s = lu.factor(A.x.data());
    check(s > 0 && lu.status() == SparseLU::kNumericallyZero,
          "equal columns: status " + std::to_string(s));
  }
  {  // KKT with a redundant constraint (two equal rows of B): exactly singular
    std::vector<int> r, c;
    std::vector<double> v;
    for (int j = 0; j < 3; ++j) {
      r.push_back(j);
      c.push_back(j);
      v.push_back(2.0);
    }
    for (int i = 0; i < 2; ++i) {  // both constraints: x0 + x1 = ..
      for (int j = 0; j < 2; ++j) {
        r.push_back(3 + i);
        c.push_back(j);
        v.push_back(1.0);
        r.push_back(j);
        c.push_back(3 + i);
        v.push_back(1.0);
      }
      r.push_back(3 + i);
      c.push_back(3 + i);
      v.push_back(0.0);
    }
    Csc A = from_triplets(5, r, c, v);
    SparseLU lu;
    lu.analyze(A.n, A.p.data(), A.i.data());
    const int s = lu.factor(A.x.data());
    check(s > 0 && (lu.status() == SparseLU::kNumericallyZero ||
                    lu.status() == SparseLU::kStructurallyZero),
          "redundant constraint: status " + std::to_string(s));
  }
  {  // NaN and Inf values: factor and refactor fail with kNotFinite, no NaN hidden
    Csc A = random_unsym(50, 3, 0.3, rng);
    SparseLU lu;
    lu.analyze(A.n, A.p.data(), A.i.data());
    check(lu.factor(A.x.data()) == 0, "NaN test: regular factor");
    for (const double bad : {NAN, INFINITY}) {
      for (std::size_t at : {std::size_t(0), A.x.size() / 2, A.x.size() - 1}) {
        std::vector<double> v(A.x);
        v[at] = bad;
        check(lu.factor(A.x.data()) == 0, "NaN test: factor");
        const int s1 = lu.refactor(v.data());
        check(s1 > 0 && lu.status() == SparseLU::kNotFinite,
              "non-finite value: refactor status " +
                  std::to_string(static_cast<int>(lu.status())));
        std::vector<double> b(A.n, 1.0);
        lu.solve(b.data());
        check(std::isnan(b[0]), "solve after a failed refactor gives NaN");
        const int s2 = lu.factor(v.data());
        check(s2 > 0 && lu.status() == SparseLU::kNotFinite,
              "non-finite value: factor status " +
                  std::to_string(static_cast<int>(lu.status())));
        check(lu.refactor(A.x.data()) > 0 && lu.status() == SparseLU::kNotAnalyzed,
              "refactor after a failed factor fails");
      }
    }
    check(lu.factor(A.x.data()) == 0, "factor again after failures");
    std::vector<double> b(A.n, 1.0), x(b);
    lu.solve(x.data());
    check(backward_error(A, A.x, x.data(), b.data()) <= 1e-13, "accuracy after failures");
  }
  {  // a NaN in an entry left out of the factors (drop_zeros) is found whatever follows it in
     // its column (a later zero entry must not hide it)
    Csc A = from_triplets(3, {0, 1, 2, 1, 2}, {0, 0, 0, 1, 2}, {4, 0, 0, 3, 2});
    SparseLU::Options o;
    o.drop_zeros = true;
    SparseLU lu(o);
    lu.analyze(A.n, A.p.data(), A.i.data());
    check(lu.factor(A.x.data()) == 0, "left-out entries: factor");
    for (int at : {1, 2}) {  // the NaN before or after the other left-out entry
      std::vector<double> v(A.x);
      v[at] = NAN;
      const int s = lu.refactor(v.data());
      check(s > 0 && lu.status() == SparseLU::kNotFinite,
            "NaN in a left-out entry (" + std::to_string(at) + "): refactor status " +
                std::to_string(static_cast<int>(lu.status())));
      check(lu.factor(A.x.data()) == 0, "left-out entries: factor again");
    }
  }
  {  // refactor: pivot that becomes zero, and a pivot that becomes too small
    Csc A = from_triplets(2, {0, 1, 0, 1}, {0, 0, 1, 1}, {4, 1, 1, 3});
    SparseLU lu;
    lu.analyze(A.n, A.p.data(), A.i.data());
    check(lu.factor(A.x.data()) == 0, "2x2 factor");
    std::vector<double> v = {1, 1, 1, 1};  // singular
    check(lu.refactor(v.data()) > 0 && lu.status() == SparseLU::kNumericallyZero,
          "refactor of a singular matrix fails");
    v = {1e-12, 1, 1, 3};  // a_00 tiny: the kept pivot sequence is unstable
    check(lu.refactor(v.data()) > 0 && lu.status() == SparseLU::kSmallPivot,
          "refactor with a tiny pivot fails");
    check(lu.factor(v.data()) == 0 && lu.row_perm()[0] == 1, "factor then pivots on row 1");
    std::vector<double> b = {1, 2}, x = b;
    lu.solve(x.data());
    check(backward_error(A, v, x.data(), b.data()) <= 1e-15, "2x2 accuracy after re-pivoting");
  }
  {  // drop_zeros: an entry zero at factor time becoming nonzero makes refactor fail
    std::vector<int> group;
    Csc A = body_kkt(chain_parent(5), 6, 0.0, {}, false, rng, group);
    SparseLU::Options o;
    o.drop_zeros = true;
    SparseLU lu(o);
    lu.analyze(A.n, A.p.data(), A.i.data(), group.data());
    check(lu.factor(A.x.data()) == 0, "drop_zeros factor");
    std::size_t z = 0;
    while (z < A.x.size() && A.x[z] != 0.0) ++z;
    std::vector<double> v(A.x);
    v[z] = 0.5;
    check(lu.refactor(v.data()) > 0 && lu.status() == SparseLU::kPatternChanged,
          "drop_zeros: refactor detects a new nonzero");
    check(lu.factor(v.data()) == 0, "drop_zeros: factor with the new nonzero");
    std::vector<double> b(A.n, 1.0), x(b);
    lu.solve(x.data());
    check(backward_error(A, v, x.data(), b.data()) <= 1e-13, "drop_zeros: accuracy");
  }
  {  // edge cases: n = 0, n = 1, invalid pattern
    SparseLU lu;
    const int p0[1] = {0};
    check(lu.analyze(0, p0, nullptr) == 0 && lu.factor(nullptr) == 0, "n = 0");
    const int p1[2] = {0, 1}, i1[1] = {0};
    const double x1[1] = {4.0};
    double b1[1] = {2.0};
    check(lu.analyze(1, p1, i1) == 0 && lu.factor(x1) == 0, "n = 1");
    lu.solve(b1);
    check(b1[0] == 0.5, "n = 1 solve");
    const int bad_i[1] = {3};
    check(lu.analyze(1, p1, bad_i) != 0 && lu.factor(x1) != 0, "invalid row index");
  }
}

void test_scaling(std::mt19937_64& rng) {
  std::printf("== fill growth on chains and binary trees (nnz(L+U) / n must stay bounded)\n");
  std::printf("   %-22s %8s %10s %8s %10s %10s\n", "graph", "n", "nnz(L+U)", "per n",
              "refac ms", "refac/n ns");
  for (const bool tree : {false, true}) {
    for (const int nc : {3, 6}) {
      double first = 0, last = 0;
      for (const int nb : {100, 1000, 10000, 20000}) {
        std::vector<int> group;
        Csc A = body_kkt(tree ? tree_parent(nb) : chain_parent(nb), nc, nc == 6 ? 0.5 : 0.0, {},
                         true, rng, group);
        SparseLU lu;
        lu.analyze(A.n, A.p.data(), A.i.data(), group.data());
        const int s = lu.factor(A.x.data());
        check(s == 0, "scaling factor");
        const double nlu = static_cast<double>(lu.nnz_L() + lu.nnz_U() - A.n);
        const double tr = timeit([&] { lu.refactor(A.x.data()); }, 1, 3);
        std::vector<double> b(A.n, 1.0), x(b);
        lu.solve(x.data());
        check(backward_error(A, A.x, x.data(), b.data()) <= 1e-13, "scaling accuracy");
        char name[64];
        std::snprintf(name, sizeof name, "%s nc=%d%s", tree ? "tree" : "chain", nc,
                      nc == 6 ? " massless" : "");
        std::printf("   %-22s %8d %10.0f %8.2f %10.3f %10.1f\n", name, A.n, nlu, nlu / A.n,
                    1e3 * tr, 1e9 * tr / A.n);
        if (nb == 100) first = nlu / A.n;
        last = nlu / A.n;
      }
      check(last <= 1.5 * first, std::string("fill per unknown bounded on ") +
                                     (tree ? "trees" : "chains"));
    }
  }
}

// One configuration of the solver on one engine matrix: accuracy checks and timings.
struct EngineRun {
  long long nlu = 0, flops = 0;
  double ta = 0, tf = 0, tr = 0, ts = 0, bf = 0, br = 0, rg = 0, rc = 0;
  int fallback = 0;  // status of a refactor that had to be replaced by a factor
};

EngineRun engine_run(const Csc& A, const std::string& tag, const int* group, bool values_hint,
                     const SparseLU::Options& opt, std::mt19937_64& rng) {
  EngineRun out;
  const int n = A.n;
  const bool small = n < 5000;
  SparseLU lu(opt);
  out.ta = timeit([&] { lu.analyze(n, A.p.data(), A.i.data(), group,
                                   values_hint ? A.x.data() : nullptr); },
                  1, small ? 20 : 3);
  int st = 0;
  out.tf = timeit([&] { st = lu.factor(A.x.data()); }, small ? 20 : 1, small ? 10 : 3);
  check(st == 0, tag + ": factor");
  std::vector<double> x(A.b);
  lu.solve(x.data());
  out.bf = backward_error(A, A.x, x.data(), A.b.data());
  check(out.bf <= 1e-13, tag + ": backward error after factor " + sci(out.bf));
  out.rg = lu.rgrowth();
  out.rc = n <= 60000 ? 1.0 / lu.condest() : NAN;
  out.nlu = lu.nnz_L() + lu.nnz_U() - n;
  out.flops = lu.refactor_flops();
  // refactor with the values of a later time step (timed), then solve (timed)
  int rs = lu.refactor(A.x2.data());
  if (rs != 0) {  // e.g. drop_zeros and an entry zero at the first step is not any more
    out.fallback = lu.status();
    check(lu.factor(A.x2.data()) == 0, tag + ": factor (later step)");
  }
  out.tr = timeit([&] { rs = lu.refactor(A.x2.data()); }, small ? 50 : 3, small ? 10 : 7);
  check(rs == 0, tag + ": refactor (later step), status " +
                     std::to_string(static_cast<int>(lu.status())));
  std::vector<double> y(A.b);
  out.ts = timeit(
      [&] {
        std::copy(A.b.begin(), A.b.end(), y.begin());
        lu.solve(y.data());
      },
      small ? 200 : 5, small ? 10 : 7);
  out.br = backward_error(A, A.x2, y.data(), A.b.data());
  check(out.br <= 1e-13, tag + ": backward error after refactor (later step) " + sci(out.br));
  // refactor with all values perturbed by up to 1 % (factor again if refactor refuses)
  std::uniform_real_distribution<double> ud(-0.01, 0.01);
  std::vector<double> v3(A.x);
  for (auto& v : v3) v *= 1.0 + ud(rng);
  if (lu.refactor(v3.data()) != 0) check(lu.factor(v3.data()) == 0, tag + ": factor (perturbed)");
  x = A.b;
  lu.solve(x.data());
  const double bp = backward_error(A, v3, x.data(), A.b.data());
  check(bp <= 1e-13, tag + ": backward error after refactor (perturbed) " + sci(bp));
  out.br = std::max(out.br, bp);
  x = A.b;
  lu.solve_refined(v3.data(), x.data(), 1);
  const double be = backward_error(A, v3, x.data(), A.b.data());
  check(be <= 1e-15, tag + ": backward error after one refinement step " + sci(be));
  return out;
}

void test_engine(const std::string& dir, std::mt19937_64& rng) {
  const char* names[] = {"slider_crank_i3",    "slider_crank_i2",    "chain10_i3",
                         "chain10_i2",         "chain100_i3",        "chain100_i2",
                         "chain1000_i3",       "chain1000_i2",       "chainplanar1000_i3",
                         "chainplanar1000_i2", "chainnodes1000_i2",  "closedchain100_i3",
                         "closedchain100_i2",  "tree10_i3",          "tree10_i2",
                         "chain10000_i3",      "chain10000_i2"};
  std::printf("== se3dyn iteration matrices from %s\n", dir.c_str());
  std::printf("   times: thread CPU time, best of several runs (splu: SciPy, COLAMD, measured the same\n"
              "   way by make_lu_matrices.py); nnz(L+U): ours structural (explicit zeros of\n"
              "   the pattern included), splu's as SciPy reports it (numerically nonzero only)\n");
  std::printf("   a: item groups (node / joint / multipliers / index-2 multipliers), defaults\n"
              "   b: joint groups (joint + child node), values to analyze, drop_zeros\n"
              "   *: refactor to the later step's values refused (with drop_zeros an entry zero at\n"
              "   the first step was not any more, or a pivot degraded) and factor was called\n");
  std::printf("%-18s %s  %6s %7s | %8s %8s %9s | %7s %7s %7s %7s | %7s %7s | %7s %7s %7s | %7s "
              "%7s\n",
              "matrix", "c", "n", "nnz(A)", "LU ours", "LU splu", "flops", "analyze", "factor",
              "refact", "solve", "splu f", "splu s", "berr f", "berr rf", "berr sp", "rgrowth",
              "1/cond");
  std::printf("%-18s %s  %6s %7s | %8s %8s %9s | %7s %7s %7s %7s | %7s %7s |\n", "", " ", "", "",
              "", "", "", "ms", "ms", "ms", "ms", "ms", "ms");
  int found = 0;
  for (const char* nm : names) {
    Csc A;
    if (!load(dir + "/" + nm + ".bin", A)) continue;
    ++found;
    for (const char cfg : {'a', 'b'}) {
      SparseLU::Options o;
      if (cfg == 'b') {
        o.drop_zeros = true;
      }
      const EngineRun r =
          engine_run(A, std::string(nm) + " (" + cfg + ")",
                     cfg == 'a' ? A.group.data() : A.group2.data(), cfg == 'b', o, rng);
      std::printf("%-18s %c%s%6d %7d | %8lld %8lld %9lld | %7.3f %7.3f %7.3f %7.4f | %7.3f %7.4f "
                  "| %7.1e %7.1e %7.1e | %7.1e %7.1e\n",
                  cfg == 'a' ? nm : "", cfg, r.fallback ? "*" : " ", A.n, A.p[A.n], r.nlu, A.splu_nnz, r.flops,
                  1e3 * r.ta, 1e3 * r.tf, 1e3 * r.tr, 1e3 * r.ts, 1e3 * A.splu_fac,
                  1e3 * A.splu_sol, r.bf, r.br, A.splu_berr, r.rg, r.rc);
    }
  }
  if (!found) std::printf("   no matrix files found (run tests/cpp/make_lu_matrices.py)\n");
}

}  // namespace

#ifndef SPARSE_LU_TEST_NO_MAIN
int main(int argc, char** argv) {
  const std::string dir = argc > 1 ? argv[1] : "/work/scratch-lu/matrices";
  std::mt19937_64 rng(12345);
  test_singular(rng);
  test_random(rng);
  test_scaling(rng);
  test_engine(dir, rng);
  return report();
}
#endif
