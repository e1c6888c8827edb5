"""Compiled kernels (numba, cached): the whole Newton iteration of a generalized-alpha step in
machine code, with no Python work per element or per iteration.

The kernels compute exactly what :func:`se3dyn.system.evaluate`, :func:`se3dyn.system.
matrix_values` and :meth:`se3dyn.integrator.GeneralizedAlpha.step` compute (same formulas, same
value order in the fixed sparsity pattern; the tests compare them), but element by element in
loops instead of vectorised numpy over element batches:

* nodes: ``H = H_n exp(n_I)`` (Eq. (38)), ``T_SE(3)(n_I)`` (Eqs. (21)-(22)), inertia forces
  (Eq. (51)), external forces (Eq. (66)), tangent damping (Eq. (53)) and stiffness (Eq. (67));
* joints: ``H_J = H_J,n exp(A n_j)``, ``G = (H_B X_B)^-1 (H_A X_A) H_J``, ``Phi = vect(G)``
  (Eqs. (55)-(56)), the forces ``Phi_q^T lambda`` (Eq. (58)), springs, dampers, actuators and PD
  laws on the relative coordinates (Eqs. (60)-(66)), and for the stabilized index-2 form the
  velocity constraints ``B v`` and the blocks of ``B_n^T xi``;
* the iteration matrix is factorised by the O(N) supernodal block LU of :mod:`se3dyn.blocklu`.

The kernels are compiled on first use and cached on disk (``cache=True``), so a new process pays
only the loading of the cache. Anything the kernels do not cover (springs on non-abelian joints;
a block pivot that fails) falls back to the numpy implementation, step by step.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from se3dyn import blocklu, lie

__all__ = ["FastSystem", "fast_system", "supported"]

_C2 = np.ascontiguousarray(lie._C2)
_C3 = np.ascontiguousarray(lie._C3)
_C4 = np.ascontiguousarray(lie._C4)
_C5 = np.ascontiguousarray(lie._C5)
_CUT = float(lie.SERIES_CUTOFF)


# ---------------------------------------------------------------------------------------------
# SE(3) kernels on single elements (mirror se3dyn.lie)
# ---------------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def _series(C, t2):
    s = 0.0
    p = 1.0
    for j in range(C.shape[0]):
        s += C[j] * p
        p *= t2
    return s


@njit(cache=True)
def _coeffs(w0, w1, w2, C2, C3, C4):
    """(a, h, c, d, e) of :func:`se3dyn.lie._coeffs` at the rotation vector w."""
    t2 = w0 * w0 + w1 * w1 + w2 * w2
    t = math.sqrt(t2)
    if t > 0:
        a = math.sin(t) / t
        half = 0.5 * t
        sh = math.sin(half) / half
        h = 0.5 * sh * sh
    else:
        a = 1.0
        h = 0.5
    if t < _CUT:
        c = _series(C2, t2)
        d = _series(C3, t2)
        e = _series(C4, t2)
    else:
        c = (1.0 - a) / t2
        d = (2.0 * h - a) / t2
        e = (h - 3.0 * c) / t2
    return a, h, c, d, e





@njit(cache=True, inline="always")
def _mm6(A, B, C):
    """C = A @ B for 6 x 6 matrices (fixed sizes: unrolled and vectorised by LLVM)."""
    for i in range(6):
        for j in range(6):
            s = 0.0
            for l in range(6):
                s += A[i, l] * B[l, j]
            C[i, j] = s


@njit(cache=True, inline="always")
def _mm4(A, B, C):
    """C = A @ B for 4 x 4 matrices (fixed sizes: unrolled and vectorised by LLVM)."""
    for i in range(4):
        for j in range(4):
            s = 0.0
            for l in range(4):
                s += A[i, l] * B[l, j]
            C[i, j] = s


@njit(cache=True, inline="always")
def _mm4a(A, B, C):
    """C = A @ B for homogeneous transformations (4, 4) (last rows [0, 0, 0, 1]): 36
    multiplications instead of 64."""
    for i in range(3):
        for j in range(3):
            C[i, j] = A[i, 0] * B[0, j] + A[i, 1] * B[1, j] + A[i, 2] * B[2, j]
        C[i, 3] = A[i, 0] * B[0, 3] + A[i, 1] * B[1, 3] + A[i, 2] * B[2, 3] + A[i, 3]
    C[3, 0] = 0.0
    C[3, 1] = 0.0
    C[3, 2] = 0.0
    C[3, 3] = 1.0


@njit(cache=True, inline="always")
def _mm3(A, B, C):
    """C = A @ B for 3 x 3 matrices (fixed sizes: unrolled and vectorised by LLVM)."""
    for i in range(3):
        for j in range(3):
            s = 0.0
            for l in range(3):
                s += A[i, l] * B[l, j]
            C[i, j] = s


@njit(cache=True, inline="always")
def _mmT6(A, B, C):
    """C = A @ B.T for 6 x 6 matrices (fixed sizes: unrolled and vectorised by LLVM)."""
    for i in range(6):
        for j in range(6):
            s = 0.0
            for l in range(6):
                s += A[i, l] * B[j, l]
            C[i, j] = s


@njit(cache=True, inline="always")
def _mTm6(A, B, C):
    """C = A.T @ B for 6 x 6 matrices (fixed sizes: unrolled and vectorised by LLVM)."""
    for i in range(6):
        for j in range(6):
            s = 0.0
            for l in range(6):
                s += A[l, i] * B[l, j]
            C[i, j] = s


@njit(cache=True)
def _hat(w, W):
    W[0, 0] = 0.0
    W[0, 1] = -w[2]
    W[0, 2] = w[1]
    W[1, 0] = w[2]
    W[1, 1] = 0.0
    W[1, 2] = -w[0]
    W[2, 0] = -w[1]
    W[2, 1] = w[0]
    W[2, 2] = 0.0


@njit(cache=True)
def _exp_tan(n, E, T, C2, C3, C4, scr):
    """E = exp_se3(n) (4, 4) (Eq. (17)) and T = tangent_se3(n) (6, 6) (Eqs. (21)-(22));
    ``scr`` (5, 3, 3) scratch."""
    a, h, c, d, e = _coeffs(n[3], n[4], n[5], C2, C3, C4)
    W = scr[0]
    _hat(n[3:6], W)
    W2 = scr[1]
    _mm3(W, W, W2)
    U = scr[2]
    _hat(n[0:3], U)
    wu = n[3] * n[0] + n[4] * n[1] + n[5] * n[2]
    UW = scr[3]
    _mm3(U, W, UW)
    WU = scr[4]
    _mm3(W, U, WU)
    for i in range(4):
        for j in range(4):
            E[i, j] = 0.0
    E[3, 3] = 1.0
    for i in range(6):
        for j in range(6):
            T[i, j] = 0.0
    for i in range(3):
        s = 0.0
        for j in range(3):
            dij = 1.0 if i == j else 0.0
            E[i, j] = dij + a * W[i, j] + h * W2[i, j]
            s += (dij + h * W[i, j] + c * W2[i, j]) * n[j]
            tso = dij - h * W[i, j] + c * W2[i, j]
            T[i, j] = tso
            T[3 + i, 3 + j] = tso
            T[i, 3 + j] = (-h * U[i, j] + c * (UW[i, j] + WU[i, j])
                           + wu * (d * W[i, j] + e * W2[i, j]))
        E[i, 3] = s


@njit(cache=True)
def _exp4(n, E, C2):
    """E = exp_se3(n) (4, 4) (Eq. (17)) alone: R = I + a W + h W^2, x = (I + h W + c W^2) u
    with the coefficients of :func:`_coeffs` (no tangent operator, no d and e)."""
    w0, w1, w2 = n[3], n[4], n[5]
    t2 = w0 * w0 + w1 * w1 + w2 * w2
    t = math.sqrt(t2)
    if t > 0:
        a = math.sin(t) / t
        half = 0.5 * t
        sh = math.sin(half) / half
        h = 0.5 * sh * sh
    else:
        a = 1.0
        h = 0.5
    if t < _CUT:
        c = _series(C2, t2)
    else:
        c = (1.0 - a) / t2
    # W^2 = w w^T - t2 I
    W2_00 = w0 * w0 - t2
    W2_11 = w1 * w1 - t2
    W2_22 = w2 * w2 - t2
    W2_01 = w0 * w1
    W2_02 = w0 * w2
    W2_12 = w1 * w2
    E[0, 0] = 1.0 + h * W2_00
    E[1, 1] = 1.0 + h * W2_11
    E[2, 2] = 1.0 + h * W2_22
    E[0, 1] = -a * w2 + h * W2_01
    E[1, 0] = a * w2 + h * W2_01
    E[0, 2] = a * w1 + h * W2_02
    E[2, 0] = -a * w1 + h * W2_02
    E[1, 2] = -a * w0 + h * W2_12
    E[2, 1] = a * w0 + h * W2_12
    u0, u1, u2 = n[0], n[1], n[2]
    E[0, 3] = (1.0 + c * W2_00) * u0 + (-h * w2 + c * W2_01) * u1 + (h * w1 + c * W2_02) * u2
    E[1, 3] = (h * w2 + c * W2_01) * u0 + (1.0 + c * W2_11) * u1 + (-h * w0 + c * W2_12) * u2
    E[2, 3] = (-h * w1 + c * W2_02) * u0 + (h * w0 + c * W2_12) * u1 + (1.0 + c * W2_22) * u2
    E[3, 0] = 0.0
    E[3, 1] = 0.0
    E[3, 2] = 0.0
    E[3, 3] = 1.0


@njit(cache=True)
def _adinv(H, Ad):
    """Ad(H^-1) (6, 6), Eq. (57): [[R^T, -R^T hat(x)], [0, R^T]]."""
    for i in range(3):
        for j in range(3):
            r = H[j, i]
            Ad[i, j] = r
            Ad[3 + i, 3 + j] = r
            Ad[3 + i, j] = 0.0
    x0, x1, x2 = H[0, 3], H[1, 3], H[2, 3]
    for i in range(3):
        # -R^T hat(x): row i = -(R^T)_i . hat(x)
        r0, r1, r2 = H[0, i], H[1, i], H[2, i]
        Ad[i, 3] = -(r1 * x2 - r2 * x1)
        Ad[i, 4] = -(r2 * x0 - r0 * x2)
        Ad[i, 5] = -(r0 * x1 - r1 * x0)


@njit(cache=True)
def _inv(H, Hi):
    for i in range(3):
        for j in range(3):
            Hi[i, j] = H[j, i]
    for i in range(3):
        Hi[i, 3] = -(H[0, i] * H[0, 3] + H[1, i] * H[1, 3] + H[2, i] * H[2, 3])
        Hi[3, i] = 0.0
    Hi[3, 3] = 1.0


@njit(cache=True)
def _ad6(v, X, scr):
    for i in range(6):
        for j in range(6):
            X[i, j] = 0.0
    W = scr[0]
    _hat(v[3:6], W)
    U = scr[1]
    _hat(v[0:3], U)
    for i in range(3):
        for j in range(3):
            X[i, j] = W[i, j]
            X[3 + i, 3 + j] = W[i, j]
            X[i, 3 + j] = U[i, j]


@njit(cache=True)
def _log_se3(H, out, C5):
    """log_se3 (6,) of :func:`se3dyn.lie.log_se3` (rotation part by log_so3, |w| <= pi)."""
    R = H[:3, :3]
    s0 = 0.5 * (R[2, 1] - R[1, 2])
    s1 = 0.5 * (R[0, 2] - R[2, 0])
    s2 = 0.5 * (R[1, 0] - R[0, 1])
    c = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)
    sn = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    t = math.atan2(sn, c)
    if c >= 0:
        ratio = t / sn if sn > 0 else 1.0
        w0, w1, w2 = s0 * ratio, s1 * ratio, s2 * ratio
    else:
        S = 0.5 * (R + R.T)
        for i in range(3):
            S[i, i] -= c
        j = 0
        for i in range(1, 3):
            if S[i, i] > S[j, j]:
                j = i
        djj = S[j, j]
        sq = math.sqrt(djj) if djj > 0 else 1.0
        a0, a1, a2 = S[0, j] / sq, S[1, j] / sq, S[2, j] / sq
        nrm = max(math.sqrt(a0 * a0 + a1 * a1 + a2 * a2), 1e-300)
        a0, a1, a2 = a0 / nrm, a1 / nrm, a2 / nrm
        sign = -1.0 if a0 * s0 + a1 * s1 + a2 * s2 < 0 else 1.0
        w0, w1, w2 = a0 * sign * t, a1 * sign * t, a2 * sign * t
    t2 = w0 * w0 + w1 * w1 + w2 * w2
    if math.sqrt(t2) < _CUT:
        f = _series(C5, t2)
    else:
        tb = math.sqrt(t2)
        x = 0.5 * tb
        f = (1.0 - x * math.cos(x) / math.sin(x)) / t2
    # u = (I - W/2 + f W^2) x with W = hat(w): W x = w x x
    x0, x1, x2 = H[0, 3], H[1, 3], H[2, 3]
    c0, c1, c2 = w1 * x2 - w2 * x1, w2 * x0 - w0 * x2, w0 * x1 - w1 * x0
    d0, d1, d2 = w1 * c2 - w2 * c1, w2 * c0 - w0 * c2, w0 * c1 - w1 * c0
    out[0] = x0 - 0.5 * c0 + f * d0
    out[1] = x1 - 0.5 * c1 + f * d1
    out[2] = x2 - 0.5 * c2 + f * d2
    out[3], out[4], out[5] = w0, w1, w2


# ---------------------------------------------------------------------------------------------
# Residual, constraints and iteration-matrix values of one Newton iterate
# ---------------------------------------------------------------------------------------------
@njit(cache=True)
def _residual(S, Wk, Hn, HJn, alpha_n, n, v, vd, lam, f, mt, tau, ref, rate, velocity,
              H, HJ, r, phi, psi, alpha):
    """Residual r (nq,) of Eq. (39), constraints phi (nm,) of Eq. (55), velocity constraints psi
    (nm,) (when ``velocity``), frames H (M, 4, 4), HJ (m, 4, 4) and relative coordinates alpha
    (nq,) (``alpha_n + n`` on joint unknowns) of an iterate; fills the work arrays ``Wk`` that
    :func:`_values` reads at the same iterate (``RtF``, ``G``, ``w``). Returns the force scale
    of :func:`se3dyn.system.evaluate`.

    Only what the residual needs is computed: exponentials without tangent operators
    (:func:`_exp4`), affine 4 x 4 products, and the joint forces ``(Ad(H_J^-1) P_A)^T lambda``
    of Eq. (58) as ``P_A^T (Ad(H_J^-1)^T lambda)`` from the rotation and translation of H_J,
    without forming Ad; the tangent operators and Ad blocks of the iteration matrix are left to
    :func:`_values`, which runs only when the matrix is refactorised."""
    (fdof, fnode, fmass, fJ, gk, gstart, gids, jk, jA, jdof, ja, jb, jfa, jfb, PA, PB, XA, XB,
     dK, dref, dC, dkp, dkd, pairs, Apinv, H0inv, nonab, mass_all, nq, nm, C2, C3, C4, C5) = S
    Tn, RtF, Gs, Ads, TJs, ws, blk_m, Adn = Wk
    nf = fdof.shape[0]
    m = jk.shape[0]
    H[:] = Hn
    r[:] = 0.0
    alpha[:] = 0.0
    E = np.empty((4, 4))
    fin = np.empty(6)
    fs = 0.0
    for q in range(nf):
        d0 = fdof[q]
        i = fnode[q]
        _exp4(n[d0:d0 + 6], E, C2)
        _mm4a(Hn[i], E, H[i])
        vU0, vU1, vU2 = v[d0], v[d0 + 1], v[d0 + 2]
        w0, w1, w2 = v[d0 + 3], v[d0 + 4], v[d0 + 5]
        ms = fmass[q]
        J = fJ[q]
        JO0 = J[0, 0] * w0 + J[0, 1] * w1 + J[0, 2] * w2
        JO1 = J[1, 0] * w0 + J[1, 1] * w1 + J[1, 2] * w2
        JO2 = J[2, 0] * w0 + J[2, 1] * w1 + J[2, 2] * w2
        fin[0] = ms * (vd[d0] + (w1 * vU2 - w2 * vU1))
        fin[1] = ms * (vd[d0 + 1] + (w2 * vU0 - w0 * vU2))
        fin[2] = ms * (vd[d0 + 2] + (w0 * vU1 - w1 * vU0))
        a0, a1, a2 = vd[d0 + 3], vd[d0 + 4], vd[d0 + 5]
        fin[3] = J[0, 0] * a0 + J[0, 1] * a1 + J[0, 2] * a2 + (w1 * JO2 - w2 * JO1)
        fin[4] = J[1, 0] * a0 + J[1, 1] * a1 + J[1, 2] * a2 + (w2 * JO0 - w0 * JO2)
        fin[5] = J[2, 0] * a0 + J[2, 1] * a1 + J[2, 2] * a2 + (w0 * JO1 - w1 * JO0)
        Hi = H[i]
        for c in range(3):
            RtF[q, c] = Hi[0, c] * f[i, 0] + Hi[1, c] * f[i, 1] + Hi[2, c] * f[i, 2]
        for c in range(6):
            ge = RtF[q, c] if c < 3 else mt[i, c - 3]
            r[d0 + c] = fin[c] - ge
            fs = max(fs, abs(fin[c]), abs(ge))
    lam_max = 0.0
    for c in range(nm):
        lam_max = max(lam_max, abs(lam[c]))
    gint_max = 0.0
    tau_max = 0.0
    for c in range(nq):
        tau_max = max(tau_max, abs(tau[c]))
    HA = np.empty((4, 4))
    HBi = np.empty((4, 4))
    HB = np.empty((4, 4))
    nJ = np.empty(6)
    y = np.empty(6)
    u = np.empty(6)
    for j in range(m):
        k = jk[j]
        A = jA[j]
        HJj = HJ[j]
        if k > 0:
            jd = jdof[j]
            for c in range(6):
                s = 0.0
                for l in range(k):
                    s += A[c, l] * n[jd + l]
                nJ[c] = s
            _exp4(nJ, E, C2)
            _mm4a(HJn[j], E, HJj)
        else:
            HJj[:] = HJn[j]
        a_ = ja[j]
        b_ = jb[j]
        _mm4a(H[a_], XA[j], HA)
        _mm4a(H[b_], XB[j], HB)
        _inv(HB, HBi)
        G = Gs[j]
        _mm4a(HBi, HA, HB)
        _mm4a(HB, HJj, G)
        mr = 6 * j
        phi[mr] = G[0, 3]
        phi[mr + 1] = G[1, 3]
        phi[mr + 2] = G[2, 3]
        phi[mr + 3] = 0.5 * (G[2, 1] - G[1, 2])
        phi[mr + 4] = 0.5 * (G[0, 2] - G[2, 0])
        phi[mr + 5] = 0.5 * (G[1, 0] - G[0, 1])
        # Ad(H_J^-1)^T = [[R, 0], [hat(x) R, R]] with (R, x) of H_J
        x0, x1, x2 = HJj[0, 3], HJj[1, 3], HJj[2, 3]
        fa = jfa[j]
        fb = jfb[j]
        if fa >= 0:
            da = fdof[fa]
            for c in range(3):
                y[c] = HJj[c, 0] * lam[mr] + HJj[c, 1] * lam[mr + 1] + HJj[c, 2] * lam[mr + 2]
                y[3 + c] = (HJj[c, 0] * lam[mr + 3] + HJj[c, 1] * lam[mr + 4]
                            + HJj[c, 2] * lam[mr + 5])
            y[3] += x1 * y[2] - x2 * y[1]
            y[4] += x2 * y[0] - x0 * y[2]
            y[5] += x0 * y[1] - x1 * y[0]
            P = PA[j]
            for c in range(6):
                s = 0.0
                for l in range(6):
                    s += P[l, c] * y[l]
                r[da + c] += s
        if fb >= 0:
            db = fdof[fb]
            P = PB[j]
            for c in range(6):
                s = 0.0
                for l in range(6):
                    s += P[l, c] * lam[mr + l]
                r[db + c] -= s
        if k > 0:
            jd = jdof[j]
            for l in range(k):
                dd = jd + l
                s = 0.0
                for c in range(6):
                    s += A[c, l] * lam[mr + c]
                ag = alpha_n[dd] + n[dd]
                alpha[dd] = ag
                vj = v[dd]
                gi = (dK[dd] * (ag - dref[dd]) + dC[dd] * vj + dkp[dd] * (ag - ref[dd])
                      + dkd[dd] * (vj - rate[dd]))
                gint_max = max(gint_max, abs(gi))
                r[dd] += s + gi - tau[dd]
        if velocity:
            # w = Ad(H_J^-1) P_A v_A = [R^T (u_top - x cross u_bot), R^T u_bot], u = P_A v_A
            w = ws[j]
            if fa >= 0:
                da = fdof[fa]
                P = PA[j]
                for c in range(6):
                    s = 0.0
                    for l in range(6):
                        s += P[c, l] * v[da + l]
                    u[c] = s
                u[0] -= x1 * u[5] - x2 * u[4]
                u[1] -= x2 * u[3] - x0 * u[5]
                u[2] -= x0 * u[4] - x1 * u[3]
                for c in range(3):
                    w[c] = HJj[0, c] * u[0] + HJj[1, c] * u[1] + HJj[2, c] * u[2]
                    w[3 + c] = HJj[0, c] * u[3] + HJj[1, c] * u[4] + HJj[2, c] * u[5]
            else:
                w[:] = 0.0
            for c in range(6):
                s = w[c]
                if fb >= 0:
                    db = fdof[fb]
                    for l in range(6):
                        s -= PB[j, c, l] * v[db + l]
                if k > 0:
                    jd = jdof[j]
                    for l in range(k):
                        s += A[c, l] * v[jd + l]
                psi[mr + c] = s
    return max(fs, lam_max, gint_max, tau_max)


@njit(cache=True)
def _put(vals, o, X, nr, nc):
    """Write the leading (nr, nc) block of X row-major at vals[o:]."""
    for i in range(nr):
        for j in range(nc):
            vals[o + i * nc + j] = X[i, j]


@njit(cache=True)
def _putn(vals, o, X, nr, nc):
    """Write minus the leading (nr, nc) block of X row-major at vals[o:]."""
    for i in range(nr):
        for j in range(nc):
            vals[o + i * nc + j] = -X[i, j]


@njit(cache=True)
def _putT(vals, o, X, nr, nc):
    """Write the transpose of the leading (nc, nr) block of X: (nr, nc) row-major."""
    for i in range(nr):
        for j in range(nc):
            vals[o + i * nc + j] = X[j, i]


@njit(cache=True)
def _values(S, Wk, n, HJ, v, lam, cM, cC, cK, index2, cv, vals):
    """Values of the scaled iteration matrix in the order of :func:`se3dyn.system._pattern`
    (= :func:`se3dyn.system.matrix_values`, with the index-2 blocks of ``_stab_values`` when
    ``index2``); needs the work arrays of :func:`_residual` at the same iterate and, for
    index 2, ``Adn`` (m, 6, 6) = Ad(H_J,n^-1) in ``Wk``. Computes and stores in ``Wk`` the
    tangent operators T_SE(3)(n_I) of the nodes (Eqs. (21)-(22)), T_SE(3)(A n_j) A of the
    joints and Ad(H_J^-1) (Eq. (57)) at the increment ``n`` (nq,) and joint frames ``HJ``
    (m, 4, 4) of the iterate."""
    (fdof, fnode, fmass, fJ, gk, gstart, gids, jk, jA, jdof, ja, jb, jfa, jfb, PA, PB, XA, XB,
     dK, dref, dC, dkp, dkd, pairs, Apinv, H0inv, nonab, mass_all, nq, nm, C2, C3, C4, C5) = S
    Tn, RtF, Gs, Ads, TJs, ws, blk_m, Adn = Wk
    nf = fdof.shape[0]
    m = jk.shape[0]
    blk = np.zeros((6, 6))
    W = np.empty((3, 3))
    U = np.empty((3, 3))
    JOh = np.empty((3, 3))
    KT = np.zeros((6, 6))
    WJ = np.empty((3, 3))
    JO = np.empty(3)
    X = np.empty((6, 6))
    Y = np.empty((6, 6))
    AdnPA = np.empty((6, 6))
    E = np.empty((4, 4))
    scr = np.empty((5, 3, 3))
    nJ = np.empty(6)
    for q in range(nf):
        d0 = fdof[q]
        _exp_tan(n[d0:d0 + 6], E, Tn[q], C2, C3, C4, scr)
    for j in range(m):
        _adinv(HJ[j], Ads[j])
        k = jk[j]
        if k > 0:
            A = jA[j]
            jd = jdof[j]
            for c in range(6):
                s = 0.0
                for l in range(k):
                    s += A[c, l] * n[jd + l]
                nJ[c] = s
            _exp_tan(nJ, E, X, C2, C3, C4, scr)
            _mm6(X, A, TJs[j])
    for q in range(nf):
        d0 = fdof[q]
        ms = fmass[q]
        J = fJ[q]
        blk[:] = 0.0
        for i in range(3):
            blk[i, i] = cM * ms
            for j in range(3):
                blk[3 + i, 3 + j] = cM * J[i, j]
        if cC != 0.0:
            _hat(v[d0 + 3:d0 + 6], W)
            _hat(v[d0:d0 + 3], U)
            for i in range(3):
                JO[i] = J[i, 0] * v[d0 + 3] + J[i, 1] * v[d0 + 4] + J[i, 2] * v[d0 + 5]
            _hat(JO, JOh)
            _mm3(W, J, WJ)
            for i in range(3):
                for j in range(3):
                    blk[i, j] += cC * ms * W[i, j]
                    blk[i, 3 + j] += -cC * ms * U[i, j]
                    blk[3 + i, 3 + j] += cC * (WJ[i, j] - JOh[i, j])
        if index2:
            blk_m[q] = blk
        if cK != 0.0:
            _hat(RtF[q], W)
            for i in range(3):
                for j in range(3):
                    KT[i, 3 + j] = -W[i, j]
            _mm6(KT, Tn[q], X)
            for i in range(6):
                for j in range(6):
                    blk[i, j] += cK * X[i, j]
        _put(vals, 36 * q, blk, 6, 6)
    o = 36 * nf
    ng = gk.shape[0]
    Dv = np.zeros((6, 6))
    AdPA = np.empty((6, 6))
    AdGi = np.empty((6, 6))
    LM = np.zeros((6, 6))
    eye6 = np.eye(6)
    Tfix = np.eye(6)
    for g in range(ng):
        k = gk[g]
        j0 = gstart[g]
        nj = gstart[g + 1] - j0
        oCA = o
        oCB = oCA + 36 * nj
        oCJ = oCB + 36 * nj
        oAdT = oCJ + 6 * k * nj
        oMI = oAdT + 36 * nj
        oAT = oMI + 36 * nj
        oGEO = oAT + 6 * k * nj
        oKJ = oGEO + 6 * k * nj
        o = oKJ + k * k * nj
        for ii in range(nj):
            j = gids[j0 + ii]
            G = Gs[j]
            Ad = Ads[j]
            A = jA[j]
            tr = G[0, 0] + G[1, 1] + G[2, 2]
            for i in range(3):
                for l in range(3):
                    Dv[i, l] = G[i, l]
                    Dv[3 + i, 3 + l] = 0.5 * ((tr if i == l else 0.0) - G[l, i])
            _mm6(Ad, PA[j], AdPA)
            Ta = Tn[jfa[j]] if jfa[j] >= 0 else Tfix
            Tb = Tn[jfb[j]] if jfb[j] >= 0 else Tfix
            _mm6(Dv, AdPA, X)
            _mm6(X, Ta, Y)
            _put(vals, oCA + 36 * ii, Y, 6, 6)
            _adinv(G, AdGi)
            _mm6(Dv, AdGi, X)
            _mm6(X, PB[j], Y)
            _mm6(Y, Tb, X)
            _putn(vals, oCB + 36 * ii, X, 6, 6)
            TJ = TJs[j]
            if k > 0:
                _mm6(Dv, TJ, X)
                _put(vals, oCJ + 6 * k * ii, X, 6, k)
            _putT(vals, oAdT + 36 * ii, AdPA, 6, 6)
            _putT(vals, oMI + 36 * ii, -PB[j], 6, 6)
            if k > 0:
                _putT(vals, oAT + 6 * k * ii, A, k, 6)
                mr = 6 * j
                _hat(lam[mr:mr + 3], W)
                _hat(lam[mr + 3:mr + 6], U)
                for i in range(3):
                    for l in range(3):
                        LM[i, 3 + l] = W[i, l]
                        LM[3 + i, l] = W[i, l]
                        LM[3 + i, 3 + l] = U[i, l]
                _mTm6(AdPA, LM, Y)
                _mm6(Y, TJ, X)
                for i in range(6):
                    for l in range(k):
                        vals[oGEO + 6 * k * ii + k * i + l] = -cK * X[i, l]
                jd = jdof[j]
                base = oKJ + k * k * ii
                for i in range(k):
                    for l in range(k):
                        vals[base + i * k + l] = 0.0
                    dd = jd + i
                    vals[base + i * k + i] = cK * (dK[dd] + dkp[dd]) + cC * (dC[dd] + dkd[dd])
    for c in range(nm):
        vals[o + c] = 0.0
    o += nm
    if not index2:
        return
    # ---- stabilized index-2 blocks (order of _stab_values)
    X6 = np.empty((6, 6))
    ad = np.empty((6, 6))
    for g in range(ng):
        k = gk[g]
        j0 = gstart[g]
        nj = gstart[g + 1] - j0
        o1 = o
        o2 = o1 + 36 * nj
        o3 = o2 + 36 * nj
        o4 = o3 + 6 * k * nj
        o5 = o4 + 36 * nj
        o6 = o5 + 36 * nj
        o = o6 + 6 * k * nj
        for ii in range(nj):
            j = gids[j0 + ii]
            A = jA[j]
            _mm6(Adn[j], PA[j], AdnPA)
            Ma = blk_m[jfa[j]] if jfa[j] >= 0 else eye6
            Mb = blk_m[jfb[j]] if jfb[j] >= 0 else eye6
            _mmT6(Ma, AdnPA, X6)
            _putn(vals, o1 + 36 * ii, X6, 6, 6)
            _mmT6(Mb, PB[j], X6)
            _put(vals, o2 + 36 * ii, X6, 6, 6)
            if k > 0:
                jd = jdof[j]
                for i in range(k):
                    cj = cC * (dC[jd + i] + dkd[jd + i])
                    for l in range(6):
                        vals[o3 + 6 * k * ii + 6 * i + l] = -cj * A[l, i]
            _mm6(Ads[j], PA[j], AdPA)
            _put(vals, o4 + 36 * ii, AdPA, 6, 6)
            _putn(vals, o5 + 36 * ii, PB[j], 6, 6)
            if k > 0:
                _ad6(ws[j], ad, scr)
                _mm6(ad, TJs[j], X6)
                for i in range(6):
                    for l in range(k):
                        vals[o6 + 6 * k * ii + k * i + l] = A[i, l] + cv * X6[i, l]
    Bi = np.empty((6, 6))
    Bj = np.empty((6, 6))
    for p in range(pairs.shape[0]):
        ji, si, jj, sj = pairs[p, 0], pairs[p, 1], pairs[p, 2], pairs[p, 3]
        if si == 0:
            _mm6(Ads[ji], PA[ji], Bi)
        else:
            for i in range(6):
                for l in range(6):
                    Bi[i, l] = -PB[ji, i, l]
        if sj == 0:
            _mm6(Adn[jj], PA[jj], Bj)
        else:
            for i in range(6):
                for l in range(6):
                    Bj[i, l] = -PB[jj, i, l]
        _mmT6(Bi, Bj, X6)
        _putn(vals, o + 36 * p, X6, 6, 6)
    o += 36 * pairs.shape[0]
    for j in range(m):
        A = jA[j]
        k = jk[j]
        for i in range(6):
            for l in range(6):
                s = 0.0
                for c in range(k):
                    s += A[i, c] * A[l, c]
                vals[o + 36 * j + 6 * i + l] = -s
    o += 36 * m
    for c in range(nm):
        vals[o + c] = 0.0


# ---------------------------------------------------------------------------------------------
# Python side: the arrays of a compiled System, flattened for the kernels
# ---------------------------------------------------------------------------------------------
def supported(s) -> bool:
    """Whether the compiled kernels cover this system (springs on non-abelian joints, which
    need the log coordinates inside Newton, are left to the numpy implementation)."""
    return not any(g.has_nonabelian_spring for g in s.groups)


class FastSystem:
    """The arrays of a :class:`~se3dyn.system.System` laid out for the compiled kernels.

    Attributes
    ----------
    S : tuple
        System arrays: free-node unknown addresses, masses, inertias; joint group structure in
        pattern order; per joint k, basis A padded to (6, 6), unknown addresses, nodes, offsets
        ``Ad(X_A^-1)``, ``Ad(X_B^-1)``, ``X_A``, ``X_B``; force-element coefficients per unknown;
        joint pairs of the index-2 pattern; pseudo-inverses and ``H_J0^-1`` for log
        coordinates; sizes; series coefficients.
    """

    def __init__(self, s):
        from se3dyn.system import _joint_pairs

        self.s = s
        m = s.m
        M = s.M
        nf = len(s.node_free)
        free_pos = -np.ones(M, dtype=np.int64)
        free_pos[s.node_free] = np.arange(nf)
        jA = np.zeros((m, 6, 6))
        Apinv = np.zeros((m, 6, 6))
        for g in s.groups:
            if g.k:
                jA[g.ids, :, :g.k] = g.A
                Apinv[g.ids, :g.k, :] = g.Apinv
        eye4 = np.broadcast_to(np.eye(4), (m, 4, 4))
        XA = np.ascontiguousarray(getattr(s, "joint_XA", eye4), dtype=float)
        XB = np.ascontiguousarray(getattr(s, "joint_XB", eye4), dtype=float)
        PA = lie.adjoint_inv(XA) if m else np.zeros((0, 6, 6))
        PB = lie.adjoint_inv(XB) if m else np.zeros((0, 6, 6))
        gk = np.array([g.k for g in s.groups], dtype=np.int64)
        gstart = np.zeros(len(s.groups) + 1, dtype=np.int64)
        gstart[1:] = np.cumsum([len(g.ids) for g in s.groups])
        gids = (np.concatenate([g.ids for g in s.groups]).astype(np.int64) if s.groups
                else np.zeros(0, np.int64))
        # the joint pairs of the index-2 pattern, without building that pattern for index 3
        pairs = _joint_pairs(s) if m else np.zeros((0, 4), np.int64)
        c = np.ascontiguousarray
        self.S = (
            c(s.node_dofadr[s.node_free].astype(np.int64)), c(s.node_free.astype(np.int64)),
            c(s.node_mass[s.node_free], dtype=float), c(s.node_J[s.node_free], dtype=float),
            gk, gstart, gids, c(s.joint_k.astype(np.int64)), jA,
            c(s.joint_dofadr.astype(np.int64)), c(s.joint_a.astype(np.int64)),
            c(s.joint_b.astype(np.int64)), c(free_pos[s.joint_a]), c(free_pos[s.joint_b]),
            c(PA), c(PB), XA, XB,
            c(s.dof_stiffness, dtype=float), c(s.dof_reference, dtype=float),
            c(s.dof_damping, dtype=float), c(s.dof_kp, dtype=float), c(s.dof_kd, dtype=float),
            c(pairs.astype(np.int64)), Apinv,
            c(lie.inverse(s.joint_H0)) if m else np.zeros((0, 4, 4)),
            c(~s.joint_abelian), c(s.node_mass, dtype=float), int(s.nq), int(s.nm),
            _C2, _C3, _C4, _C5)

    def work(self):
        """Fresh work arrays for :func:`_residual` / :func:`_values`."""
        nf = len(self.s.node_free)
        m = self.s.m
        return (np.zeros((nf, 6, 6)), np.zeros((nf, 3)), np.zeros((m, 4, 4)),
                np.zeros((m, 6, 6)), np.zeros((m, 6, 6)), np.zeros((m, 6)),
                np.zeros((nf, 6, 6)), np.zeros((m, 6, 6)))


def fast_system(s) -> FastSystem:
    """The (cached) :class:`FastSystem` of a compiled system."""
    if "fast" not in s.pattern:
        s.pattern["fast"] = FastSystem(s)
    return s.pattern["fast"]


# ---------------------------------------------------------------------------------------------
# Energies and powers (mirror se3dyn.integrator.energies)
# ---------------------------------------------------------------------------------------------
@njit(cache=True)
def _energies(S, H, alpha, v, f_load, mt, tau, ref, rate, gravity, out):
    """out[:] = (kinetic (Eq. (47)), gravity potential, spring energy (Eq. (62)), actuator power
    incl. PD laws, power of the external loads, damper dissipation)."""
    (fdof, fnode, fmass, fJ, gk, gstart, gids, jk, jA, jdof, ja, jb, jfa, jfb, PA, PB, XA, XB,
     dK, dref, dC, dkp, dkd, pairs, Apinv, H0inv, nonab, mass_all, nq, nm, C2, C3, C4, C5) = S
    kin = 0.0
    pext = 0.0
    for q in range(fdof.shape[0]):
        d0 = fdof[q]
        i = fnode[q]
        J = fJ[q]
        ku = v[d0] ** 2 + v[d0 + 1] ** 2 + v[d0 + 2] ** 2
        ko = 0.0
        for a in range(3):
            for c in range(3):
                ko += v[d0 + 3 + a] * J[a, c] * v[d0 + 3 + c]
        kin += 0.5 * (fmass[q] * ku + ko)
        for a in range(3):
            xd = H[i, a, 0] * v[d0] + H[i, a, 1] * v[d0 + 1] + H[i, a, 2] * v[d0 + 2]
            pext += f_load[i, a] * xd + mt[i, a] * v[d0 + 3 + a]
    pot = 0.0
    for i in range(H.shape[0]):
        pot -= mass_all[i] * (H[i, 0, 3] * gravity[0] + H[i, 1, 3] * gravity[1]
                              + H[i, 2, 3] * gravity[2])
    spring = 0.0
    pact = 0.0
    pdiss = 0.0
    for j in range(jk.shape[0]):
        jd = jdof[j]
        for l in range(jk[j]):
            d = jd + l
            e = alpha[d] - dref[d]
            spring += 0.5 * dK[d] * e * e
            tpd = -dkp[d] * (alpha[d] - ref[d]) - dkd[d] * (v[d] - rate[d])
            pact += (tau[d] + tpd) * v[d]
            pdiss += dC[d] * v[d] * v[d]
    out[0] = kin
    out[1] = pot
    out[2] = spring
    out[3] = pact
    out[4] = pext
    out[5] = pdiss


@njit(cache=True)
def _log_coordinates(S, HJ, alpha):
    """Log coordinates ``A^+ log(H_J0^-1 H_J)`` of the non-abelian joints into alpha (nq,)."""
    (fdof, fnode, fmass, fJ, gk, gstart, gids, jk, jA, jdof, ja, jb, jfa, jfb, PA, PB, XA, XB,
     dK, dref, dC, dkp, dkd, pairs, Apinv, H0inv, nonab, mass_all, nq, nm, C2, C3, C4, C5) = S
    lg = np.empty(6)
    D = np.empty((4, 4))
    for j in range(jk.shape[0]):
        k = jk[j]
        if k == 0 or not nonab[j]:
            continue
        _mm4(H0inv[j], HJ[j], D)
        _log_se3(D, lg, C5)
        for l in range(k):
            s = 0.0
            for c in range(6):
                s += Apinv[j, l, c] * lg[c]
            alpha[jdof[j] + l] = s


# ---------------------------------------------------------------------------------------------
# One generalized-alpha step with Newton iterations (mirror GeneralizedAlpha.step)
# ---------------------------------------------------------------------------------------------
@njit(cache=True)
def _step(S, Wk, sym, vmask, vone, store, piv, lwork, dropm,
          Hn, HJn, alpha_n, v_n, vd_n, a_n, lam_n, f, mt, tau, ref, rate,
          h, am, af, g, b, tol_r, ltol, lscale, max_iter, index2, reuse, kmax,
          H, HJ, alpha, v, vd, a, lam, n, r, phi, psi, vals, rhs, sol, info):
    """One step of the Lie-group generalized-alpha scheme (Eqs. (38)-(46)); for index 2 the
    stabilized form of :meth:`se3dyn.integrator.GeneralizedAlpha.step`.

    Inputs are the state at t_n (``a_n`` already rescaled to the step) and the loads at
    t_{n+1}; outputs (H, HJ, alpha, v, vd, a, lam, n) the state at t_{n+1} and the increment.
    ``info`` (4,) receives (iterations, scaled residual, constraint violation,
    factorisations).

    Jacobian reuse (``reuse``, modified Newton): the iteration matrix is factorised at the
    predictor of every step (with the predictor vd_{n+1} = vd_n it is close to the one at the
    solution) and kept over the iterations while Newton contracts fast enough: it is
    recomputed at the current iterate when the scaled residual or constraint violation grows,
    when the contraction rate theta = |dn_k| / |dn_k-1| reaches 0.9, or when at that rate more
    than ``kmax`` (:data:`KMAX`) further iterations would be needed to reach the
    tolerances. Measured on the
    slider-crank and on chains of 100-10000 links, keeping the factors across steps too cost
    more iterations and more factorisations than it saved. The converged solution satisfies
    the same tolerances as full Newton (``reuse=False``: a new matrix every iteration).

    Returns
    -------
    int
        0 converged, 1 non-finite iterate, 2 no convergence within max_iter, 3 diverging,
        4 singular block pivot (the caller falls back to the numpy implementation, which
        reports or recovers).
    """
    (fdof, fnode, fmass, fJ, gk, gstart, gids, jk, jA, jdof, ja, jb, jfa, jfb, PA, PB, XA, XB,
     dK, dref, dC, dkp, dkd, pairs, Apinv, H0inv, nonab, mass_all, nq, nm, C2, C3, C4, C5) = S
    Adn = Wk[7]
    m = jk.shape[0]
    stab = index2 and nm > 0
    if stab:
        for j in range(m):
            _adinv(HJn[j], Adn[j])
    # predictor vd_{n+1} = vd_n (as in GeneralizedAlpha.step), a_{n+1} of Eq. (43) at it
    for i in range(nq):
        vd[i] = vd_n[i]
        a[i] = (vd_n[i] - am * a_n[i]) / (1 - am)
        v[i] = v_n[i] + h * (1 - g) * a_n[i] + h * g * a[i]
        n[i] = h * v_n[i] + h * h * (0.5 - b) * a_n[i] + h * h * b * a[i]
    lam[:] = lam_n
    bp = (1 - am) / (b * h * h * (1 - af))
    gp = g / (b * h)
    cM, cC, cK = 1.0, gp / bp, 1.0 / bp
    cv = 1.0 / gp
    y6 = np.empty(6)  # Ad_n^T xi of one joint
    it = 0
    er0 = 1.0
    er = 0.0
    ep = 0.0
    status = 0
    nfac = 0
    refac = True  # every step starts with the iteration matrix at its predictor
    dn_prev = 0.0
    ec_prev = np.inf
    while True:
        fs = _residual(S, Wk, Hn, HJn, alpha_n, n, v, vd, lam, f, mt, tau, ref, rate, stab,
                       H, HJ, r, phi, psi, alpha)
        fs = max(fs, 1e-300)
        er = 0.0
        for i in range(nq):
            er = max(er, abs(r[i]))
        er /= fs
        ep = 0.0
        for i in range(nm):
            ep = max(ep, abs(phi[i]))
        if stab:
            for i in range(nm):
                ep = max(ep, abs(psi[i]) / gp)
        if not (np.isfinite(er) and np.isfinite(ep)):
            status = 1
            break
        if er <= tol_r and ep <= ltol:
            break
        if it >= max_iter:
            status = 2
            break
        if it >= 3 and (ep > 10.0 * lscale or er > 1e3 * max(er0, 1.0)):
            status = 3
            break
        if it == 0:
            er0 = er
        ec = max(er / tol_r, ep / ltol) if nm > 0 else er / tol_r
        if ec > ec_prev:
            refac = True
        ec_prev = ec
        if refac or not reuse:
            _values(S, Wk, n, HJ, v, lam, cM, cC, cK, stab, cv, vals)
            code = blocklu.factor(sym, vmask, vone, vals, store, piv)
            nfac += 1
            if code != 0:
                status = 4
                break
            refac = False
        for i in range(nq):
            rhs[i] = -r[i] / bp
        for i in range(nm):
            rhs[nq + i] = 0.0 if dropm[i] else -phi[i]
            if stab:
                rhs[nq + nm + i] = 0.0 if dropm[i] else -psi[i] / gp
        blocklu.solve(sym, store, piv, rhs, sol, lwork)
        dnmax = 0.0
        nmax = 0.0
        for i in range(nq):
            n[i] += sol[i]
            dnmax = max(dnmax, abs(sol[i]))
            nmax = max(nmax, abs(n[i]))
        if stab:
            # dm = dn - B_n^T xi (node A: (Ad_n P_A)^T xi, node B: -P_B^T xi, joint: A^T xi)
            X = nq + nm
            for j in range(m):
                mr = X + 6 * j
                if jfa[j] >= 0:
                    da = fdof[jfa[j]]
                    Aj = Adn[j]
                    for c in range(6):
                        s = 0.0
                        for l in range(6):
                            s += Aj[l, c] * sol[mr + l]
                        y6[c] = s
                    P = PA[j]
                    for c in range(6):
                        s = 0.0
                        for l in range(6):
                            s += P[l, c] * y6[l]
                        sol[da + c] -= s
                if jfb[j] >= 0:
                    db = fdof[jfb[j]]
                    for c in range(6):
                        s = 0.0
                        for l in range(6):
                            s += PB[j, l, c] * sol[mr + l]
                        sol[db + c] += s
                jd = jdof[j]
                for c in range(jk[j]):
                    s = 0.0
                    for l in range(6):
                        s += jA[j, l, c] * sol[mr + l]
                    sol[jd + c] -= s
        for i in range(nq):
            v[i] += gp * sol[i]
            vd[i] += bp * sol[i]
        for i in range(nm):
            lam[i] += bp * sol[nq + i]
        it += 1
        # slow contraction -> new Jacobian when, at the observed rate theta, more than
        # kmax further iterations would be needed (not when the corrections are at
        # round-off level)
        if dn_prev > 0 and dnmax > 1e-12 * nmax:
            theta = dnmax / dn_prev
            if theta >= 0.9:
                refac = True
            elif theta > 1e-3:
                lt = math.log(theta)
                k_rem = math.log(tol_r / max(er * theta, tol_r)) / lt
                if nm > 0:
                    k_rem = max(k_rem, math.log(ltol / max(ep * theta, ltol)) / lt)
                if k_rem > kmax:
                    refac = True
        dn_prev = dnmax
        if ep <= ltol and dnmax <= 4e-16 * max(nmax, 1e-300):
            fs = max(_residual(S, Wk, Hn, HJn, alpha_n, n, v, vd, lam, f, mt, tau, ref, rate,
                               stab, H, HJ, r, phi, psi, alpha), 1e-300)
            er = 0.0
            for i in range(nq):
                er = max(er, abs(r[i]))
            er /= fs
            ep = 0.0
            for i in range(nm):
                ep = max(ep, abs(phi[i]))
            if stab:
                for i in range(nm):
                    ep = max(ep, abs(psi[i]) / gp)
            break
    info[0] = it
    info[1] = er
    info[2] = ep
    info[3] = nfac
    if status == 0:
        c1 = (1 - af) / (1 - am)
        for i in range(nq):
            a[i] += c1 * (vd[i] - vd_n[i])
    return status


#: modified Newton: refactorise when more than KMAX further iterations are predicted (a
#: factorisation costs about five iterations on the benchmark models; 5-12 perform alike)
KMAX = 8.0


class Stepper:
    """Python driver of :func:`_step` for one system, formulation and set of dropped equations:
    owns the block LU (:func:`se3dyn.blocklu.from_system`) and the work arrays."""

    def __init__(self, s, index2: bool, drop):
        self.s = s
        self.F = fast_system(s)
        self.index2 = bool(index2)
        self.drop = np.unique(np.asarray(drop, dtype=np.int64))
        self.bl = blocklu.from_system(s, index2=self.index2, drop=self.drop)
        self.Wk = self.F.work()
        self.dropm = np.zeros(s.nm, dtype=np.bool_)
        self.dropm[self.drop] = True
        self.vals = np.zeros(self.bl.nvals)
        N = self.bl.N
        self.rhs = np.zeros(N)
        self.sol = np.zeros(N)
        self.info = np.zeros(4)
        self.factorizations = 0
        self.evals = np.zeros(6)

    def matches(self, index2: bool, drop) -> bool:
        return self.index2 == bool(index2) and np.array_equal(self.drop, np.unique(drop))

    def step(self, st, h, params, inputs, tol_r, ltol, max_iter, reuse=True):
        """Run :func:`_step`; returns (status, H, HJ, alpha, v, vd, a, lam, n)."""
        s = self.s
        am, af, g, b = params
        a_n = st.a
        if st.h_last > 0 and h != st.h_last:
            a_n = st.vd + (h / st.h_last) * (st.a - st.vd)
        nq, nm = s.nq, s.nm
        H = np.empty_like(st.H)
        HJ = np.empty_like(st.HJ)
        alpha = np.empty(nq)
        v, vd, a, n = (np.empty(nq) for _ in range(4))
        lam = np.empty(nm)
        bl = self.bl
        status = _step(self.F.S, self.Wk, bl.sym, bl.vmask, bl.vone, bl.store, bl.piv, bl.work,
                       self.dropm, st.H, st.HJ, st.alpha, st.v, st.vd, a_n, st.lam,
                       inputs["f"], inputs["m"], inputs["tau"], inputs["ref"], inputs["rate"],
                       float(h), am, af, g, b, tol_r, ltol, float(s.length_scale), max_iter,
                       self.index2, bool(reuse), KMAX, H, HJ, alpha, v, vd, a, lam,
                       n, np.empty(nq), np.empty(nm), np.empty(nm), self.vals, self.rhs,
                       self.sol, self.info)
        self.factorizations += int(self.info[3])
        return status, a_n, H, HJ, alpha, v, vd, a, lam, n

    def energies(self, H, alpha, v, inputs) -> np.ndarray:
        """(kinetic, potential, spring, actuator power, load power, dissipation) (6,)."""
        _energies(self.F.S, H, alpha, v, inputs["f_load"], inputs["m"], inputs["tau"],
                  inputs["ref"], inputs["rate"], self.s.gravity, self.evals)
        return self.evals.copy()

    def log_coordinates(self, HJ, alpha) -> None:
        _log_coordinates(self.F.S, HJ, alpha)


def stepper(s, index2: bool, drop) -> Stepper:
    """The (cached) :class:`Stepper` of a system for a formulation and dropped equations."""
    st = s.pattern.get("fast_stepper")
    if st is None or not st.matches(index2, drop):
        st = Stepper(s, index2, drop)
        s.pattern["fast_stepper"] = st
    return st


# ---------------------------------------------------------------------------------------------
# A fixed-step run: the time loop in machine code as well
# ---------------------------------------------------------------------------------------------
@njit(cache=True)
def _run(S, Wk, sym, vmask, vone, store, piv, lwork, dropm,
         H, HJ, alpha, v, vd, a, lam, acc, t_grid, fgrav, gravity,
         ld_node, ld_F, ld_T, act_dof, act_val, ctl_dof, ctl_ref, ctl_rate,
         am, af, g, b, tol_r, ltol, lscale, max_iter, index2, reuse, kmax,
         output_every, rec_t, rec_H, rec_v, rec_vd, rec_lam, rec_alpha, rec_scal, counters,
         i0, i1):
    """Steps ``i0 .. i1-1`` to the times ``t_grid[i]`` (the state is at ``acc[0]`` = t).

    State arrays (H, HJ, alpha, v, vd, a, lam) are updated in place after every converged
    step; ``acc`` (9,) = (t, h_last, work_act, work_ext, dissipated, power (3), unused).
    Loads per step from the tables (``ld_*`` loaded nodes, forces in the inertial frame and
    material torques; ``act_*`` actuator values; ``ctl_*`` PD targets and rates), gravity
    forces ``fgrav`` (M, 3). Every ``output_every``-th step (and the last) is written to the
    ``rec_*`` arrays at row ``counters[0]`` (incremented); ``counters[1]`` accumulates Newton
    iterations, ``counters[2]`` the steps done, ``counters[3]`` the factorisations.

    Returns
    -------
    (status, i) : the status of :func:`_step` (0 = all done) and the failed step index.
    """
    nq = v.shape[0]
    nm = lam.shape[0]
    M = H.shape[0]
    f = fgrav.copy()
    f_load = np.zeros((M, 3))
    mt = np.zeros((M, 3))
    tau = np.zeros(nq)
    ref = np.zeros(nq)
    rate = np.zeros(nq)
    H1 = np.empty_like(H)
    HJ1 = np.empty_like(HJ)
    alpha1 = np.empty(nq)
    v1 = np.empty(nq)
    vd1 = np.empty(nq)
    a1 = np.empty(nq)
    lam1 = np.empty(nm)
    n = np.empty(nq)
    a_n = np.empty(nq)
    r = np.empty(nq)
    phi = np.empty(nm)
    psi = np.empty(nm)
    vals = np.empty(sym[10].shape[0])
    N = lwork.shape[0]
    rhs = np.empty(N)
    sol = np.empty(N)
    info = np.zeros(4)
    en = np.zeros(6)
    for i in range(i0, i1):
        t1 = t_grid[i]
        h = t1 - acc[0]
        # loads at t_{n+1}
        for c in range(ld_node.shape[0]):
            nd = ld_node[c]
            for l in range(3):
                f_load[nd, l] = 0.0
                mt[nd, l] = 0.0
        for c in range(ld_node.shape[0]):
            nd = ld_node[c]
            for l in range(3):
                f_load[nd, l] += ld_F[i, c, l]
                mt[nd, l] += ld_T[i, c, l]
        for c in range(ld_node.shape[0]):
            nd = ld_node[c]
            for l in range(3):
                f[nd, l] = fgrav[nd, l] + f_load[nd, l]
        for c in range(act_dof.shape[0]):
            tau[act_dof[c]] = 0.0
        for c in range(act_dof.shape[0]):
            tau[act_dof[c]] += act_val[i, c]
        for c in range(ctl_dof.shape[0]):
            ref[ctl_dof[c]] = ctl_ref[i, c]
            rate[ctl_dof[c]] = ctl_rate[i, c]
        hl = acc[1]
        if hl > 0 and h != hl:
            for c in range(nq):
                a_n[c] = vd[c] + (h / hl) * (a[c] - vd[c])
        else:
            a_n[:] = a
        st = _step(S, Wk, sym, vmask, vone, store, piv, lwork, dropm,
                   H, HJ, alpha, v, vd, a_n, lam, f, mt, tau, ref, rate,
                   h, am, af, g, b, tol_r, ltol, lscale, max_iter, index2, reuse, kmax,
                   H1, HJ1, alpha1, v1, vd1, a1, lam1, n, r, phi, psi, vals, rhs, sol, info)
        counters[3] += int(info[3])
        if st != 0:
            _log_coordinates(S, HJ, alpha)
            return st, i
        # log coordinates of non-abelian joints: outputs only (no force element uses them
        # in the compiled engine), so computed for the stored rows and the final state
        _energies(S, H1, alpha1, v1, f_load, mt, tau, ref, rate, gravity, en)
        for c in range(3):
            acc[2 + c] += 0.5 * h * (acc[5 + c] + en[3 + c])
            acc[5 + c] = en[3 + c]
        H[:] = H1
        HJ[:] = HJ1
        alpha[:] = alpha1
        v[:] = v1
        vd[:] = vd1
        a[:] = a1
        lam[:] = lam1
        acc[0] = t1
        acc[1] = h
        counters[1] += int(info[0])
        counters[2] += 1
        if (i + 1) % output_every == 0 or i == t_grid.shape[0] - 1:
            _log_coordinates(S, HJ, alpha)
            k = counters[0]
            rec_t[k] = t1
            rec_H[k] = H
            rec_v[k] = v
            rec_vd[k] = vd
            rec_lam[k] = lam
            rec_alpha[k] = alpha
            rec_scal[k, 0] = en[0]
            rec_scal[k, 1] = en[1]
            rec_scal[k, 2] = en[2]
            rec_scal[k, 3] = acc[2]
            rec_scal[k, 4] = acc[3]
            rec_scal[k, 5] = acc[4]
            rec_scal[k, 6] = info[0]
            rec_scal[k, 7] = info[1]
            rec_scal[k, 8] = info[2]
            counters[0] += 1
    _log_coordinates(S, HJ, alpha)
    return 0, i1


def input_tables(s, times: np.ndarray):
    """Loads of every step, compactly: (ld_node, ld_F, ld_T, act_dof, act_val, ctl_dof,
    ctl_ref, ctl_rate, n_ok). ``n_ok`` < len(times) when a time function failed at
    ``times[n_ok]`` (the caller runs up to there and lets the step report the error)."""
    from se3dyn.integrator import _sample

    ns = len(times)
    loaded = sorted({i for i, F, T, item in s.loads})
    lpos = {nd: c for c, nd in enumerate(loaded)}
    ld_F = np.zeros((ns, len(loaded), 3))
    ld_T = np.zeros((ns, len(loaded), 3))
    act_dof = (np.concatenate([d for d, tf, item in s.actuators]).astype(np.int64)
               if s.actuators else np.zeros(0, np.int64))
    act_val = np.zeros((ns, len(act_dof)))
    ctl_dof = (np.concatenate([d for d, *_ in s.controls]).astype(np.int64)
               if s.controls else np.zeros(0, np.int64))
    ctl_ref = np.zeros((ns, len(ctl_dof)))
    ctl_rate = np.zeros((ns, len(ctl_dof)))
    n_ok = ns
    from se3dyn.errors import SimulationError

    if _vector_tables(s, times, lpos, ld_F, ld_T, act_val, ctl_ref, ctl_rate):
        return (np.array(loaded, dtype=np.int64), ld_F, ld_T, act_dof, act_val, ctl_dof,
                ctl_ref, ctl_rate, n_ok)
    for x in (ld_F, ld_T, act_val, ctl_ref, ctl_rate):
        x[:] = 0.0
    try:
        for k, t in enumerate(times):
            n_ok = k
            for i, F, T, item in s.loads:
                c = lpos[i]
                if F is not None:
                    ld_F[k, c] += _sample(F, t, (3,), item, "force")
                if T is not None:
                    ld_T[k, c] += _sample(T, t, (3,), item, "torque")
            o = 0
            for d, tf, item in s.actuators:
                act_val[k, o:o + len(d)] = _sample(tf, t, d.shape, item, "value")
                o += len(d)
            o = 0
            for d, tgt, rt, item in s.controls:
                ctl_ref[k, o:o + len(d)] = _sample(tgt, t, d.shape, item, "target")
                ctl_rate[k, o:o + len(d)] = (
                    _sample(tgt.rate, t, d.shape, item, "target rate") if rt is None
                    else _sample(rt, t, d.shape, item, "target_rate"))
                o += len(d)
        n_ok = ns
    except SimulationError:
        pass
    return (np.array(loaded, dtype=np.int64), ld_F, ld_T, act_dof, act_val, ctl_dof, ctl_ref,
            ctl_rate, n_ok)


def _table(f, times: np.ndarray, shape: tuple, rate: bool = False) -> np.ndarray | None:
    """Values (nt,) + shape of a time function at all ``times`` at once
    (:meth:`se3dyn.timefunc.TimeFunction.sample`); None when that is not possible or gives
    non-finite values (the caller then samples time by time, which names the failure)."""
    fn = getattr(f, "sample_rate" if rate else "sample", None)
    if fn is None:
        return None
    try:
        val = np.asarray(fn(times), dtype=float)
        val = np.broadcast_to(val.reshape(len(times), -1), (len(times),) + tuple(shape))
    except Exception:  # user code: anything; the per-time path reports it
        return None
    return val if np.all(np.isfinite(val)) else None


def _vector_tables(s, times, lpos, ld_F, ld_T, act_val, ctl_ref, ctl_rate) -> bool:
    """Fill the load tables of :func:`input_tables` with one vectorised evaluation per time
    function; False when some function needs the time-by-time path."""
    for i, F, T, _item in s.loads:
        c = lpos[i]
        for fn, out in ((F, ld_F), (T, ld_T)):
            if fn is not None:
                x = _table(fn, times, (3,))
                if x is None:
                    return False
                out[:, c] += x
    o = 0
    for d, tf, _item in s.actuators:
        x = _table(tf, times, d.shape)
        if x is None:
            return False
        act_val[:, o:o + len(d)] = x
        o += len(d)
    o = 0
    for d, tgt, rt, _item in s.controls:
        x = _table(tgt, times, d.shape)
        y = _table(tgt, times, d.shape, rate=True) if rt is None else _table(rt, times, d.shape)
        if x is None or y is None:
            return False
        ctl_ref[:, o:o + len(d)] = x
        ctl_rate[:, o:o + len(d)] = y
        o += len(d)
    return True


def run_fixed(stp: Stepper, st, t_grid, i0, i1, tables, params, tol_r, ltol, max_iter,
              output_every, rec, reuse=True):
    """Drive :func:`_run` from state ``st`` (modified in place) over steps i0..i1-1; records
    into the arrays of the recorder ``rec``. Returns (status, i, newton_iterations)."""
    s = stp.s
    bl = stp.bl
    am, af, g, b = params
    acc = np.zeros(9)
    acc[0] = st.t
    acc[1] = st.h_last
    acc[2:5] = (st.work_act, st.work_ext, st.dissipated)
    acc[5:8] = st.power
    counters = np.array([rec.n, 0, 0, 0], dtype=np.int64)
    ld_node, ld_F, ld_T, act_dof, act_val, ctl_dof, ctl_ref, ctl_rate, _ = tables
    fgrav = np.ascontiguousarray(s.node_mass[:, None] * s.gravity)
    status, i = _run(stp.F.S, stp.Wk, bl.sym, bl.vmask, bl.vone, bl.store, bl.piv, bl.work,
                     stp.dropm, st.H, st.HJ, st.alpha, st.v, st.vd, st.a, st.lam, acc,
                     t_grid, fgrav, np.asarray(s.gravity, dtype=float), ld_node, ld_F, ld_T,
                     act_dof, act_val, ctl_dof, ctl_ref, ctl_rate, am, af, g, b, tol_r, ltol,
                     float(s.length_scale), max_iter, stp.index2, bool(reuse), KMAX,
                     output_every, rec.t, rec.H,
                     rec.v, rec.vd, rec.lam, rec.alpha, rec.scal, counters, i0, i1)
    st.t = float(acc[0])
    st.h_last = float(acc[1])
    st.work_act, st.work_ext, st.dissipated = (float(x) for x in acc[2:5])
    st.power = acc[5:8].copy()
    rec.n = int(counters[0])
    stp.factorizations += int(counters[3])
    return int(status), int(i), int(counters[1])
