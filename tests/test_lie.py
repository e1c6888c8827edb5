"""Property-based tests of the Lie-group kernel :mod:`se3dyn.lie`.

Conventions under test (module docstring of ``se3dyn.lie``; paper Eqs. (1)-(27), (56)-(57)):
tangent vectors are 6-vectors ``(U, Omega)``, translation first, and material:
``d(H) = H hat6(h)``.

What is covered, every property over near-identity (0, 1e-12..1e-6), moderate, near-pi
(pi - 1e-9 .. pi) and, where the function is defined there, larger rotation angles, and over
batch shapes ``()``, ``(5,)``, ``(2, 3)``:

* hat/vee: inverse pairs, ``hat3(w) u = w x u``, the layout of Eqs. (2), (3), (6).
* Group: ``exp_so3`` is orthonormal with det +1, inverse/compose/make_frame follow Eq. (1).
* exp/log round trips for SO(3) and SE(3) (``log(exp(n)) = n`` below pi, ``exp(log(H)) = H``
  for any frame, including exact half turns), ``box_minus(box_plus(H, n), H) = n``.
* Exponentials against ``scipy.linalg.expm`` and the one-parameter-subgroup property.
* Tangent operators: central finite differences of Eq. (20); the exact integral
  ``T(n) = int_0^1 expm(-s ad6(n)) ds`` (Van Loan block exponential); ``T Tinv = I`` up to
  ``|n_Omega| = 6``; ``T(n) n = n``; ``T(-n) = Ad(exp n) T(n)``; the block layout of Eq. (21);
  ``T_UOmega+(n_U, 0) = -hat3(n_U)/2`` exactly; ``T(A q) A = A`` for the hinge, prismatic,
  cylindrical and screw subalgebras, which are abelian (Eq. (11)); ``exp_tangent_se3`` returns
  ``(exp_se3, tangent_se3)``.
* Adjoint: conjugation identity, ``adjoint_inv`` (explicit Eq. (57)), homomorphism,
  ``Ad(exp n) = expm(ad6 n)``, equivariance of exp; ``ad6`` is the commutator, Jacobi identity.
* ``vect_se3`` (Eq. (56)): explicit form, zero at the identity, first-order agreement with the
  exponential argument with the exact second-order term ``(Omega x U / 2, 0)``.
* Accuracy claims: exact identities at angle 0; agreement with the closed forms of
  Eqs. (17)-(19), (22) (and the closed-form inverse tangent) evaluated in mpmath with 40 digits
  beyond the worst cancellation, to 1e-13 relative; relative accuracy of the coefficient
  functions for all angles (white-box); relative accuracy when ``|n_Omega|^2`` underflows;
  no NaN/inf for any angle in [0, pi].
* Batch behaviour: every public function on a batch equals the stack of single calls.
"""

from __future__ import annotations

import math

import mpmath as mp
import numpy as np
import pytest
import scipy.linalg
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from se3dyn import lie

PI = math.pi
EPS = np.finfo(float).eps

# Round trips and comparisons with an independent reference: the module promises a few ulps
# per coefficient (worst ~100 eps at t ~ 1); 1e-12 leaves a margin for the matrix arithmetic.
RTOL = 1e-12
# Comparison with scipy.linalg.expm, the Van Loan integral and mpmath references.
REF_TOL = 1e-13

COMMON = settings(deadline=None, suppress_health_check=[HealthCheck.too_slow])
BATCH = settings(COMMON, max_examples=15)
FEW = settings(COMMON, max_examples=25)
MANY = settings(COMMON, max_examples=50)


# ---------------------------------------------------------------------------------------------
# Strategies
# ---------------------------------------------------------------------------------------------
def finite(lo: float, hi: float) -> st.SearchStrategy[float]:
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False, allow_subnormal=False)


ZERO = st.just(0.0)
TINY = finite(-12.0, -6.0).map(lambda e: 10.0**e)  # log-uniform in [1e-12, 1e-6]
MODERATE = finite(1e-6, 3.0)
BELOW_NEAR_PI = finite(3.0, PI - 1e-9)
NEAR_PI = st.one_of(finite(PI - 1e-9, PI), st.just(PI))
BEYOND_PI = finite(PI, 6.0)

ANGLES_BELOW_PI = st.one_of(ZERO, TINY, MODERATE, BELOW_NEAR_PI)
ANGLES_UP_TO_PI = st.one_of(ANGLES_BELOW_PI, NEAR_PI)
ANGLES_UP_TO_6 = st.one_of(ANGLES_UP_TO_PI, BEYOND_PI)

BATCH_SHAPES = st.sampled_from([(), (5,), (2, 3)])
TRANSLATION = finite(-5.0, 5.0)


def _unit_from_angles(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    st_ = np.sin(theta)
    return np.stack([st_ * np.cos(phi), st_ * np.sin(phi), np.cos(theta)], axis=-1)


@st.composite
def unit_vectors(draw, shape=()):
    theta = draw(arrays(np.float64, shape, elements=finite(0.0, PI)))
    phi = draw(arrays(np.float64, shape, elements=finite(0.0, 2 * PI)))
    return _unit_from_angles(theta, phi)


@st.composite
def rotation_vectors(draw, angles=ANGLES_BELOW_PI, shape=None):
    """Rotation vectors ``t a`` with unit axis ``a`` and angle ``t`` drawn from ``angles``."""
    shape = draw(BATCH_SHAPES) if shape is None else shape
    axis = draw(unit_vectors(shape))
    t = draw(arrays(np.float64, shape, elements=angles))
    return axis * t[..., None]


@st.composite
def twists(draw, angles=ANGLES_BELOW_PI, shape=None, translation=TRANSLATION):
    """Tangent vectors ``(n_U, n_Omega)`` (translation first)."""
    shape = draw(BATCH_SHAPES) if shape is None else shape
    w = draw(rotation_vectors(angles, shape))
    u = draw(arrays(np.float64, shape + (3,), elements=translation))
    return np.concatenate([u, w], axis=-1)


def quat_to_rot(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion (scalar first), independent of ``se3dyn.lie``."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )


def frame(R: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``H(R, x)`` of Eq. (1), built by hand."""
    H = np.zeros(np.broadcast_shapes(R.shape[:-2], x.shape[:-1]) + (4, 4))
    H[..., :3, :3] = R
    H[..., :3, 3] = x
    H[..., 3, 3] = 1.0
    return H


@st.composite
def rotations(draw, shape=None):
    """Any rotation, from a unit quaternion; scalar part 0 (exact half turns) is frequent."""
    shape = draw(BATCH_SHAPES) if shape is None else shape
    q = draw(arrays(np.float64, shape + (4,), elements=finite(-1.0, 1.0)))
    nq = np.linalg.norm(q, axis=-1, keepdims=True)
    q = np.where(nq > 1e-3, q / np.where(nq > 0, nq, 1.0), np.array([1.0, 0.0, 0.0, 0.0]))
    return quat_to_rot(q)


@st.composite
def frames(draw, shape=None):
    shape = draw(BATCH_SHAPES) if shape is None else shape
    R = draw(rotations(shape))
    x = draw(arrays(np.float64, shape + (3,), elements=TRANSLATION))
    return frame(R, x)


# ---------------------------------------------------------------------------------------------
# Helpers
# ---------------------------------------------------------------------------------------------
def norm(v: np.ndarray) -> np.ndarray:
    """Euclidean norm over the last axis without underflow (|v| ~ 1e-188 must not give 0)."""
    v = np.asarray(v, dtype=float)
    m = np.max(np.abs(v), axis=-1)
    safe = np.where(m > 0, m, 1.0)
    return m * np.sqrt(np.sum((v / safe[..., None]) ** 2, axis=-1))


def assert_scaled_close(got, want, scale, tol: float, err_msg: str = "") -> None:
    """Entrywise ``|got - want| <= tol * scale``, ``scale`` given per batch element."""
    got = np.asarray(got, dtype=float)
    want = np.asarray(want, dtype=float)
    diff = got - want
    scale = np.asarray(scale, dtype=float)
    scale = scale.reshape(scale.shape + (1,) * (diff.ndim - scale.ndim))
    np.testing.assert_allclose(diff / scale, 0.0, rtol=0.0, atol=tol, err_msg=err_msg)


def mv(M: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.einsum("...ij,...j->...i", M, v)


I3, I4, I6 = np.eye(3), np.eye(4), np.eye(6)


# =============================================================================================
# 10. hat / vee, group basics
# =============================================================================================
@MANY
@given(w=arrays(np.float64, st.sampled_from([(3,), (5, 3), (2, 3, 3)]), elements=TRANSLATION))
def test_vee3_inverts_hat3_and_hat3_is_skew(w):
    W = lie.hat3(w)
    np.testing.assert_array_equal(lie.vee3(W), w)
    np.testing.assert_array_equal(W, -np.swapaxes(W, -1, -2))


@MANY
@given(
    wu=arrays(np.float64, st.sampled_from([(2, 3), (2, 5, 3), (2, 2, 3, 3)]), elements=TRANSLATION)
)
def test_hat3_times_vector_is_cross_product(wu):
    w, u = wu[0], wu[1]
    scale = np.maximum(norm(w) * norm(u), 1.0)
    assert_scaled_close(mv(lie.hat3(w), u), np.cross(w, u), scale, 4 * EPS)


@MANY
@given(n=arrays(np.float64, st.sampled_from([(6,), (5, 6), (2, 3, 6)]), elements=TRANSLATION))
def test_hat6_has_layout_of_eq2_and_vee6_inverts_it(n):
    X = lie.hat6(n)
    np.testing.assert_array_equal(X[..., :3, :3], lie.hat3(n[..., 3:]))
    np.testing.assert_array_equal(X[..., :3, 3], n[..., :3])
    np.testing.assert_array_equal(X[..., 3, :], 0.0)
    np.testing.assert_array_equal(lie.vee6(X), n)


@MANY
@given(n=arrays(np.float64, st.sampled_from([(6,), (5, 6)]), elements=TRANSLATION))
def test_ad6_has_layout_of_eq6(n):
    A = lie.ad6(n)
    np.testing.assert_array_equal(A[..., :3, :3], lie.hat3(n[..., 3:]))
    np.testing.assert_array_equal(A[..., 3:, 3:], lie.hat3(n[..., 3:]))
    np.testing.assert_array_equal(A[..., :3, 3:], lie.hat3(n[..., :3]))
    np.testing.assert_array_equal(A[..., 3:, :3], 0.0)


@MANY
@given(w=rotation_vectors(ANGLES_UP_TO_6))
def test_exp_so3_is_orthonormal_with_unit_determinant(w):
    R = lie.exp_so3(w)
    # Each entry of I + a W + h W^2 carries ~eps (1 + t|a| + t^2 h) <= 5 eps of rounding for
    # t <= 6; R^T R and det sum three such products: 1e-14 (~45 eps) bounds both.
    np.testing.assert_allclose(np.swapaxes(R, -1, -2) @ R, np.broadcast_to(I3, R.shape),
                               rtol=0, atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, rtol=0, atol=1e-14)


@MANY
@given(H=frames())
def test_inverse_is_two_sided_group_inverse(H):
    scale = np.maximum(1.0, norm(H[..., :3, 3]))
    eye = np.broadcast_to(I4, H.shape)
    assert_scaled_close(lie.inverse(H) @ H, eye, scale, 16 * EPS)
    assert_scaled_close(H @ lie.inverse(H), eye, scale, 16 * EPS)
    np.testing.assert_array_equal(lie.inverse(H)[..., 3, :], np.broadcast_to([0, 0, 0, 1.0],
                                                                             H.shape[:-1]))


@MANY
@given(data=st.data())
def test_compose_and_make_frame_follow_eq1(data):
    shape = data.draw(BATCH_SHAPES)
    R1, R2 = data.draw(rotations(shape)), data.draw(rotations(shape))
    x1 = data.draw(arrays(np.float64, shape + (3,), elements=TRANSLATION))
    x2 = data.draw(arrays(np.float64, shape + (3,), elements=TRANSLATION))
    H1 = lie.make_frame(R1, x1)
    np.testing.assert_array_equal(H1, frame(R1, x1))
    np.testing.assert_array_equal(lie.make_frame(), I4)
    np.testing.assert_array_equal(lie.make_frame(x=x1), frame(np.broadcast_to(I3, shape + (3, 3)),
                                                              x1))
    H12 = lie.compose(H1, lie.make_frame(R2, x2))
    scale = 1.0 + norm(x1) + norm(x2)
    assert_scaled_close(H12, frame(R1 @ R2, mv(R1, x2) + x1), scale, 8 * EPS)


# =============================================================================================
# 1. exp / log round trips
# =============================================================================================
@MANY
@given(w=rotation_vectors(ANGLES_BELOW_PI))
def test_log_so3_inverts_exp_so3_below_pi(w):
    # Relative to |w| (the module promises relative accuracy down to tiny angles); w = 0 exactly
    # must give exactly 0.
    scale = np.maximum(norm(w), 1e-200)
    assert_scaled_close(lie.log_so3(lie.exp_so3(w)), w, scale, RTOL)


@MANY
@given(w=rotation_vectors(NEAR_PI))
def test_exp_so3_inverts_log_so3_near_pi(w):
    R = lie.exp_so3(w)
    v = lie.log_so3(R)
    np.testing.assert_allclose(lie.exp_so3(v), R, rtol=0, atol=RTOL)
    assert np.all(norm(v) <= PI * (1 + 4 * EPS))
    # The rotation vector is determined up to sign at pi: v = +-w.
    err = np.minimum(norm(v - w), norm(v + w))
    np.testing.assert_allclose(err, 0.0, rtol=0, atol=RTOL * PI)


@MANY
@given(R=rotations())
def test_log_so3_of_any_rotation_is_a_principal_logarithm(R):
    v = lie.log_so3(R)
    assert np.all(norm(v) <= PI * (1 + 4 * EPS))
    np.testing.assert_allclose(lie.exp_so3(v), R, rtol=0, atol=RTOL)


@FEW
@given(a=unit_vectors((5,)))
def test_log_so3_of_exact_half_turn_has_angle_pi_and_axis_a(a):
    a = np.concatenate([a, np.eye(3), [[1.0, 1.0, 0.0]] / np.sqrt(2.0)])
    R = 2.0 * a[:, :, None] * a[:, None, :] - I3  # rotation by pi about a: 2 a a^T - I
    v = lie.log_so3(R)
    assert np.all(np.isfinite(v))
    np.testing.assert_allclose(norm(v), PI, rtol=RTOL)
    np.testing.assert_allclose(np.abs(np.einsum("ni,ni->n", v, a)), PI, rtol=RTOL)
    np.testing.assert_allclose(lie.exp_so3(v), R, rtol=0, atol=RTOL)


@MANY
@given(n=twists(ANGLES_BELOW_PI))
def test_log_se3_inverts_exp_se3_below_pi(n):
    m = lie.log_se3(lie.exp_se3(n))
    # Each part relative to its own size (floors only avoid 0/0; zero parts come back as 0).
    assert_scaled_close(m[..., :3], n[..., :3], np.maximum(norm(n[..., :3]), 1e-200), RTOL)
    assert_scaled_close(m[..., 3:], n[..., 3:], np.maximum(norm(n[..., 3:]), 1e-200), RTOL)


@MANY
@given(n=twists(NEAR_PI))
def test_exp_se3_inverts_log_se3_near_pi(n):
    H = lie.exp_se3(n)
    m = lie.log_se3(H)
    assert np.all(norm(m[..., 3:]) <= PI * (1 + 4 * EPS))
    assert_scaled_close(lie.exp_se3(m), H, np.maximum(1.0, norm(n)), RTOL)


@MANY
@given(H=frames())
def test_exp_se3_inverts_log_se3_for_any_frame(H):
    m = lie.log_se3(H)
    assert np.all(norm(m[..., 3:]) <= PI * (1 + 4 * EPS))
    assert_scaled_close(lie.exp_se3(m), H, np.maximum(1.0, norm(H[..., :3, 3])), RTOL)


@MANY
@given(data=st.data())
def test_box_minus_inverts_box_plus(data):
    shape = data.draw(BATCH_SHAPES)
    H = data.draw(frames(shape))
    n = data.draw(twists(ANGLES_BELOW_PI, shape))
    scale = np.maximum.reduce([np.ones(shape), norm(n), norm(H[..., :3, 3])])
    assert_scaled_close(lie.box_minus(lie.box_plus(H, n), H), n, scale, RTOL)
    # and the other way round: H0 [+] (H1 [-] H0) == H1
    H1 = data.draw(frames(shape))
    scale1 = 1.0 + norm(H[..., :3, 3]) + norm(H1[..., :3, 3])
    assert_scaled_close(lie.box_plus(H, lie.box_minus(H1, H)), H1, scale1, RTOL)


# =============================================================================================
# 7. exponentials against scipy.linalg.expm
# =============================================================================================
def _expm_batch(M: np.ndarray) -> np.ndarray:
    flat = M.reshape((-1,) + M.shape[-2:])
    return np.stack([scipy.linalg.expm(m) for m in flat]).reshape(M.shape)


@MANY
@given(w=rotation_vectors(ANGLES_UP_TO_6))
def test_exp_so3_equals_matrix_exponential_of_hat3(w):
    np.testing.assert_allclose(lie.exp_so3(w), _expm_batch(lie.hat3(w)), rtol=0, atol=REF_TOL)


@MANY
@given(n=twists(ANGLES_UP_TO_6))
def test_exp_se3_equals_matrix_exponential_of_hat6(n):
    assert_scaled_close(lie.exp_se3(n), _expm_batch(lie.hat6(n)), np.maximum(1.0, norm(n)),
                        REF_TOL)


@MANY
@given(n=twists(ANGLES_UP_TO_PI), s=finite(-1.0, 1.0), r=finite(-1.0, 1.0))
def test_exp_se3_is_a_one_parameter_subgroup(n, s, r):
    lhs = lie.exp_se3((s + r) * n)
    rhs = lie.exp_se3(s * n) @ lie.exp_se3(r * n)
    assert_scaled_close(lhs, rhs, np.maximum(1.0, norm(n)), RTOL)


@MANY
@given(n=twists(ANGLES_UP_TO_6))
def test_exp_se3_has_the_block_form_of_eq17(n):
    H = lie.exp_se3(n)
    scale = np.maximum(1.0, norm(n))
    assert_scaled_close(H[..., :3, :3], lie.exp_so3(n[..., 3:]), scale, 4 * EPS)
    TsoT = np.swapaxes(lie.tangent_so3(n[..., 3:]), -1, -2)
    assert_scaled_close(H[..., :3, 3], mv(TsoT, n[..., :3]), scale, 16 * EPS)
    np.testing.assert_array_equal(H[..., 3, :], np.broadcast_to([0, 0, 0, 1.0], H.shape[:-1]))


# =============================================================================================
# 2. tangent operators: derivative of the exponential map (Eq. (20))
# =============================================================================================
# Central differences with step e: truncation (e^2/6)|d^3/de^3 exp(n + e dn)| <~ 2e-11 (1+|n|)^3
# and rounding ~ eps |exp(n)| / e <~ 2e-11 (1+|n|) for e = 1e-5 and |dn_i| <= 1. A tolerance of
# 1e-8 (1+|n|)^2 keeps two orders of magnitude of margin over the measured FD error (~2e-10).
FD_STEP = 1e-5
FD_TOL = 1e-8


@MANY
@given(data=st.data())
def test_tangent_se3_is_the_derivative_of_exp_se3_eq20(data):
    shape = data.draw(BATCH_SHAPES)
    n = data.draw(twists(ANGLES_UP_TO_6, shape))
    dn = data.draw(arrays(np.float64, shape + (6,), elements=finite(-1.0, 1.0)))
    e = FD_STEP
    dH = (lie.exp_se3(n + e * dn) - lie.exp_se3(n - e * dn)) / (2 * e)
    h_fd = lie.vee6(lie.inverse(lie.exp_se3(n)) @ dH)
    assert_scaled_close(mv(lie.tangent_se3(n), dn), h_fd, (1.0 + norm(n)) ** 2, FD_TOL)


@MANY
@given(data=st.data())
def test_tangent_so3_is_the_derivative_of_exp_so3(data):
    shape = data.draw(BATCH_SHAPES)
    w = data.draw(rotation_vectors(ANGLES_UP_TO_6, shape))
    dw = data.draw(arrays(np.float64, shape + (3,), elements=finite(-1.0, 1.0)))
    e = FD_STEP
    dR = (lie.exp_so3(w + e * dw) - lie.exp_so3(w - e * dw)) / (2 * e)
    h_fd = lie.vee3(np.swapaxes(lie.exp_so3(w), -1, -2) @ dR)
    assert_scaled_close(mv(lie.tangent_so3(w), dw), h_fd, (1.0 + norm(w)) ** 2, FD_TOL)


def _integral_of_expm(A: np.ndarray) -> np.ndarray:
    """``int_0^1 expm(s A) ds`` via Van Loan: the top-right block of expm([[A, I], [0, 0]])."""
    m = A.shape[-1]
    flat = A.reshape((-1, m, m))
    out = []
    for a in flat:
        M = np.zeros((2 * m, 2 * m))
        M[:m, :m] = a
        M[:m, m:] = np.eye(m)
        out.append(scipy.linalg.expm(M)[:m, m:])
    return np.stack(out).reshape(A.shape)


@MANY
@given(n=twists(ANGLES_UP_TO_6))
def test_tangent_se3_equals_integral_of_exp_of_minus_ad(n):
    # Right-trivialised derivative of exp: T(n) = sum_k (-ad n)^k/(k+1)! = int_0^1 e^{-s ad n} ds
    assert_scaled_close(lie.tangent_se3(n), _integral_of_expm(-lie.ad6(n)),
                        np.maximum(1.0, norm(n)), REF_TOL)


@MANY
@given(w=rotation_vectors(ANGLES_UP_TO_6))
def test_tangent_so3_equals_integral_of_exp_of_minus_hat(w):
    np.testing.assert_allclose(lie.tangent_so3(w), _integral_of_expm(-lie.hat3(w)),
                               rtol=0, atol=REF_TOL)


# =============================================================================================
# 3. tangent inverses and fixed vectors
# =============================================================================================
@MANY
@given(n=twists(ANGLES_UP_TO_6))
def test_tangent_se3_times_tangent_se3_inv_is_identity_below_2pi(n):
    T, Ti = lie.tangent_se3(n), lie.tangent_se3_inv(n)
    eye = np.broadcast_to(I6, T.shape)
    scale = np.maximum(1.0, norm(n))
    assert_scaled_close(T @ Ti, eye, scale, RTOL)
    assert_scaled_close(Ti @ T, eye, scale, RTOL)


@MANY
@given(w=rotation_vectors(ANGLES_UP_TO_6))
def test_tangent_so3_times_tangent_so3_inv_is_identity_below_2pi(w):
    T, Ti = lie.tangent_so3(w), lie.tangent_so3_inv(w)
    eye = np.broadcast_to(I3, T.shape)
    np.testing.assert_allclose(T @ Ti, eye, rtol=0, atol=RTOL)
    np.testing.assert_allclose(Ti @ T, eye, rtol=0, atol=RTOL)


@MANY
@given(n=twists(ANGLES_UP_TO_6))
def test_tangent_operators_fix_their_argument(n):
    scale = np.maximum(1.0, norm(n))
    assert_scaled_close(mv(lie.tangent_se3(n), n), n, scale, RTOL)
    assert_scaled_close(mv(lie.tangent_se3_inv(n), n), n, scale, RTOL)
    w = n[..., 3:]
    assert_scaled_close(mv(lie.tangent_so3(w), w), w, scale, RTOL)
    assert_scaled_close(mv(lie.tangent_so3_inv(w), w), w, scale, RTOL)


@MANY
@given(n=twists(ANGLES_UP_TO_6))
def test_tangent_of_negated_argument_is_adjoint_transport(n):
    # J_r(-n) = J_l(n) = Ad(exp n) J_r(n)
    lhs = lie.tangent_se3(-n)
    rhs = lie.adjoint(lie.exp_se3(n)) @ lie.tangent_se3(n)
    assert_scaled_close(lhs, rhs, np.maximum(1.0, norm(n)) ** 2, RTOL)


# =============================================================================================
# 4. the paper's remarks on T_SE(3)
# =============================================================================================
@MANY
@given(n=twists(ANGLES_UP_TO_6))
def test_tangent_se3_has_the_block_form_of_eq21(n):
    T = lie.tangent_se3(n)
    Tso = lie.tangent_so3(n[..., 3:])
    np.testing.assert_array_equal(T[..., :3, :3], Tso)
    np.testing.assert_array_equal(T[..., 3:, 3:], Tso)
    np.testing.assert_array_equal(T[..., 3:, :3], 0.0)


@MANY
@given(n=twists(ANGLES_UP_TO_6))
def test_exp_tangent_se3_returns_exp_se3_and_tangent_se3(n):
    E, T = lie.exp_tangent_se3(n)
    scale = np.maximum(1.0, norm(n))
    assert_scaled_close(E, lie.exp_se3(n), scale, 4 * EPS)
    assert_scaled_close(T, lie.tangent_se3(n), scale**2, 4 * EPS)


@MANY
@given(u=arrays(np.float64, st.sampled_from([(3,), (5, 3), (2, 3, 3)]), elements=TRANSLATION))
def test_coupling_block_at_zero_rotation_is_exactly_minus_half_hat(u):
    n = np.concatenate([u, np.zeros_like(u)], axis=-1)
    T = lie.tangent_se3(n)
    np.testing.assert_array_equal(T[..., :3, 3:], -lie.hat3(u) / 2)
    np.testing.assert_array_equal(T[..., :3, :3], np.broadcast_to(I3, T.shape[:-2] + (3, 3)))
    np.testing.assert_array_equal(T[..., 3:, 3:], np.broadcast_to(I3, T.shape[:-2] + (3, 3)))


def joint_subalgebra(kind: str, a: np.ndarray, pitch: float) -> np.ndarray:
    """Columns spanning the allowed material twists (Table 1; screw: (p a, a))."""
    z = np.zeros(3)
    cols = {
        "hinge": [np.r_[z, a]],
        "prismatic": [np.r_[a, z]],
        "cylindrical": [np.r_[a, z], np.r_[z, a]],
        "screw": [np.r_[pitch * a, a]],
    }[kind]
    return np.stack(cols, axis=-1)


JOINTS = ["hinge", "prismatic", "cylindrical", "screw"]


@pytest.mark.parametrize("kind", JOINTS)
@MANY
@given(a=unit_vectors(), q=st.tuples(finite(-10.0, 10.0), finite(-10.0, 10.0)),
       pitch=finite(-3.0, 3.0))
def test_tangent_se3_restricted_to_joint_subalgebra_is_identity(kind, a, q, pitch):
    A = joint_subalgebra(kind, a, pitch)
    qv = np.array(q[: A.shape[1]])
    n = A @ qv
    # Exact in exact arithmetic (hat(a) a = 0); rounding leaves O(eps |n|^2).
    scale = max(1.0, float(np.linalg.norm(n))) ** 2
    np.testing.assert_allclose(lie.tangent_se3(n) @ A, A, rtol=0, atol=16 * EPS * scale)


@pytest.mark.parametrize("kind", JOINTS)
@MANY
@given(a=unit_vectors(), v=st.tuples(finite(-10.0, 10.0), finite(-10.0, 10.0)),
       pitch=finite(-3.0, 3.0))
def test_joint_subalgebras_are_abelian_eq11(kind, a, v, pitch):
    A = joint_subalgebra(kind, a, pitch)
    vv = np.array(v[: A.shape[1]])
    scale = max(1.0, float(np.linalg.norm(A @ vv))) * max(1.0, abs(pitch))
    np.testing.assert_allclose(lie.ad6(A @ vv) @ A, 0.0, rtol=0, atol=8 * EPS * scale)


# =============================================================================================
# 5. adjoint and ad
# =============================================================================================
@MANY
@given(data=st.data())
def test_adjoint_conjugates_hat6(data):
    shape = data.draw(BATCH_SHAPES)
    H = data.draw(frames(shape))
    v = data.draw(arrays(np.float64, shape + (6,), elements=TRANSLATION))
    lhs = lie.hat6(mv(lie.adjoint(H), v))
    rhs = H @ lie.hat6(v) @ lie.inverse(H)
    scale = np.maximum(1.0, norm(v)) * np.maximum(1.0, norm(H[..., :3, 3]))
    assert_scaled_close(lhs, rhs, scale, RTOL)


@MANY
@given(H=frames())
def test_adjoint_inv_is_inverse_of_adjoint_and_adjoint_of_inverse(H):
    Ai = lie.adjoint_inv(H)
    scale = np.maximum(1.0, norm(H[..., :3, 3]))
    assert_scaled_close(Ai, np.linalg.inv(lie.adjoint(H)), scale, RTOL)
    assert_scaled_close(Ai, lie.adjoint(lie.inverse(H)), scale, RTOL)
    assert_scaled_close(Ai @ lie.adjoint(H), np.broadcast_to(I6, Ai.shape), scale**2, RTOL)


@MANY
@given(H=frames())
def test_adjoint_inv_has_the_explicit_form_of_eq57(H):
    R, x = H[..., :3, :3], H[..., :3, 3]
    Rt = np.swapaxes(R, -1, -2)
    want = np.zeros(H.shape[:-2] + (6, 6))
    want[..., :3, :3] = Rt
    want[..., 3:, 3:] = Rt
    want[..., :3, 3:] = -Rt @ lie.hat3(x)
    np.testing.assert_allclose(lie.adjoint_inv(H), want, rtol=0, atol=4 * EPS * 5)


@MANY
@given(data=st.data())
def test_adjoint_is_a_group_homomorphism(data):
    shape = data.draw(BATCH_SHAPES)
    H1, H2 = data.draw(frames(shape)), data.draw(frames(shape))
    scale = (1.0 + norm(H1[..., :3, 3])) * (1.0 + norm(H2[..., :3, 3]))
    assert_scaled_close(lie.adjoint(H1 @ H2), lie.adjoint(H1) @ lie.adjoint(H2), scale, RTOL)


@FEW
@given(n=twists(ANGLES_UP_TO_6))
def test_adjoint_of_exp_is_matrix_exponential_of_ad6(n):
    assert_scaled_close(lie.adjoint(lie.exp_se3(n)), _expm_batch(lie.ad6(n)),
                        np.maximum(1.0, norm(n)) ** 2, REF_TOL)


@MANY
@given(data=st.data())
def test_exp_se3_is_equivariant_under_conjugation(data):
    shape = data.draw(BATCH_SHAPES)
    H = data.draw(frames(shape))
    n = data.draw(twists(ANGLES_UP_TO_6, shape))
    lhs = lie.exp_se3(mv(lie.adjoint(H), n))
    rhs = H @ lie.exp_se3(n) @ lie.inverse(H)
    scale = (1.0 + norm(n)) * (1.0 + norm(H[..., :3, 3])) ** 2
    assert_scaled_close(lhs, rhs, scale, RTOL)


@MANY
@given(xy=arrays(np.float64, st.sampled_from([(2, 6), (2, 5, 6), (2, 2, 3, 6)]),
                 elements=TRANSLATION))
def test_ad6_is_the_matrix_commutator_and_antisymmetric(xy):
    x, y = xy[0], xy[1]
    X, Y = lie.hat6(x), lie.hat6(y)
    scale = np.maximum(1.0, norm(x) * norm(y))
    assert_scaled_close(mv(lie.ad6(x), y), lie.vee6(X @ Y - Y @ X), scale, 8 * EPS)
    assert_scaled_close(mv(lie.ad6(x), y), -mv(lie.ad6(y), x), scale, 8 * EPS)


@MANY
@given(xyz=arrays(np.float64, st.sampled_from([(3, 6), (3, 5, 6)]), elements=TRANSLATION))
def test_ad6_satisfies_the_jacobi_identity(xyz):
    x, y, z = xyz

    def br(a, b):
        return mv(lie.ad6(a), b)

    total = br(x, br(y, z)) + br(y, br(z, x)) + br(z, br(x, y))
    scale = np.maximum(1.0, norm(x) * norm(y) * norm(z))
    assert_scaled_close(total, np.zeros_like(total), scale, 32 * EPS)
    # ad is a Lie-algebra homomorphism: ad([x, y]) = [ad x, ad y]
    lhs = lie.ad6(br(x, y))
    rhs = lie.ad6(x) @ lie.ad6(y) - lie.ad6(y) @ lie.ad6(x)
    assert_scaled_close(lhs, rhs, scale / np.maximum(1.0, norm(z)), 32 * EPS)


# =============================================================================================
# 6. the vectorial map of Eq. (56)
# =============================================================================================
@MANY
@given(H=frames())
def test_vect_se3_is_position_and_axial_vector_of_antisymmetric_part_eq56(H):
    R, x = H[..., :3, :3], H[..., :3, 3]
    A = 0.5 * (R - np.swapaxes(R, -1, -2))
    v = lie.vect_se3(H)
    np.testing.assert_array_equal(v[..., :3], x)
    # hat3(phi) = (R - R^T)/2
    np.testing.assert_allclose(lie.hat3(v[..., 3:]), A, rtol=0, atol=2 * EPS)


def test_vect_se3_of_identity_is_zero():
    np.testing.assert_array_equal(lie.vect_se3(I4), np.zeros(6))
    np.testing.assert_array_equal(lie.vect_se3(np.broadcast_to(I4, (2, 3, 4, 4))),
                                  np.zeros((2, 3, 6)))


@MANY
@given(n=twists(ANGLES_UP_TO_PI, translation=finite(-2.0, 2.0)))
def test_vect_se3_of_small_exponential_is_its_argument_to_first_order(n):
    U, W = n[..., :3], n[..., 3:]
    nn = norm(n)
    for eps in (1e-1, 1e-2, 1e-3):
        err = norm(lie.vect_se3(lie.exp_se3(eps * n)) - eps * n)
        # translation error <= eps^2 |W||U|/2 + eps^3 |W|^2|U|/6, rotation <= eps^3 |W|^3/6
        assert np.all(err <= eps**2 * nn**2 * (0.5 + eps * nn / 3) + 1e-15), (eps, err)
    # The second-order term is exactly (Omega x U / 2, 0):
    eps = 1e-4
    ratio = (lie.vect_se3(lie.exp_se3(eps * n)) - eps * n) / eps**2
    want = np.concatenate([0.5 * np.cross(W, U), np.zeros_like(W)], axis=-1)
    # third-order remainder <= eps |n|^3 / 3; rounding <= ~1e-16 eps |n| / eps^2 ~ 1e-12 |n|
    assert np.all(norm(ratio - want) <= eps * nn**3 / 3 + 1e-10)


# =============================================================================================
# 8. accuracy claims: exact zero, high-precision closed forms, no NaN
# =============================================================================================
def test_zero_rotation_gives_exact_identities_without_nan():
    z3, z6 = np.zeros(3), np.zeros(6)
    np.testing.assert_array_equal(lie.exp_so3(z3), I3)
    np.testing.assert_array_equal(lie.tangent_so3(z3), I3)
    np.testing.assert_array_equal(lie.tangent_so3_inv(z3), I3)
    np.testing.assert_array_equal(lie.exp_se3(z6), I4)
    np.testing.assert_array_equal(lie.tangent_se3(z6), I6)
    np.testing.assert_array_equal(lie.tangent_se3_inv(z6), I6)
    np.testing.assert_array_equal(lie.log_so3(I3), z3)
    np.testing.assert_array_equal(lie.log_se3(I4), z6)
    np.testing.assert_array_equal(lie.box_minus(I4, I4), z6)
    # pure translation: exp is exact, log recovers the translation exactly
    u = np.array([0.3, -1.7, 2.5])
    H = lie.exp_se3(np.r_[u, z3])
    np.testing.assert_array_equal(H, frame(I3, u))
    np.testing.assert_array_equal(lie.log_se3(H), np.r_[u, z3])


@pytest.mark.parametrize("t", [1e-100, 1e-160, 1e-200, 1e-300])
def test_round_trips_stay_relatively_accurate_when_the_angle_squared_underflows(t):
    # |w|^2 underflows to 0 below ~1e-154: the module must fall back to the t -> 0 limits
    # without losing the (first-order exact) rotation vector.
    w = t * np.array([0.6, -0.8, 0.0])
    n = np.r_[3.0 * w, w]
    np.testing.assert_allclose(lie.log_so3(lie.exp_so3(w)) / t, w / t, rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(lie.log_se3(lie.exp_se3(n)) / t, n / t, rtol=0, atol=8 * EPS)
    np.testing.assert_allclose(lie.vee3(lie.exp_so3(w)) / t, w / t, rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(lie.vee3(lie.tangent_so3(w)) / t, -w / (2 * t), rtol=0,
                               atol=4 * EPS)
    for M in (lie.tangent_se3(n), lie.tangent_se3_inv(n)):
        assert np.all(np.isfinite(M))


def _mp_dps(t: float) -> int:
    # 40 significant digits beyond the worst cancellation: the Eq. (22) coefficient
    # (b/2 - 3(1-a)/t^2)/t^2 loses ~4 log10(1/t) digits at small t.
    return 40 + (max(0, math.ceil(-4 * math.log10(t))) if t > 0 else 0)


def _mp_to_np(M) -> np.ndarray:
    return np.array([[float(M[i, j]) for j in range(M.cols)] for i in range(M.rows)])


def _mp_hat3(v):
    return mp.matrix([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def mp_closed_forms(u: np.ndarray, w: np.ndarray) -> dict[str, np.ndarray]:
    """Eqs. (17), (18), (19), (22) and the closed-form inverse of Eq. (19), in mpmath.

    The float inputs are converted exactly; the angle is the exact norm of the float vector.
    """
    t_float = float(np.linalg.norm(w))
    with mp.workdps(_mp_dps(t_float)):
        wm = [mp.mpf(float(c)) for c in w]
        um = [mp.mpf(float(c)) for c in u]
        t2 = sum(c * c for c in wm)
        t = mp.sqrt(t2)
        Wt, Ut = _mp_hat3(wm), _mp_hat3(um)
        Wt2 = Wt * Wt
        I = mp.eye(3)
        if t == 0:  # every coefficient multiplies a power of hat(n_Omega) = 0
            a = b = mp.mpf(1)
            c1 = cw = f = mp.mpf(0)
            coupl = mp.mpf(0)
        else:
            a = mp.sin(t) / t
            b = 2 * (1 - mp.cos(t)) / t2
            c1 = (1 - a) / t2
            cw = b / 2 - 3 * (1 - a) / t2
            f = (1 - (t / 2) * mp.cot(t / 2)) / t2
            coupl = sum(p * q for p, q in zip(wm, um, strict=True)) / t2
        R = I + a * Wt + (b / 2) * Wt2  # Eq. (18)
        T = I - (b / 2) * Wt + c1 * Wt2  # Eq. (19)
        Tinv = I + Wt / 2 + f * Wt2  # inverse of Eq. (19)
        TUO = -(b / 2) * Ut + c1 * (Ut * Wt + Wt * Ut) + coupl * ((b - a) * Wt + cw * Wt2)  # (22)
        x = T.T * mp.matrix(um)  # Eq. (17)
        # axial vectors of the antisymmetric parts of Eqs. (18), (19) (hat(w)^2 is symmetric)
        Rax = a * mp.matrix(wm)
        Tax = -(b / 2) * mp.matrix(wm)
        out = {
            k: _mp_to_np(v)
            for k, v in dict(R=R, T=T, Tinv=Tinv, TUO=TUO, x=x, Rax=Rax, Tax=Tax).items()
        }
    for k in ("x", "Rax", "Tax"):
        out[k] = out[k][:, 0]
    return out


ACCURACY_ANGLES = [0.0, 1e-9, 1e-6, 1e-3, 0.5, 0.999, np.nextafter(1.0, 0.0), 1.0, 1.001, 2.0,
                   3.0, PI - 1e-9, PI, 4.0, 6.0]
_rng = np.random.default_rng(20240917)
_AXES = [np.array([0.0, 0.0, 1.0])] + [v / np.linalg.norm(v) for v in _rng.normal(size=(2, 3))]
_U = np.array([0.7, -1.3, 2.1])


@pytest.mark.parametrize("axis_id", range(len(_AXES)))
@pytest.mark.parametrize("angle", ACCURACY_ANGLES)
def test_matches_high_precision_closed_forms_eqs_17_to_22(angle, axis_id):
    w = angle * _AXES[axis_id]
    u = _U + 0.5 * _AXES[axis_id]  # generic, with n_Omega . n_U != 0
    ref = mp_closed_forms(u, w)
    n = np.r_[u, w]

    def check(got, want, what):
        scale = max(1.0, float(np.linalg.norm(want)))
        assert np.all(np.isfinite(got)), what
        np.testing.assert_allclose(got, want, rtol=0, atol=REF_TOL * scale, err_msg=what)

    check(lie.exp_so3(w), ref["R"], "exp_so3, Eq. (18)")
    check(lie.tangent_so3(w), ref["T"], "tangent_so3, Eq. (19)")
    check(lie.tangent_so3_inv(w), ref["Tinv"], "tangent_so3_inv")
    H = lie.exp_se3(n)
    check(H[:3, :3], ref["R"], "exp_se3 rotation, Eq. (17)")
    check(H[:3, 3], ref["x"], "exp_se3 translation, Eq. (17)")
    T = lie.tangent_se3(n)
    check(T[:3, :3], ref["T"], "tangent_se3 diagonal block, Eq. (21)")
    # the coupling block on its own scale (it does not contain the identity)
    check(T[:3, 3:], ref["TUO"], "tangent_se3 coupling block, Eq. (22)")
    Ti = lie.tangent_se3_inv(n)
    Tso_inv = ref["Tinv"]
    check(Ti[:3, 3:], -Tso_inv @ ref["TUO"] @ Tso_inv, "tangent_se3_inv coupling block")
    # Relative accuracy of the parts that vanish at the identity: the antisymmetric parts are
    # a hat(w) and -(b/2) hat(w), accurate relative to |w| even at tiny angles.
    t = float(np.linalg.norm(w))
    np.testing.assert_allclose(lie.vee3(lie.exp_so3(w)), ref["Rax"], rtol=0, atol=8 * EPS * t)
    np.testing.assert_allclose(lie.vee3(lie.tangent_so3(w)), ref["Tax"], rtol=0,
                               atol=8 * EPS * t)


def _mp_coefficients(t: float) -> dict[str, float]:
    with mp.workdps(_mp_dps(t)):
        tm = mp.mpf(t)
        a = mp.sin(tm) / tm
        b = 2 * (1 - mp.cos(tm)) / tm**2
        return {
            "a": float(a),
            "h": float(b / 2),
            "c": float((1 - a) / tm**2),
            "d": float((b - a) / tm**2),
            "e": float((b / 2 - 3 * (1 - a) / tm**2) / tm**2),
            "f": float((1 - (tm / 2) * mp.cot(tm / 2)) / tm**2),
        }


_COEF_ANGLES = np.unique(np.concatenate([
    [1e-154, 1e-20, 1e-9, 1e-6, 1e-3, 0.1],
    np.linspace(0.9, 1.1, 41),
    [np.nextafter(1.0, 0.0), np.nextafter(1.0, 2.0)],
    np.linspace(0.2, 6.2, 31),
    [PI - 1e-9, PI],
]))


def test_coefficient_functions_are_relatively_accurate_for_all_angles():
    """White-box check of the module's accuracy claim on its coefficient functions.

    a = sin t/t, h = (1-cos t)/t^2, c = (1-a)/t^2, d = (b-a)/t^2, e = Eq. (22)'s
    (b/2 - 3(1-a)/t^2)/t^2 and f = (1 - (t/2)cot(t/2))/t^2, relative to a 40-digit reference.
    None of them vanishes on (0, 2 pi), so relative error is meaningful everywhere.
    """
    worst = {}
    for t in _COEF_ANGLES:
        got = lie._coeffs(np.array([t, 0.0, 0.0]), "ahcdef")
        ref = _mp_coefficients(float(t))
        for k, r in ref.items():
            rel = abs(float(got[k]) - r) / abs(r)
            if rel > worst.get(k, (0.0, 0.0))[0]:
                worst[k] = (rel, float(t))
    bad = {k: v for k, v in worst.items() if v[0] > REF_TOL}
    assert not bad, f"relative error above {REF_TOL}: {bad}"


ALL_ANGLES_0_PI = st.one_of(st.just(0.0), st.just(PI), TINY, finite(0.0, PI), NEAR_PI)


@MANY
@given(n=twists(ALL_ANGLES_0_PI))
def test_no_nan_or_inf_for_any_angle_in_closed_interval_0_pi(n):
    w = n[..., 3:]
    R = lie.exp_so3(w)
    H = lie.exp_se3(n)
    outs = [R, lie.log_so3(R), lie.tangent_so3(w), lie.tangent_so3_inv(w), H, lie.log_se3(H),
            lie.tangent_se3(n), lie.tangent_se3_inv(n), lie.adjoint(H), lie.adjoint_inv(H),
            lie.vect_se3(H), lie.box_minus(H, lie.inverse(H)), *lie.exp_tangent_se3(n)]
    for o in outs:
        assert np.all(np.isfinite(o))


# =============================================================================================
# 9. batch behaviour
# =============================================================================================
@st.composite
def batch_inputs(draw):
    shape = draw(st.sampled_from([(5,), (2, 3), (1,)]))
    # log inputs stay 1e-6 away from pi, where the sign of the logarithm is arbitrary
    angles = st.one_of(ZERO, TINY, MODERATE, finite(3.0, PI - 1e-6))
    n = draw(twists(angles, shape))
    n2 = draw(twists(angles, shape))
    w = n[..., 3:]
    H = lie.exp_se3(n)
    H2 = lie.exp_se3(n2)
    M = draw(arrays(np.float64, shape + (4, 4), elements=TRANSLATION))
    return dict(shape=shape, n=n, w=w, u=n[..., :3], R=lie.exp_so3(w), H=H, H2=H2,
                H1=H2 @ lie.exp_se3(n), M3=M[..., :3, :3], M4=M)


BATCH_CASES = {
    "hat3": lambda d: (d["w"],),
    "vee3": lambda d: (d["M3"],),
    "hat6": lambda d: (d["n"],),
    "vee6": lambda d: (d["M4"],),
    "ad6": lambda d: (d["n"],),
    "exp_so3": lambda d: (d["w"],),
    "log_so3": lambda d: (d["R"],),
    "tangent_so3": lambda d: (d["w"],),
    "tangent_so3_inv": lambda d: (d["w"],),
    "exp_se3": lambda d: (d["n"],),
    "log_se3": lambda d: (d["H"],),
    "tangent_se3": lambda d: (d["n"],),
    "tangent_se3_inv": lambda d: (d["n"],),
    "exp_tangent_se3": lambda d: (d["n"],),
    "adjoint": lambda d: (d["H"],),
    "adjoint_inv": lambda d: (d["H"],),
    "vect_se3": lambda d: (d["H"],),
    "make_frame": lambda d: (d["R"], d["u"]),
    "compose": lambda d: (d["H"], d["H2"]),
    "inverse": lambda d: (d["H"],),
    "box_plus": lambda d: (d["H2"], d["n"]),
    "box_minus": lambda d: (d["H1"], d["H2"]),
}


# functions returning several arrays (see test_exp_tangent_se3_returns_exp_se3_and_tangent_se3)
MULTI_OUTPUT = {"exp_tangent_se3"}


def test_batch_cases_cover_every_public_function():
    public = {name for name in lie.__all__ if callable(getattr(lie, name))}
    assert public == set(BATCH_CASES) | MULTI_OUTPUT


@pytest.mark.parametrize("name", sorted(BATCH_CASES))
@BATCH
@given(d=batch_inputs())
def test_batched_call_equals_stack_of_single_calls(name, d):
    f = getattr(lie, name)
    args = BATCH_CASES[name](d)
    shape = d["shape"]

    def as_tuple(out):  # exp_tangent_se3 returns a pair
        return out if isinstance(out, tuple) else (out,)

    batched = as_tuple(f(*args))
    singles = [as_tuple(f(*(a[idx] for a in args))) for idx in np.ndindex(*shape)]
    assert all(len(o) == len(batched) for o in singles)
    for k, out in enumerate(batched):
        stacked = np.stack([o[k] for o in singles]).reshape(shape + singles[0][k].shape)
        assert out.shape == stacked.shape
        scale = max(1.0, float(np.max(np.abs(stacked))))
        np.testing.assert_allclose(out, stacked, rtol=0, atol=4 * EPS * scale)
