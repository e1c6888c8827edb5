"""Relative equilibria (steady spin) and Campbell diagrams (sd.relative_equilibrium,
sd.campbell; issue 32, items 1 and 3).

References are closed forms and an independent solver: a bead on a spring along a rotating
rail (radius ``k r0 / (k - m W^2)``, radial frequency ``sqrt(k/m - W^2)``, growth rate
``sqrt(W^2 - k/m)`` beyond), and the flapwise frequencies of a rotating uniform cantilever from
the Euler-Bernoulli equation with the centrifugal tension, ``EI w'''' - (T w')' = m omega^2 w``,
``T = m W^2 (L^2 - x^2) / 2``, solved by Chebyshev collocation with scipy here (60 points:
converged to 1e-10), itself checked against the values tabulated by Wright, Smith, Thresher and
Wang, J. Appl. Mech. 49 (1982) 197-202 (Table 1: 3.5160, 4.7973, 13.1702 for the speed
parameters 0, 3, 12).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg as sla

import se3dyn as sd
from se3dyn.errors import ModelError

K_R, M_B, R0 = 50.0, 2.0, 0.5


def _bead(W, drive=True):
    """A hub turning about z (driven at W), a bead of mass m on a radial rail with a spring k
    (free length: the bead at R0)."""
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("hub", (0, 0, 0), mass=1.0, inertia=(0.1, 0.1, 0.1))
    mb.node("bead", (R0, 0, 0), mass=M_B, inertia=(0.01, 0.01, 0.01))
    mb.joint("spin", "hinge", "g", "hub", axis=(0, 0, 1))
    mb.joint("rail", "prismatic", "hub", "bead", axis=(1, 0, 0), stiffness=K_R, at=(R0, 0, 0))
    if drive:
        mb.drive("motor", "spin", velocity=W)
    return mb.build()


@pytest.mark.parametrize("W", [1.0, 3.0, 4.5])
def test_a_bead_on_a_spinning_rail_sits_and_oscillates_where_the_closed_form_says(W):
    st = sd.relative_equilibrium(_bead(W), "spin", W)
    r = st.H[2, 0, 3]
    assert abs(r - K_R * R0 / (K_R - M_B * W * W)) < 1e-12
    # the state is a steady spin: material velocities of a rigid rotation, no acceleration
    assert np.allclose(st.v[6:9], [0, r * W, 0]) and not np.any(st.vd)
    md = sd.linearize(_bead(W), at=st).modes()
    assert len(md) == 1 and abs(md.omega[0] / math.sqrt(K_R / M_B - W * W) - 1) < 1e-10


def test_campbell_of_the_bead_tracks_its_mode_and_finds_where_it_turns_unstable():
    Wc = math.sqrt(K_R / M_B)
    speeds = np.array([0.0, 2.0, 4.0, 4.9, 5.1, 6.0])
    cb = sd.campbell(_bead(0.0), "spin", speeds, k=1)
    below = speeds < Wc
    # (relative to k/m: near the critical speed omega^2 = k/m - W^2 loses digits by cancellation)
    np.testing.assert_allclose(cb.omega[below, 0] ** 2, K_R / M_B - speeds[below] ** 2,
                               rtol=0, atol=1e-8 * K_R / M_B)
    assert np.all(cb.growth[below] <= 1e-9)
    np.testing.assert_allclose(cb.growth[~below] ** 2, speeds[~below] ** 2 - K_R / M_B,
                               rtol=0, atol=1e-8 * K_R / M_B)


def _cheb(N):
    x = np.cos(np.pi * np.arange(N + 1) / N)
    c = np.hstack([2, np.ones(N - 1), 2]) * (-1) ** np.arange(N + 1)
    dX = x[:, None] - x[None, :]
    D = np.outer(c, 1 / c) / (dX + np.eye(N + 1))
    return D - np.diag(D.sum(axis=1)), x


def _flap_reference(lam, modes=2, N=60):
    """Nondimensional flapwise frequencies omega sqrt(m L^4 / EI) of a rotating uniform
    cantilever at the speed parameter lam = W sqrt(m L^4 / EI) (module docstring)."""
    D, x = _cheb(N)
    xi, D = (x + 1) / 2, 2 * D  # on [0, 1]: xi = 1 at index 0, xi = 0 at index N
    D2 = D @ D
    A = D2 @ D2 - (np.diag(lam ** 2 * (1 - xi ** 2) / 2) @ D2 - np.diag(lam ** 2 * xi) @ D)
    B = np.eye(N + 1)
    for row, bc in ((N, np.eye(N + 1)[N]), (N - 1, D[N]), (0, D2[0]), (1, (D2 @ D)[0])):
        A[row], B[row] = bc, 0.0  # clamped root, free tip
    w = sla.eig(A, B, right=False)
    w = np.sort(w[np.isfinite(w) & (w.real > 0)].real)
    return np.sqrt(w[:modes])


def test_the_reference_solver_reproduces_the_tabulated_values():
    for lam, tab in ((0.0, 3.5160), (3.0, 4.7973), (12.0, 13.1702)):
        assert abs(_flap_reference(lam)[0] - tab) < 6e-5


def _blade(n):
    """A uniform blade (L = m = EI = 1) on a hub turning about z: its flap (out of the plane of
    rotation) is the soft bending, lag, axial and torsion are stiff."""
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("hub", (0, 0, 0), mass=1.0, inertia=(1, 1, 1))
    mb.node("tip", (1.0, 0, 0))
    mb.joint("spin", "hinge", "g", "hub", axis=(0, 0, 1))
    mb.beam("b", "hub", "tip", elements=n, EA=1e6, GA=1e6, GJ=1e6, EI=(1.0, 1e4),
            mass_per_length=1.0, rotary_inertia=(1e-9, 1e-9, 1e-9))
    return mb.build()


def test_rotating_cantilever_flap_frequencies_against_the_centrifugally_stiffened_beam():
    lams = np.array([0.0, 6.0, 12.0])
    cb = {n: sd.campbell(_blade(n), "spin", lams, k=2) for n in (12, 24)}
    rich = (4 * cb[24].omega - cb[12].omega) / 3  # (lumped masses: order 2 in the mesh)
    ref = np.array([_flap_reference(lam) for lam in lams])
    assert np.abs(rich / ref - 1).max() < 1e-4, rich / ref
    assert np.all(cb[24].mac > 0.99)  # the flap modes tracked from speed to speed
    # undamped and stable: the real parts are round-off (of the stiff axial and torsion modes'
    # 1e9 rad/s)
    assert np.all(np.abs(cb[24].growth) <= 1e-6 * cb[24].omega.max())


def test_bad_spin_arguments_are_refused():
    with pytest.raises(ModelError, match="field 'joint'.*node A is fixed"):
        sd.relative_equilibrium(_bead(1.0), "rail", 1.0)
    with pytest.raises(ModelError, match="field 'speed'"):
        sd.relative_equilibrium(_bead(1.0), "spin", float("nan"))
    with pytest.raises(ModelError, match="field 'speeds'"):
        sd.campbell(_bead(0.0), "spin", [2.0, 1.0])
