"""Bad input gives a clear :class:`se3dyn.ModelError` naming the item and the field.

Every case must raise ``sd.ModelError`` (a ``ValueError``), never a bare numpy/Python error,
and its message must name the offending item (node, joint, load, ``simulate``) and field, plus a
hint where one helps (did-you-mean for near-miss names and joint types).
"""

from __future__ import annotations

import numpy as np
import pytest

import se3dyn as sd


def _base() -> sd.ModelBuilder:
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81))
    mb.node("ground", position=(0.0, 0.0, 0.0), fixed=True)
    mb.node("body", position=(1.0, 0.0, 0.0), mass=1.0, inertia=(1.0, 1.0, 1.0))
    return mb


def _two_joints(mb, first, second):
    mb.joint(*first[0], **first[1])
    mb.joint(*second[0], **second[1])


ROT_X_Y = np.array([[0, 0, 0, 1, 0, 0], [0, 0, 0, 0, 1, 0]], dtype=float).T  # no [x, y] = z

# (id, action on a base builder, field, substrings the message must contain)
CASES = [
    ("unknown_node_b", lambda mb: mb.joint("pin", "hinge", "ground", "bdoy", axis=(0, 0, 1)),
     "node_b", ["joint 'pin'", "node_b", "'bdoy'", "did you mean 'body'"]),
    ("unknown_node_a", lambda mb: mb.joint("pin", "hinge", "grund", "body", axis=(0, 0, 1)),
     "node_a", ["joint 'pin'", "node_a", "'grund'", "did you mean 'ground'"]),
    ("joint_to_itself", lambda mb: mb.joint("pin", "hinge", "body", "body", axis=(0, 0, 1)),
     "node_b", ["joint 'pin'", "node_b", "itself"]),
    ("zero_axis", lambda mb: mb.joint("pin", "hinge", "ground", "body", axis=(0, 0, 0)),
     "axis", ["joint 'pin'", "axis", "zero length"]),
    ("non_unit_axis", lambda mb: mb.joint("pin", "prismatic", "ground", "body",
                                          axis=(0, 0, 2)),
     "axis", ["joint 'pin'", "axis", "unit"]),
    ("negative_mass", lambda mb: mb.node("rock", mass=-1.0, inertia=(1, 1, 1)),
     "mass", ["node 'rock'", "mass", "-1"]),
    ("indefinite_inertia", lambda mb: mb.node("rock", mass=1.0, inertia=(1.0, -1.0, 1.0)),
     "inertia", ["node 'rock'", "inertia", "positive-definite"]),
    ("singular_inertia_tensor", lambda mb: mb.node("rock", mass=1.0,
                                                   inertia=[[1, 1, 0], [1, 1, 0], [0, 0, 1]]),
     "inertia", ["node 'rock'", "inertia", "positive-definite"]),
    ("fixed_node_with_mass", lambda mb: mb.node("base", mass=2.0, inertia=(1, 1, 1),
                                                fixed=True),
     "mass", ["node 'base'", "mass", "fixed"]),
    ("general_not_a_subalgebra", lambda mb: mb.joint("gimbal", "general", "ground", "body",
                                                     A=ROT_X_Y),
     "A", ["joint 'gimbal'", "'A'", "subalgebra"]),
    ("duplicate_node", lambda mb: mb.node("body"), "name", ["node 'body'", "name", "unique"]),
    ("duplicate_joint", lambda mb: _two_joints(
        mb, (("pin", "hinge", "ground", "body"), dict(axis=(0, 0, 1))),
        (("pin", "prismatic", "ground", "body"), dict(axis=(1, 0, 0)))),
     "name", ["joint 'pin'", "name", "unique"]),
    ("duplicate_load", lambda mb: (mb.load("push", "body", force=(1, 0, 0)),
                                   mb.load("push", "body", force=(0, 1, 0))),
     "name", ["load 'push'", "name", "unique"]),
    ("unknown_joint_type", lambda mb: mb.joint("pin", "hinj", "ground", "body", axis=(0, 0, 1)),
     "type", ["joint 'pin'", "type", "'hinj'", "did you mean 'hinge'"]),
    ("stiffness_wrong_size", lambda mb: mb.joint("slide", "cylindrical", "ground", "body",
                                                 axis=(1, 0, 0), stiffness=(1.0, 2.0, 3.0)),
     "stiffness", ["joint 'slide'", "stiffness", "2 numbers"]),
    ("pd_on_spherical", lambda mb: mb.joint("ball", "spherical", "ground", "body",
                                            control=sd.PD(1.0, 0.1, 0.0)),
     "control", ["joint 'ball'", "control", "abelian"]),
    ("load_on_unknown_node", lambda mb: mb.load("push", "bodi", force=(1, 0, 0)),
     "node", ["load 'push'", "node", "'bodi'", "did you mean 'body'"]),
    ("nan_position", lambda mb: mb.node("rock", position=(0.0, np.nan, 0.0)),
     "position", ["node 'rock'", "position", "finite"]),
    ("negative_step", lambda mb: sd.simulate(_hinged(mb), 1.0, -1e-3),
     "step", ["simulate", "step", "positive"]),
    # a few more of the same kind
    ("missing_axis", lambda mb: mb.joint("pin", "hinge", "ground", "body"),
     "axis", ["joint 'pin'", "axis", "required"]),
    ("mass_without_inertia", lambda mb: mb.node("rock", mass=1.0),
     "inertia", ["node 'rock'", "inertia"]),
    ("reflection_orientation", lambda mb: mb.node("rock", orientation=np.diag([1.0, 1, -1])),
     "orientation", ["node 'rock'", "orientation", "rotation"]),
    ("general_rank_deficient", lambda mb: mb.joint(
        "gimbal", "general", "ground", "body", A=np.c_[ROT_X_Y[:, 0], 2 * ROT_X_Y[:, 0]]),
     "A", ["joint 'gimbal'", "'A'", "full rank"]),
    ("universal_axes_not_orthogonal", lambda mb: mb.joint(
        "cardan", "universal", "ground", "body", axes=[(1, 0, 0), (0.6, 0.8, 0)]),
     "axes", ["joint 'cardan'", "axes", "orthogonal"]),
    ("rigid_with_spring", lambda mb: mb.joint("weld", "rigid", "ground", "body", stiffness=1.0),
     "stiffness", ["joint 'weld'", "stiffness", "rigid"]),
    ("negative_damping", lambda mb: mb.joint("pin", "hinge", "ground", "body", axis=(0, 0, 1),
                                             damping=-0.1),
     "damping", ["joint 'pin'", "damping", "non-negative"]),
    ("load_force_wrong_size", lambda mb: mb.load("push", "body", force=(1.0, 0.0)),
     "force", ["load 'push'", "force", "3"]),
    ("actuator_raises_at_t0", lambda mb: mb.joint("pin", "hinge", "ground", "body",
                                                  axis=(0, 0, 1), torque=lambda t: 1 / 0),
     "torque", ["joint 'pin'", "torque", "ZeroDivisionError"]),
    ("screw_without_pitch", lambda mb: mb.joint("lead", "screw", "ground", "body",
                                                axis=(1, 0, 0)),
     "pitch", ["joint 'lead'", "pitch"]),
    ("rho_inf_out_of_range", lambda mb: sd.simulate(_hinged(mb), 1.0, 1e-3, rho_inf=1.5),
     "rho_inf", ["rho_inf", "[0, 1]"]),
    ("t_end_before_start", lambda mb: sd.simulate(_hinged(mb), -1.0, 1e-3),
     "t_end", ["simulate", "t_end"]),
]


def _hinged(mb):
    mb.joint("pin", "hinge", "ground", "body", axis=(0, 0, 1))
    return mb.build()


@pytest.mark.parametrize("action, field, expected", [c[1:] for c in CASES],
                         ids=[c[0] for c in CASES])
def test_bad_input_raises_model_error_naming_item_and_field(action, field, expected):
    mb = _base()
    with pytest.raises(sd.ModelError) as info:
        action(mb)
    err = info.value
    assert isinstance(err, ValueError)  # callers may catch ValueError
    assert err.field == field
    msg = str(err)
    for part in expected:
        assert part in msg, f"{part!r} not in {msg!r}"
    # a message written for people, not a leaked numpy/Python error
    for leak in ("Traceback", "LinAlgError", "broadcast", "could not convert"):
        assert leak not in msg


def test_model_error_is_a_value_error_and_an_se3dyn_error():
    assert issubclass(sd.ModelError, ValueError)
    assert issubclass(sd.ModelError, sd.Se3dynError)
    assert issubclass(sd.NewtonError, sd.SimulationError)


def test_a_valid_model_builds_after_a_rejected_call():
    # a rejected call leaves the builder usable and unchanged
    mb = _base()
    with pytest.raises(sd.ModelError):
        mb.joint("pin", "hinge", "ground", "bdoy", axis=(0, 0, 1))
    mb.joint("pin", "hinge", "ground", "body", axis=(0, 0, 1))
    model = mb.build()
    assert model.joint_names == ["pin"]


def test_unhashable_node_name_is_a_model_error():
    mb = _base()
    with pytest.raises(sd.ModelError) as info:
        mb.joint("pin", "hinge", ["ground"], "body", axis=(0, 0, 1))
    assert "node_a" in str(info.value)


def test_universal_joint_does_not_overwrite_an_existing_joint():
    mb = _base()
    mb.node("arm", position=(2.0, 0.0, 0.0), mass=1.0, inertia=(1, 1, 1))
    mb.joint("u:1", "prismatic", "body", "arm", axis=(1, 0, 0))
    with pytest.raises(sd.ModelError) as info:
        mb.joint("u", "universal", "ground", "body", axes=[(1, 0, 0), (0, 1, 0)])
    assert "u:1" in str(info.value)


def test_numpy_scalar_times_are_accepted():
    model = _hinged(_base())
    res = sd.simulate(model, np.int64(1), np.float32(0.25))
    assert res.t[-1] == pytest.approx(1.0)


def test_load_changing_shape_during_simulation_names_the_load():
    mb = _base()
    mb.load("push", "body", force=lambda t: np.zeros(3) if t < 0.05 else np.zeros(2))
    with pytest.raises(sd.Se3dynError) as info:
        sd.simulate(mb.build(), 0.1, 0.01)
    assert "'push'" in str(info.value)
