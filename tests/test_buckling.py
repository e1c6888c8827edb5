"""Buckling (sd.buckling) and statics of stiff structures up to their critical load (issue 32,
item 4).

References are closed forms: Euler's cantilever column ``P = pi^2 EI / (4 L^2)`` with the
shape ``1 - cos(pi z / 2 L)``; Prandtl's lateral-torsional buckling of a narrow cantilever
under a tip load at the centroid, ``P = gamma sqrt(EI_z GJ) / L^2`` with ``gamma / 2`` the first
zero of the Bessel function ``J_(-1/4)`` (Timoshenko & Gere, Theory of Elastic Stability,
2nd ed., Sec. 6.3: gamma = 4.013), computed here with scipy; the straight column's axial
shortening ``P L / EA``; a chain of rotational springs under a tip load (small deflections:
rotations ``F (L - x_i) / k``). Discretisation errors are removed by Richardson
extrapolation of two meshes (the beam element converges at order 2).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.special import jv

import se3dyn as sd
from se3dyn.errors import ModelError, SimulationError


def _column(frac=1.0, n=32, EI=1.0, ratio=1e7, L=1.0):
    """A cantilever column along z (steel-like EA / EI = 1e7), a dead load ``frac`` times
    Euler's critical load pressing its tip."""
    mb = sd.ModelBuilder()
    mb.node("base", (0, 0, 0), fixed=True)
    mb.node("tip", (0, 0, L))
    EA = ratio * EI
    mb.beam("col", "base", "tip", elements=n, EA=EA, GA=EA / 2.6 * 0.85, GJ=EI / 1.3, EI=EI)
    mb.load("P", "tip", force=(0, 0, -frac * math.pi ** 2 * EI / (4 * L * L)))
    return mb.build()


def _richardson(f, n):
    """Order-2 extrapolation of f(n), f(2 n)."""
    a, b = f(n), f(2 * n)
    return (4.0 * b - a) / 3.0


def test_euler_column_buckles_at_its_closed_form_load_with_its_shape():
    lam = _richardson(lambda n: sd.buckling(_column(n=n)).load_factors[0], 32)
    assert abs(lam - 1.0) < 5e-6, lam
    b = sd.buckling(_column(n=32), k=3)
    # two equal bending modes (the section is round), then the next at about 9 (odd harmonic)
    assert abs(b.load_factors[1] / b.load_factors[0] - 1.0) < 1e-6
    assert abs(b.load_factors[2] / b.load_factors[0] - 9.0) < 0.02
    # the buckled shape: lateral displacement 1 - cos(pi z / 2 L), relative to the tip's
    names = ["base"] + [f"col/{i}" for i in range(1, 32)] + ["tip"]
    z = np.linspace(0.0, 1.0, 33)
    u = np.array([b.node_shape(0, m)[:2] for m in names])
    d = u[:, np.argmax(np.abs(u[-1]))]
    np.testing.assert_allclose(d / d[-1], 1.0 - np.cos(0.5 * math.pi * z), atol=1e-3)


def test_prandtl_lateral_torsional_buckling_of_a_tip_loaded_cantilever():
    gamma = 2.0 * brentq(lambda x: jv(-0.25, x), 1.0, 3.0)
    assert abs(gamma - 4.013) < 5e-4  # (Timoshenko & Gere's value)

    def factor(n):
        mb = sd.ModelBuilder()
        mb.node("base", (0, 0, 0), fixed=True)
        mb.node("tip", (1.0, 0, 0))
        # narrow section: EI about y (the load's plane) 1e6 times EI about z
        mb.beam("b", "base", "tip", elements=n, EA=1e7, GA=1e7, GJ=1.0, EI=(1e6, 1.0))
        mb.load("P", "tip", force=(0, 0, -1.0))
        return sd.buckling(mb.build()).load_factors[0]
    assert abs(_richardson(factor, 32) / gamma - 1.0) < 5e-5


def test_nonlinear_path_finds_the_same_critical_load_on_a_perfect_column():
    lin = sd.buckling(_column(n=16)).load_factors[0]
    nl = sd.buckling(_column(n=16), method="nonlinear")
    # the straight column only shortens before it buckles (P / EA = 2.5e-7 of its length)
    assert abs(nl.load_factors[0] / lin - 1.0) < 2e-6
    assert nl.method == "nonlinear" and nl.shapes.shape[1] == 1


@pytest.mark.parametrize("frac", [0.5, 0.9, 0.99])
def test_statics_of_a_stiff_column_reaches_its_critical_load(frac):
    # EA / EI = 1e7, 32 elements: the straight column, shortened by P L / EA, stable
    res = sd.static_equilibrium(_column(frac))
    P = frac * math.pi ** 2 / 4
    tip = res.node_position("tip")
    assert abs((1.0 - tip[2]) - P / 1e7) < 1e-12 and np.abs(tip[:2]).max() < 1e-12
    assert res.stable and res.min_stiffness > 0
    assert not sd.static_equilibrium(_column(1.01)).stable


def _spring_chain(n=16, kt=1e12, kr=1e5, F=1e2, l=0.1):
    """n six-axis spring joints (general joints, stiffness on all six coordinates) in a
    cantilever chain along x, a tip load along -y."""
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    prev = "g"
    for i in range(n):
        mb.node(f"b{i}", (l * (i + 1), 0, 0), mass=1.0, inertia=(1e-3, 1e-3, 1e-3))
        mb.joint(f"j{i}", "general", prev, f"b{i}", A=np.eye(6), at=(l * i, 0, 0),
                 stiffness=(kt, kt, kt, kr, kr, kr))
        prev = f"b{i}"
    mb.load("F", prev, force=(0, -F, 0))
    return mb.build()


@pytest.mark.parametrize("n", [8, 16])
def test_statics_of_a_chain_of_stiff_six_axis_springs_converges_quadratically(n):
    # translation 1e12 beside rotation 1e5: the tip deflection of the small-deflection closed
    # form (rotations F (L - x_i) / kr), in a few Newton iterations
    res = sd.static_equilibrium(_spring_chain(n))
    L, l = 0.1 * n, 0.1
    arm = L - l * np.arange(n)
    closed = 1e2 * np.sum(arm ** 2) / 1e5 + n * 1e2 / 1e12
    tip = res.node_position(f"b{n - 1}")
    assert abs(-tip[1] / closed - 1.0) < 2e-3, (tip, closed)
    assert res.iterations.max() <= 6 and res.cuts == 0


def test_buckling_refuses_bad_arguments_and_loads_that_stiffen():
    with pytest.raises(ModelError, match="field 'method'"):
        sd.buckling(_column(n=4), method="arc")
    with pytest.raises(ModelError, match="field 'k'"):
        sd.buckling(_column(n=4), k=0)
    with pytest.raises(ModelError, match="field 'delta'"):
        sd.buckling(_column(n=4), delta=0.0)
    with pytest.raises(ModelError, match="field 'load_factor'"):
        sd.static_equilibrium(_column(n=4), load_factor=float("nan"))
    # gravity only stiffens a hanging pendulum: K_0 = 0, K_g > 0, no positive factor
    mb = sd.ModelBuilder(gravity=(0, 0, -9.81))
    mb.node("g", fixed=True)
    mb.node("bob", (0, 0, -1), mass=1.0, inertia=(0.1, 0.1, 0.1))
    mb.joint("pin", "hinge", "g", "bob", axis=(1, 0, 0), at=(0, 0, 0))
    with pytest.raises(SimulationError, match="no positive critical load factor"):
        sd.buckling(mb.build())
