"""The compiled path of JointSpace on trees (C++ recursive Newton-Euler and composite-rigid-body
algorithm, se3dyn/_core/joint_tree.hpp) against the general path (the engine's residual and
mass matrix projected by the minimal-coordinate map, itself checked against Pinocchio in
tests/test_jointspace.py) on random branching trees: hinges, sliders, cylindrical and screw
joints, joints at offset points, joints whose node A is the child, a fixed node away from the
origin, a floating base, centres of mass off the nodes, armatures, joint springs and dampers;
and the general path kept where the compiled one does not apply."""

from __future__ import annotations

import numpy as np
import pytest

import se3dyn as sd
from _mechanisms import parallelogram_fourbar

TYPES = ("hinge", "prismatic", "cylindrical", "screw")


def _rot(rng) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def _unit(rng) -> np.ndarray:
    x = rng.normal(size=3)
    return x / np.linalg.norm(x)


def random_tree(seed: int, n: int, floating: bool) -> sd.Model:
    """A random tree of n bodies on the ground, on a fixed post, or on a floating base."""
    rng = np.random.default_rng(seed)
    mb = sd.ModelBuilder(gravity=tuple(rng.normal(size=3) * 5.0))
    mb.node("ground", fixed=True)
    mb.node("post", position=rng.uniform(-1, 1, 3), orientation=_rot(rng), fixed=True)
    names = ["ground", "post"]
    if floating:
        mb.node("base", position=rng.uniform(-1, 1, 3), orientation=_rot(rng), mass=2.0,
                inertia=(0.1, 0.12, 0.15), com=None)
        names = ["base"]
    for i in range(n):
        parent = names[int(rng.integers(len(names)))]
        x = rng.uniform(-1, 1, 3)
        R = _rot(rng)
        mb.node(f"L{i}", position=x, orientation=R, mass=rng.uniform(0.5, 2.0),
                inertia=R @ np.diag(rng.uniform(0.04, 0.07, 3)) @ R.T,
                com=x + R @ rng.uniform(-0.2, 0.2, 3))
        typ = TYPES[int(rng.integers(len(TYPES)))]
        extra = dict(pitch=0.3) if typ == "screw" else {}
        k = 2 if typ == "cylindrical" else 1
        if rng.uniform() < 0.7:
            extra.update(armature=rng.uniform(0.0, 0.2, k), initial=rng.uniform(-1, 1, k))
        if rng.uniform() < 0.5:
            extra.update(stiffness=rng.uniform(0, 5, k), damping=rng.uniform(0, 2, k),
                         reference=rng.uniform(-1, 1, k))
        a, b = (parent, f"L{i}") if parent == "base" or rng.uniform() < 0.6 else (
            f"L{i}", parent)
        mb.joint(f"j{i}", typ, a, b, axis=_unit(rng), at=rng.uniform(-1, 1, 3), **extra)
        names.append(f"L{i}")
    return mb.build()


def random_q(js: sd.JointSpace, rng, N: int) -> np.ndarray:
    """N configurations about the model's (a root's quaternion perturbed too: not of unit
    length, both paths normalise it)."""
    return js.neutral() + rng.uniform(-0.8, 0.8, (N, js.nq))


def both(model) -> tuple[sd.JointSpace, sd.JointSpace]:
    fast, slow = sd.JointSpace(model), sd.JointSpace(model, compiled=False)
    assert fast.compiled, fast.fallback_reason
    assert not slow.compiled
    return fast, slow


def close(x, ref, tol=1e-12) -> None:
    scale = max(float(np.abs(ref).max()), 1.0)
    assert float(np.abs(x - ref).max()) <= tol * scale


@pytest.mark.parametrize("seed,floating", [(1, False), (2, False), (3, True), (4, True),
                                           (5, True)])
def test_compiled_equals_general_path_on_random_trees(seed, floating):
    """Inverse dynamics, bias, gravity, mass matrix and forward dynamics: the same numbers by
    both paths at random states (the free base's quaternion not normalised: both
    normalise)."""
    fast, slow = both(random_tree(seed, 6, floating))
    assert fast.nq == fast.nv + (1 if floating else 0)
    rng = np.random.default_rng(seed)
    Q = random_q(fast, rng, 4)
    V, A = rng.normal(size=(2, 4, fast.nv))
    close(fast.inverse_dynamics(Q, V, A), slow.inverse_dynamics(Q, V, A))
    close(fast.bias(Q, V), slow.bias(Q, V))
    close(fast.gravity(Q), slow.gravity(Q))
    M = fast.mass_matrix(Q)
    close(M, slow.mass_matrix(Q))
    assert np.array_equal(M, np.swapaxes(M, 1, 2))
    close(fast.forward_dynamics(Q, V, A), slow.forward_dynamics(Q, V, A), 1e-10)
    close(fast.inverse_dynamics(Q[0], V[0], A[0]), slow.inverse_dynamics(Q[0], V[0], A[0]))


def test_batches_give_the_bits_of_single_calls():
    """Same inputs, same bits: a batch row by row equals the single calls exactly."""
    fast, _ = both(random_tree(3, 5, True))
    rng = np.random.default_rng(0)
    Q = random_q(fast, rng, 5)
    V, A = rng.normal(size=(2, 5, fast.nv))
    tau, M = fast.inverse_dynamics(Q, V, A), fast.mass_matrix(Q)
    for r in range(5):
        assert np.array_equal(tau[r], fast.inverse_dynamics(Q[r], V[r], A[r]))
        assert np.array_equal(M[r], fast.mass_matrix(Q[r]))


def test_bad_input_still_named():
    fast, _ = both(random_tree(1, 3, False))
    with pytest.raises(sd.ModelError, match="q"):
        fast.inverse_dynamics(np.full(fast.nq, np.nan), np.zeros(fast.nv), np.zeros(fast.nv))
    with pytest.raises(sd.ModelError, match="v"):
        fast.inverse_dynamics(np.zeros(fast.nq), np.zeros(fast.nv + 1), np.zeros(fast.nv))


def test_general_path_kept_where_the_compiled_one_does_not_apply():
    """A closed loop and a PD law: the general path, with the reason."""
    js = sd.JointSpace(parallelogram_fourbar(9.81))
    assert not js.compiled and js.fallback_reason == "closed loops"
    mb = sd.ModelBuilder(gravity=(0, 0, -9.81))
    mb.node("ground", fixed=True)
    mb.node("arm", position=(0.5, 0, 0), mass=1.0, inertia=(0.01, 0.01, 0.01))
    mb.joint("j", "hinge", "ground", "arm", axis=(0, 1, 0), at=(0, 0, 0),
             control=sd.PD(kp=10.0, kd=1.0))
    js = sd.JointSpace(mb.build())
    assert not js.compiled and "control" in js.fallback_reason
