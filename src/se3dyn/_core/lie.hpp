// SE(3)/SO(3) kernel of the compiled engine, on single elements.
//
// Conventions are those of se3dyn/lie.py (written once there): frames H = [[R, x], [0, 1]]
// (Eq. (1)); tangent vectors (U, Omega), translation first, material (right-trivialised):
// d(H) = H hat6(h) (Eqs. (2), (4)); exp_se3 is Eq. (17), its tangent operator Eqs. (21)-(22);
// Ad(H^-1) is Eq. (57); vect is Eq. (56).  The Taylor coefficients of the cancelling
// functions of the angle (and their cut-off, SERIES_CUTOFF = 1) come from se3dyn.lie at import
// (set_series), so the series exist once.
#pragma once
#include <cmath>
#include <cstring>

namespace se3dyn {

// ---------------------------------------------------------------------------------------------
// Fixed-size products, row-major (literal sizes: the compiler unrolls them)
// ---------------------------------------------------------------------------------------------
template <int R, int K, int C>
inline void mm(const double* A, const double* B, double* out) {  // out = A B
  for (int i = 0; i < R; ++i)
    for (int j = 0; j < C; ++j) {
      double s = 0.0;
      for (int l = 0; l < K; ++l) s += A[i * K + l] * B[l * C + j];
      out[i * C + j] = s;
    }
}
template <int R, int K, int C>
inline void mmT(const double* A, const double* B, double* out) {  // out = A B^T, B (C, K)
  for (int i = 0; i < R; ++i)
    for (int j = 0; j < C; ++j) {
      double s = 0.0;
      for (int l = 0; l < K; ++l) s += A[i * K + l] * B[j * K + l];
      out[i * C + j] = s;
    }
}
template <int R, int K, int C>
inline void mTm(const double* A, const double* B, double* out) {  // out = A^T B, A (K, R)
  for (int i = 0; i < R; ++i)
    for (int j = 0; j < C; ++j) {
      double s = 0.0;
      for (int l = 0; l < K; ++l) s += A[l * R + i] * B[l * C + j];
      out[i * C + j] = s;
    }
}
template <int R, int C>
inline void mv(const double* A, const double* x, double* y) {  // y = A x
  for (int i = 0; i < R; ++i) {
    double s = 0.0;
    for (int j = 0; j < C; ++j) s += A[i * C + j] * x[j];
    y[i] = s;
  }
}
template <int R, int C>
inline void mTv(const double* A, const double* x, double* y) {  // y = A^T x, A (R, C)
  for (int j = 0; j < C; ++j) {
    double s = 0.0;
    for (int i = 0; i < R; ++i) s += A[i * C + j] * x[i];
    y[j] = s;
  }
}

inline void cross(const double* a, const double* b, double* c) {
  c[0] = a[1] * b[2] - a[2] * b[1];
  c[1] = a[2] * b[0] - a[0] * b[2];
  c[2] = a[0] * b[1] - a[1] * b[0];
}
inline double dot3(const double* a, const double* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

// hat3 (Eq. (3)) into a 3x3 block of a row-major matrix with leading dimension ld
inline void hat3(const double* w, double* W, int ld = 3, double s = 1.0) {
  W[0] = 0.0;        W[1] = -s * w[2];  W[2] = s * w[1];
  W[ld] = s * w[2];  W[ld + 1] = 0.0;   W[ld + 2] = -s * w[0];
  W[2 * ld] = -s * w[1]; W[2 * ld + 1] = s * w[0]; W[2 * ld + 2] = 0.0;
}
inline void add_hat3(const double* w, double* W, int ld, double s) {
  W[1] -= s * w[2]; W[2] += s * w[1];
  W[ld] += s * w[2]; W[ld + 2] -= s * w[0];
  W[2 * ld] -= s * w[1]; W[2 * ld + 1] += s * w[0];
}

// A frame H = (R, x) of SE(3): R row-major 3x3, x.
struct Frame {
  double R[9];
  double x[3];
};

inline void set_identity(Frame& H) {
  std::memset(&H, 0, sizeof(Frame));
  H.R[0] = H.R[4] = H.R[8] = 1.0;
}
inline void frame_from4(const double* H4, Frame& H) {
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) H.R[3 * i + j] = H4[4 * i + j];
    H.x[i] = H4[4 * i + 3];
  }
}
inline void frame_to4(const Frame& H, double* H4) {
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) H4[4 * i + j] = H.R[3 * i + j];
    H4[4 * i + 3] = H.x[i];
  }
  H4[12] = H4[13] = H4[14] = 0.0;
  H4[15] = 1.0;
}
// C = A B
inline void compose(const Frame& A, const Frame& B, Frame& C) {
  mm<3, 3, 3>(A.R, B.R, C.R);
  for (int i = 0; i < 3; ++i)
    C.x[i] = A.R[3 * i] * B.x[0] + A.R[3 * i + 1] * B.x[1] + A.R[3 * i + 2] * B.x[2] + A.x[i];
}
// C = A^-1 B
inline void compose_inv(const Frame& A, const Frame& B, Frame& C) {
  mTm<3, 3, 3>(A.R, B.R, C.R);
  double d[3] = {B.x[0] - A.x[0], B.x[1] - A.x[1], B.x[2] - A.x[2]};
  mTv<3, 3>(A.R, d, C.x);
}
inline void inverse(const Frame& A, Frame& C) {
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) C.R[3 * i + j] = A.R[3 * j + i];
  mv<3, 3>(C.R, A.x, C.x);
  C.x[0] = -C.x[0]; C.x[1] = -C.x[1]; C.x[2] = -C.x[2];
}
// point of the frame's body: R p + x
inline void apply(const Frame& H, const double* p, double* out) {
  mv<3, 3>(H.R, p, out);
  out[0] += H.x[0]; out[1] += H.x[1]; out[2] += H.x[2];
}

// ---------------------------------------------------------------------------------------------
// Coefficient functions of the angle (see the docstring of se3dyn/lie.py)
// ---------------------------------------------------------------------------------------------
constexpr int SERIES_TERMS = 10;
struct Series {
  double cut = 1.0;
  double c[SERIES_TERMS], d[SERIES_TERMS], e[SERIES_TERMS], f[SERIES_TERMS];
};
Series& series();  // defined in module.cpp, filled from se3dyn.lie at import

inline double sum_series(const double* C, double t2) {
  double s = 0.0, p = 1.0;
  for (int j = 0; j < SERIES_TERMS; ++j) {
    s += C[j] * p;
    p *= t2;
  }
  return s;
}

// a = sin t/t, h = (1-cos t)/t^2, c = (1-a)/t^2, d = (b-a)/t^2, e = (b/2 - 3(1-a)/t^2)/t^2
struct Coeffs {
  double a, h, c, d, e;
};
inline Coeffs coeffs(const double* w, bool de) {
  const Series& S = series();
  Coeffs k;
  double t2 = dot3(w, w), t = std::sqrt(t2);
  if (t > 0) {
    k.a = std::sin(t) / t;
    double half = 0.5 * t, sh = std::sin(half) / half;
    k.h = 0.5 * sh * sh;
  } else {
    k.a = 1.0;
    k.h = 0.5;
  }
  if (t < S.cut) {
    k.c = sum_series(S.c, t2);
    k.d = de ? sum_series(S.d, t2) : 0.0;
    k.e = de ? sum_series(S.e, t2) : 0.0;
  } else {
    k.c = (1.0 - k.a) / t2;
    k.d = (2.0 * k.h - k.a) / t2;
    k.e = (k.h - 3.0 * k.c) / t2;
  }
  return k;
}

// W = hat(w) and W^2 = w w^T - |w|^2 I: every map below forms its matrices from these, entry
// by entry in the same order, so that shared blocks agree bit for bit (e.g. the T_SO(3) blocks
// of T_SE(3) and tangent_so3, exp_se3 with and without its tangent operator)
inline void hat_and_square(const double* w, double* W, double* W2) {
  hat3(w, W);
  double t2 = dot3(w, w);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) W2[3 * i + j] = w[i] * w[j] - (i == j ? t2 : 0.0);
}

// exp_so3 (Eq. (18)): R = I + a W + h W^2
inline void exp_so3(const double* w, const Coeffs& k, double* R) {
  double W[9], W2[9];
  hat_and_square(w, W, W2);
  for (int q = 0; q < 9; ++q) R[q] = (q % 4 == 0 ? 1.0 : 0.0) + k.a * W[q] + k.h * W2[q];
}

// exp_se3 (Eq. (17)): (exp_so3(w), T_so3(w)^T u) with T_so3^T = I + h W + c W^2
inline void exp_se3(const double* n, Frame& E) {
  const double* w = n + 3;
  Coeffs k = coeffs(w, false);
  double W[9], W2[9];
  hat_and_square(w, W, W2);
  for (int i = 0; i < 3; ++i) {
    double s = 0.0;
    for (int j = 0; j < 3; ++j) {
      int q = 3 * i + j;
      double dij = i == j ? 1.0 : 0.0;
      E.R[q] = dij + k.a * W[q] + k.h * W2[q];
      s += (dij + k.h * W[q] + k.c * W2[q]) * n[j];
    }
    E.x[i] = s;
  }
}

// exp_se3 and its tangent operator T_SE(3)(n) (Eqs. (21)-(22)), T (6x6) row-major
inline void exp_tangent_se3(const double* n, Frame& E, double* T) {
  const double* w = n + 3;
  const double* u = n;
  Coeffs k = coeffs(w, true);
  double W[9], W2[9], U[9], UW[9], WU[9];
  hat_and_square(w, W, W2);
  hat3(u, U);
  mm<3, 3, 3>(U, W, UW);
  mm<3, 3, 3>(W, U, WU);
  double wu = dot3(w, u);
  std::memset(T, 0, 36 * sizeof(double));
  for (int i = 0; i < 3; ++i) {
    double s = 0.0;
    for (int j = 0; j < 3; ++j) {
      double dij = i == j ? 1.0 : 0.0;
      int q = 3 * i + j;
      E.R[q] = dij + k.a * W[q] + k.h * W2[q];
      s += (dij + k.h * W[q] + k.c * W2[q]) * u[j];
      double tso = dij - k.h * W[q] + k.c * W2[q];
      T[6 * i + j] = tso;
      T[6 * (3 + i) + 3 + j] = tso;
      T[6 * i + 3 + j] = -k.h * U[q] + k.c * (UW[q] + WU[q]) + wu * (k.d * W[q] + k.e * W2[q]);
    }
    E.x[i] = s;
  }
}

// tangent_so3 (Eq. (19)): I - h W + c W^2
inline void tangent_so3(const double* w, double* T) {
  Coeffs k = coeffs(w, false);
  double W[9], W2[9];
  hat_and_square(w, W, W2);
  for (int q = 0; q < 9; ++q) T[q] = (q % 4 == 0 ? 1.0 : 0.0) - k.h * W[q] + k.c * W2[q];
}

// The coupling block T_UOmega+ of Eq. (22) (3x3) with the coefficients k of w = n_Omega
inline void t_uo_plus(const double* u, const double* w, const Coeffs& k, double* C) {
  double W[9], W2[9], U[9], UW[9], WU[9];
  hat_and_square(w, W, W2);
  hat3(u, U);
  mm<3, 3, 3>(U, W, UW);
  mm<3, 3, 3>(W, U, WU);
  double wu = dot3(w, u);
  for (int q = 0; q < 9; ++q)
    C[q] = -k.h * U[q] + k.c * (UW[q] + WU[q]) + wu * (k.d * W[q] + k.e * W2[q]);
}

// log_so3 of a rotation (|w| <= pi); see the docstring of se3dyn/lie.py for the branches
inline void log_so3(const double* R, double* w) {
  double s0 = 0.5 * (R[7] - R[5]), s1 = 0.5 * (R[2] - R[6]), s2 = 0.5 * (R[3] - R[1]);
  double c = 0.5 * (R[0] + R[4] + R[8] - 1.0);
  double sn = std::sqrt(s0 * s0 + s1 * s1 + s2 * s2);
  double t = std::atan2(sn, c);
  if (c >= 0) {
    double ratio = sn > 0 ? t / sn : 1.0;
    w[0] = s0 * ratio; w[1] = s1 * ratio; w[2] = s2 * ratio;
    return;
  }
  double S[9];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) S[3 * i + j] = 0.5 * (R[3 * i + j] + R[3 * j + i]);
  for (int i = 0; i < 3; ++i) S[4 * i] -= c;
  int j = 0;
  for (int i = 1; i < 3; ++i)
    if (S[4 * i] > S[4 * j]) j = i;
  double djj = S[4 * j];
  double sq = djj > 0 ? std::sqrt(djj) : 1.0;
  double a0 = S[j] / sq, a1 = S[3 + j] / sq, a2 = S[6 + j] / sq;
  double nrm = std::fmax(std::sqrt(a0 * a0 + a1 * a1 + a2 * a2), 1e-300);
  a0 /= nrm; a1 /= nrm; a2 /= nrm;
  double sign = (a0 * s0 + a1 * s1 + a2 * s2) < 0 ? -1.0 : 1.0;
  w[0] = a0 * sign * t; w[1] = a1 * sign * t; w[2] = a2 * sign * t;
}

// coefficient f = (1 - (t/2) cot(t/2))/t^2 of the inverse tangent operator
inline double coeff_f(double t2) {
  const Series& S = series();
  double t = std::sqrt(t2);
  if (t < S.cut) return sum_series(S.f, t2);
  double x = 0.5 * t;
  return (1.0 - x * std::cos(x) / std::sin(x)) / t2;
}

// log_se3 (inverse of Eq. (17) on |w| <= pi): (T_so3(w)^-T x, w)
inline void log_se3(const Frame& H, double* out) {
  double w[3];
  log_so3(H.R, w);
  double f = coeff_f(dot3(w, w));
  double c[3], d[3];
  cross(w, H.x, c);
  cross(w, c, d);
  for (int i = 0; i < 3; ++i) out[i] = H.x[i] - 0.5 * c[i] + f * d[i];
  out[3] = w[0]; out[4] = w[1]; out[5] = w[2];
}

// T_so3(w)^-1 = I + W/2 + f W^2 (3x3, row-major)
inline void tangent_so3_inv(const double* w, double* Ti) {
  double f = coeff_f(dot3(w, w));
  double W[9], W2[9];
  hat_and_square(w, W, W2);
  for (int q = 0; q < 9; ++q) Ti[q] = (q % 4 == 0 ? 1.0 : 0.0) + 0.5 * W[q] + f * W2[q];
}

// T_SE(3)(n)^-1 = [[Ti, -Ti C Ti], [0, Ti]] (block inverse of Eq. (21)), |n_Omega| < 2 pi
inline void tangent_se3_inv(const double* n, double* out) {
  const double* w = n + 3;
  Coeffs k = coeffs(w, true);
  double Ti[9], C[9], t1[9], t2[9];
  tangent_so3_inv(w, Ti);
  t_uo_plus(n, w, k, C);
  mm<3, 3, 3>(Ti, C, t1);
  mm<3, 3, 3>(t1, Ti, t2);
  std::memset(out, 0, 36 * sizeof(double));
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      out[6 * i + j] = Ti[3 * i + j];
      out[6 * (3 + i) + 3 + j] = Ti[3 * i + j];
      out[6 * i + 3 + j] = -t2[3 * i + j];
    }
}

// ---------------------------------------------------------------------------------------------
// Derivatives of the tangent operator T of Eqs. (21)-(22) applied to a fixed vector:
// DT(x, z) = d(T(x) z)/dx (dt_apply) and d(T(x)^T p)/dx (dtt_apply), for the exact tangents of
// the beam and of the springs on non-abelian joints
// ---------------------------------------------------------------------------------------------

// d'(t)/t and e'(t)/t of the coefficients d, e above (t = |w|): (h - c - 4d)/t^2 and
// (-d - 5e)/t^2, by the term-wise derivative of their series below the cut-off
inline void coeffs_dp_ep(double t2, const Coeffs& k, double& dp, double& ep) {
  const Series& S = series();
  if (std::sqrt(t2) < S.cut) {
    dp = ep = 0.0;
    double p = 1.0;
    for (int j = 0; j + 1 < SERIES_TERMS; ++j) {
      dp += 2.0 * (j + 1) * S.d[j + 1] * p;
      ep += 2.0 * (j + 1) * S.e[j + 1] * p;
      p *= t2;
    }
    return;
  }
  dp = (k.h - k.c - 4.0 * k.d) / t2;
  ep = (-k.d - 5.0 * k.e) / t2;
}

// D (3x3, ld ldD at D) += d(T_SO(3)(w) a)/dw = d (w x a) w^T + h hat(a) + e (w x (w x a)) w^T
//                          - c (hat(w x a) + hat(w) hat(a))
inline void add_dtso(const double* w, const double* a, const Coeffs& k, double* D, int ld) {
  double wa[3], wwa[3], W[9], A[9], WA[9], H[9];
  cross(w, a, wa);
  cross(w, wa, wwa);
  hat3(w, W);
  hat3(a, A);
  hat3(wa, H);
  mm<3, 3, 3>(W, A, WA);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      D[ld * i + j] += k.d * wa[i] * w[j] + k.h * A[3 * i + j] + k.e * wwa[i] * w[j] -
                       k.c * (H[3 * i + j] + WA[3 * i + j]);
}

// DT (6x6) = d(T(x) z)/dx for the tangent operator T of Eqs. (21)-(22), x = (u, w)
inline void dt_apply(const double* x, const double* z, double* DT) {
  const double* u = x;
  const double* w = x + 3;
  const double* zU = z;
  const double* zO = z + 3;
  Coeffs k = coeffs(w, true);
  double dp, ep;
  coeffs_dp_ep(dot3(w, w), k, dp, ep);
  std::memset(DT, 0, 36 * sizeof(double));
  add_dtso(w, zO, k, DT, 6);            // d(C zO)/du = d(T_SO3 zO)/dw
  add_dtso(w, zO, k, DT + 21, 6);       // bottom-right: d(T_SO3 zO)/dw
  add_dtso(w, zU, k, DT + 3, 6);        // top-right: d(T_SO3 zU)/dw + d(C zO)/dw
  double wz[3], wwz[3], uz[3], uwz[3], wuz[3], U[9], Z[9], W[9], UZ[9], WZ[9], Huz[9], Hwz[9];
  cross(w, zO, wz);
  cross(w, wz, wwz);
  cross(u, zO, uz);
  cross(u, wz, uwz);
  cross(w, uz, wuz);
  hat3(u, U);
  hat3(zO, Z);
  hat3(w, W);
  hat3(uz, Huz);
  hat3(wz, Hwz);
  mm<3, 3, 3>(U, Z, UZ);
  mm<3, 3, 3>(W, Z, WZ);
  double wu = dot3(w, u);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      int q = 3 * i + j;
      DT[6 * i + 3 + j] += k.d * uz[i] * w[j] + k.e * (uwz[i] + wuz[i]) * w[j] -
                           k.c * (UZ[q] + Huz[q]) + (k.d * wz[i] + k.e * wwz[i]) * u[j] +
                           wu * (dp * wz[i] * w[j] + ep * wwz[i] * w[j] - k.d * Z[q] -
                                 k.e * (Hwz[q] + WZ[q]));
    }
}

// DTt (6x6) = d(T(x)^T p)/dx = -Pi DT(-x, Pi p): T(x)^T = Pi T(-x) Pi, Pi swapping the
// translation and rotation halves (from ad(x)^T = -Pi ad(x) Pi and T a series in ad(x))
inline void dtt_apply(const double* x, const double* p, double* DTt) {
  double mx[6], pp[6], D[36];
  for (int i = 0; i < 6; ++i) mx[i] = -x[i];
  for (int i = 0; i < 3; ++i) {
    pp[i] = p[3 + i];
    pp[3 + i] = p[i];
  }
  dt_apply(mx, pp, D);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 6; ++j) {
      DTt[6 * i + j] = -D[6 * (3 + i) + j];
      DTt[6 * (3 + i) + j] = -D[6 * i + j];
    }
}

// Ad(H^-1) (Eq. (57)) = [[R^T, -R^T hat(x)], [0, R^T]]
inline void adjoint_inv(const Frame& H, double* Ad) {
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      double r = H.R[3 * j + i];
      Ad[6 * i + j] = r;
      Ad[6 * (3 + i) + 3 + j] = r;
      Ad[6 * (3 + i) + j] = 0.0;
    }
  const double* x = H.x;
  for (int i = 0; i < 3; ++i) {
    double r0 = H.R[i], r1 = H.R[3 + i], r2 = H.R[6 + i];  // row i of R^T
    Ad[6 * i + 3] = -(r1 * x[2] - r2 * x[1]);
    Ad[6 * i + 4] = -(r2 * x[0] - r0 * x[2]);
    Ad[6 * i + 5] = -(r0 * x[1] - r1 * x[0]);
  }
}
// Ad(H) = [[R, hat(x) R], [0, R]]
inline void adjoint(const Frame& H, double* Ad) {
  double X[9];
  hat3(H.x, X);
  double XR[9];
  mm<3, 3, 3>(X, H.R, XR);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      Ad[6 * i + j] = H.R[3 * i + j];
      Ad[6 * (3 + i) + 3 + j] = H.R[3 * i + j];
      Ad[6 * (3 + i) + j] = 0.0;
      Ad[6 * i + 3 + j] = XR[3 * i + j];
    }
}
// ad6(v) (Eq. (6)) = [[hat(v_O), hat(v_U)], [0, hat(v_O)]]
inline void ad6(const double* v, double* X) {
  std::memset(X, 0, 36 * sizeof(double));
  hat3(v + 3, X, 6);
  hat3(v + 3, X + 21, 6);
  hat3(v, X + 3, 6);
}
// Lambda(p) with ad6(d)^T p = Lambda(p) d: [[0, hat(p_U)], [hat(p_U), hat(p_O)]]
inline void lam_matrix(const double* p, double* L) {
  std::memset(L, 0, 36 * sizeof(double));
  hat3(p, L + 3, 6);
  hat3(p, L + 18, 6);
  hat3(p + 3, L + 21, 6);
}
// vect_se3 (Eq. (56)): (x, axial((R - R^T)/2))
inline void vect(const Frame& G, double* out) {
  out[0] = G.x[0]; out[1] = G.x[1]; out[2] = G.x[2];
  out[3] = 0.5 * (G.R[7] - G.R[5]);
  out[4] = 0.5 * (G.R[2] - G.R[6]);
  out[5] = 0.5 * (G.R[3] - G.R[1]);
}
// D with vect(G exp(d)) = vect(G) + D d + O(d^2): [[R, 0], [0, (tr(R) I - R^T)/2]]
inline void dvect(const Frame& G, double* D) {
  std::memset(D, 0, 36 * sizeof(double));
  double tr = G.R[0] + G.R[4] + G.R[8];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      D[6 * i + j] = G.R[3 * i + j];
      D[6 * (3 + i) + 3 + j] = 0.5 * ((i == j ? tr : 0.0) - G.R[3 * j + i]);
    }
}

}  // namespace se3dyn
