// Frame variables at one Newton iterate and the generic maps between the tangent space of a
// frame and its unknowns (Eqs. (14), (26)-(27)).
//
// Every configuration variable of the model is a frame of SE(3) (Eq. (12)): the nodes and the
// kinematic-joint transformations alike.  Frame f has k_f unknowns at frame_dof[f] (k = 6 for a
// free node, k = 0 for a clamped node or a rigid joint, k of Table 1 for a joint) and a constant
// 6 x k matrix A_f (the identity for nodes, Eq. (9) for joints): its increment is n* = A n
// (Eq. (14)), H = H_n exp(n*) (Eq. (38)), variations d h* = T(n*) A d n (Eq. (26)), velocities
// v* = A v.  Elements see frames only: they return 6-vector forces and 6 x 6 blocks in the
// tangent space of their frames, which the assembler maps to the unknowns by A^T (rows, Eq.
// (31)) and T A (configuration columns, Eq. (46)) or A (velocity and acceleration columns).
#pragma once
#include <vector>

#include "lie.hpp"

namespace se3dyn {

struct FrameTables {
  int F = 0;
  std::vector<int> dof;        // (F,) first unknown, -1 without unknowns
  std::vector<int> k;          // (F,) number of unknowns
  std::vector<char> node;      // (F,) A is the identity (a node frame)
  std::vector<double> A;       // (F, 6, 6) A_f in the first k columns (row-major, ld 6)
  // (F,) A selects: each of its k columns one entry 1, the others 0 (the joints of Table 1
  // along the frame's axes: spherical, hinge about z, ...); then A x, A^T g and X A are copies,
  // sel[6 f + c] the row of column c's 1 (the same numbers as the products)
  std::vector<char> select;
  std::vector<signed char> sel;  // (F, 6)
  // prescribed (driven) unknowns (se3dyn.ModelBuilder.drive): (nq,) flags and (F,) frames with
  // one; B_n of such a frame has the driven columns zero (Joints::constant_slots), so that the
  // index-2 correction B_n^T xi leaves a prescribed coordinate where its driver puts it
  std::vector<char> prescribed, pframe;
  bool driven(int f, int c) const {
    return !prescribed.empty() && dof[f] >= 0 && prescribed[dof[f] + c];
  }
  void classify() {
    select.assign(F, 0);
    sel.assign(6L * F, -1);
    for (int f = 0; f < F; ++f) {
      if (node[f] || k[f] == 0) continue;
      bool ok = true;
      for (int c = 0; c < k[f] && ok; ++c) {
        int ones = 0, at = -1;
        for (int i = 0; i < 6; ++i) {
          double a = A[36L * f + 6 * i + c];
          if (a == 1.0) { ++ones; at = i; }
          else if (a != 0.0) ok = false;
        }
        ok = ok && ones == 1;
        sel[6L * f + c] = static_cast<signed char>(at);
      }
      select[f] = ok;
    }
  }
};

struct FrameState {
  std::vector<Frame> H;        // (F,) frames of the iterate
  std::vector<double> TA;      // (F, 6, 6) T(n*) A in the first k columns
  std::vector<double> v;       // (F, 6) v* = A v
  std::vector<double> vd;      // (F, 6) vd* = A vd
  void resize(int F) {
    H.resize(F);
    TA.assign(36 * F, 0.0);
    v.assign(6 * F, 0.0);
    vd.assign(6 * F, 0.0);
  }
};

// out (6,) = A x for a frame (x: its k unknowns)
inline void frame_expand(const FrameTables& T, int f, const double* x, double* out) {
  int k = T.k[f];
  if (T.node[f]) {
    for (int i = 0; i < 6; ++i) out[i] = x[i];
    return;
  }
  if (T.select[f]) {
    for (int i = 0; i < 6; ++i) out[i] = 0.0;
    for (int c = 0; c < k; ++c) out[T.sel[6 * f + c]] = x[c];
    return;
  }
  const double* A = &T.A[36 * f];
  for (int i = 0; i < 6; ++i) {
    double s = 0.0;
    for (int c = 0; c < k; ++c) s += A[6 * i + c] * x[c];
    out[i] = s;
  }
}

// r[dof + c] += s * (A^T g)_c : a tangent-space force g (6,) on frame f (Eq. (31))
inline void frame_force(const FrameTables& T, int f, const double* g, double s, double* r) {
  int d = T.dof[f];
  if (d < 0) return;
  int k = T.k[f];
  if (T.node[f]) {
    for (int i = 0; i < 6; ++i) r[d + i] += s * g[i];
    return;
  }
  if (T.select[f]) {
    for (int c = 0; c < k; ++c) r[d + c] += s * g[T.sel[6 * f + c]];
    return;
  }
  const double* A = &T.A[36 * f];
  for (int c = 0; c < k; ++c) {
    double acc = 0.0;
    for (int i = 0; i < 6; ++i) acc += A[6 * i + c] * g[i];
    r[d + c] += s * acc;
  }
}

// Row map of a 6 x 6 tangent-space block X: out (k_f x 6, ld 6) = A_f^T X
inline void rows_to_unknowns(const FrameTables& T, int f, const double* X, double* out) {
  if (T.node[f]) {
    for (int i = 0; i < 36; ++i) out[i] = X[i];
    return;
  }
  int k = T.k[f];
  if (T.select[f]) {
    for (int c = 0; c < k; ++c)
      for (int j = 0; j < 6; ++j) out[6 * c + j] = X[6 * T.sel[6 * f + c] + j];
    return;
  }
  const double* A = &T.A[36 * f];
  for (int c = 0; c < k; ++c)
    for (int j = 0; j < 6; ++j) {
      double s = 0.0;
      for (int i = 0; i < 6; ++i) s += A[6 * i + c] * X[6 * i + j];
      out[6 * c + j] = s;
    }
}

// out (r x c) = op(X) op(Y) with inner dimension n, op(Z) = Z^T where tZ; every matrix stored
// row-major with leading dimension 6 (the joint blocks of k <= 6 unknowns)
inline void prod6(int r, int n, int c, const double* X, bool tX, const double* Y, bool tY,
                  double* out) {
  for (int i = 0; i < r; ++i)
    for (int j = 0; j < c; ++j) {
      double s = 0.0;
      for (int l = 0; l < n; ++l)
        s += (tX ? X[6 * l + i] : X[6 * i + l]) * (tY ? Y[6 * j + l] : Y[6 * l + j]);
      out[6 * i + j] = s;
    }
}

// Column map: out (r x k_g, ld 6) = X (r x 6, ld 6) Y_g with Y_g (6 x k_g, ld 6)
inline void cols_times(int r, int kg, const double* X, const double* Y, double* out) {
  if (r == 6 && kg == 6) {  // node frames: fixed sizes (unrolled)
    mm<6, 6, 6>(X, Y, out);
    return;
  }
  prod6(r, 6, kg, X, false, Y, false, out);
}

// out (r x k_f, ld 6) = X A_f, X (r x 6, ld 6): copies for node frames (A the identity) and
// for selections
inline void frame_cols(const FrameTables& T, int f, const double* X, double* out, int r = 6) {
  if (T.node[f]) {
    for (int i = 0; i < 6 * r; ++i) out[i] = X[i];
    return;
  }
  if (T.select[f]) {
    for (int i = 0; i < r; ++i)
      for (int c = 0; c < T.k[f]; ++c) out[6 * i + c] = X[6 * i + T.sel[6 * f + c]];
    return;
  }
  cols_times(r, T.k[f], X, &T.A[36 * f], out);
}

// vals[off : off + kr*kc] += s * X[:kr, :kc]  (X with ld 6)
inline void add_block(double* vals, long off, int kr, int kc, const double* X, double s) {
  if (off < 0) return;
  double* o = vals + off;
  if (kr == 6 && kc == 6) {
    for (int i = 0; i < 36; ++i) o[i] += s * X[i];
    return;
  }
  for (int i = 0; i < kr; ++i)
    for (int j = 0; j < kc; ++j) o[i * kc + j] += s * X[6 * i + j];
}
// vals[off ...] += s * X^T[:kr, :kc]  (X with ld 6, X^T[i][j] = X[j][i])
inline void add_block_T(double* vals, long off, int kr, int kc, const double* X, double s) {
  if (off < 0) return;
  double* o = vals + off;
  for (int i = 0; i < kr; ++i)
    for (int j = 0; j < kc; ++j) o[i * kc + j] += s * X[6 * j + i];
}

// A tangent-space block K (6x6) of d(force on frame f)/d(h* of frame g), scaled by s, into the
// unknown block (f, g): A_f^T K (T A)_g (configuration) when tangent, A_f^T K A_g otherwise.
inline void add_frame_block(const FrameTables& T, const FrameState& S, double* vals, long off,
                            int f, int g, const double* K, double s, bool tangent) {
  if (off < 0 || T.k[f] == 0 || T.k[g] == 0) return;
  double X[36], Y[36];
  if (T.node[f] && T.node[g]) {  // the common case, fixed sizes (unrolled)
    if (tangent) {
      mm<6, 6, 6>(K, &S.TA[36 * g], Y);
      for (int i = 0; i < 36; ++i) vals[off + i] += s * Y[i];
    } else {
      for (int i = 0; i < 36; ++i) vals[off + i] += s * K[i];
    }
    return;
  }
  rows_to_unknowns(T, f, K, X);
  if (tangent) cols_times(T.k[f], T.k[g], X, &S.TA[36 * g], Y);
  else frame_cols(T, g, X, Y, T.k[f]);
  add_block(vals, off, T.k[f], T.k[g], Y, s);
}

}  // namespace se3dyn
