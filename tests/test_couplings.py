"""Exact couplings of joint coordinates (ModelBuilder.coupling: gears, racks, mimic joints).

References are closed forms: two wheels geared with ratio r under a torque on the leader turn
with the effective inertia ``J_a + r^2 J_b``, the gear carrying ``J_b r alpha_a''`` to the
follower; a rack and pinion likewise with ``J + m R^2``; a geared arm under gravity balances
where ``tau_a + r tau_gravity,b = 0``; an ideal coupling does no work.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import se3dyn as sd
from _results_file import run_and_read
from se3dyn.errors import ModelError, Se3dynWarning
from se3dyn.io.modelfile import load_model, save_model
from se3dyn.results.channels import channel_unit, get_channel, list_channels

JA, JB, R, TAU = 0.2, 0.05, -2.0, 1.0


def _run(model, t_end, h, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Se3dynWarning)
        return sd.simulate(model, t_end, h, **kw)


def _gears(gravity=False):
    mb = sd.ModelBuilder(gravity=(0, -9.81, 0) if gravity else (0, 0, 0))
    mb.node("g", fixed=True)
    mb.node("A", (0, 0, 0), mass=1.0, inertia=(JA, JA, JA))
    mb.node("B", (1.5, 0, 0), mass=2.0, inertia=(JB, JB, JB))
    mb.joint("ja", "hinge", "g", "A", axis=(0, 0, 1), torque=TAU)
    mb.joint("jb", "hinge", "g", "B", axis=(0, 0, 1), at=(1.5, 0, 0))
    if gravity:  # an arm fixed on the follower wheel, 0.5 m off its axis
        mb.node("arm", (2.0, 0, 0), mass=0.5, inertia=(1e-3, 1e-2, 1e-2))
        mb.joint("fix", "rigid", "B", "arm")
    mb.coupling("gear", leader="ja", follower="jb", ratio=R)
    return mb.build()


@pytest.mark.parametrize("formulation", ["index2", "index3"])
def test_gear_pair_turns_with_the_effective_inertia_and_carries_the_followers_torque(
        formulation):
    res = _run(_gears(), 1.0, 1e-2, formulation=formulation)
    a, b = res.joint_coordinates("ja")[:, 0], res.joint_coordinates("jb")[:, 0]
    acc = TAU / (JA + R * R * JB)
    np.testing.assert_array_equal(b, R * a)  # the ratio at every step, to the last bit
    np.testing.assert_array_equal(res.joint_velocities("jb")[:, 0],
                                  R * res.joint_velocities("ja")[:, 0])
    np.testing.assert_allclose(a, acc * res.t ** 2 / 2, rtol=0, atol=1e-13)
    np.testing.assert_allclose(res.coupling_force("gear"), JB * R * acc, rtol=1e-12)
    # the leader's hinge transmits the torque less what the gear takes: A^T lambda
    np.testing.assert_allclose(res.joint_torque("ja")[:, 0], TAU - JA * acc, rtol=1e-12)
    assert res.stats["energy_balance_error"] < 1e-12 * res.stats["energy_scale"]


def test_geared_arm_under_gravity_balances_its_energy_and_statics_finds_the_balance():
    res = _run(_gears(gravity=True), 1.0, 1e-3)
    np.testing.assert_array_equal(res.joint_coordinates("jb")[:, 0],
                                  R * res.joint_coordinates("ja")[:, 0])
    assert res.stats["energy_balance_error"] < 1e-5 * res.stats["energy_scale"]
    assert res.stats["newton_iterations"] <= 1.2 * len(res.t)  # an exact Newton matrix
    st = sd.static_equilibrium(_gears(gravity=True))
    tb = st.joint_coordinates("jb")[0]
    # torque on A + ratio times gravity's on B (the arm, 0.5 kg at 0.5 m) = 0
    np.testing.assert_allclose(TAU + R * (-0.5 * 9.81 * 0.5 * math.cos(tb)), 0.0, atol=1e-9)
    assert st.joint_coordinates("ja")[0] == pytest.approx(tb / R, abs=1e-12)


def test_rack_and_pinion():
    J, m, rad = 0.02, 3.0, 0.1
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("pinion", mass=1.0, inertia=(J, J, J))
    mb.node("rack", (0.0, -rad, 0.0), mass=m, inertia=(0.1, 0.1, 0.1))
    mb.joint("pin", "hinge", "g", "pinion", axis=(0, 0, 1), torque=0.5)
    mb.joint("slide", "prismatic", "g", "rack", axis=(1, 0, 0))
    mb.coupling("teeth", leader="pin", follower="slide", ratio=rad)
    res = _run(mb.build(), 0.5, 1e-2)
    acc = 0.5 / (J + m * rad * rad)
    np.testing.assert_allclose(res.joint_coordinates("pin")[:, 0], acc * res.t ** 2 / 2,
                               rtol=0, atol=1e-13)
    np.testing.assert_allclose(res.coupling_force("teeth"), m * rad * acc, rtol=1e-12)
    assert channel_unit("coupling/teeth/force", res) == "N m | N"


def test_model_file_channels_and_results_files(tmp_path):
    model = _gears(gravity=True)
    text = save_model(model)
    assert "couplings:" in text
    back, _ = load_model(text)
    a, b = _run(model, 0.2, 1e-2), _run(back, 0.2, 1e-2)
    assert np.array_equal(a.H, b.H) and np.array_equal(a.lam, b.lam)
    assert "coupling/gear/force" in list_channels(a)
    res, back = run_and_read(model, 0.2, tmp_path / "r.h5")
    np.testing.assert_array_equal(get_channel(back, "coupling/gear/force"),
                                  get_channel(res, "coupling/gear/force"))


def _two_hinges():
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("A", mass=1.0, inertia=(1, 1, 1))
    mb.node("B", (1, 0, 0), mass=1.0, inertia=(1, 1, 1))
    mb.node("C", (2, 0, 0), mass=1.0, inertia=(1, 1, 1))
    mb.joint("ja", "hinge", "g", "A", axis=(0, 0, 1))
    mb.joint("jb", "hinge", "g", "B", axis=(0, 0, 1), at=(1, 0, 0))
    mb.joint("jc", "hinge", "g", "C", axis=(0, 0, 1), at=(2, 0, 0))
    return mb


@pytest.mark.parametrize("kw, field, text", [
    (dict(leader="ja", follower="ja"), "follower", "other than the leader"),
    (dict(leader="ja", follower="jbx"), "follower", "did you mean"),
    (dict(leader="ja", follower="jb", ratio=0.0), "ratio", "nonzero"),
    (dict(leader="ja", follower="jb", ratio=float("inf")), "ratio", "finite"),
    (dict(leader="ja", follower="jb", follower_coordinate=1), "follower_coordinate", "0 to 0"),
])
def test_bad_couplings_are_refused(kw, field, text):
    with pytest.raises(ModelError, match="coupling 'c'") as e:
        _two_hinges().coupling("c", **kw)
    assert e.value.field == field and text in str(e.value), str(e.value)


def test_a_coordinate_prescribed_twice_or_a_chain_is_refused():
    mb = _two_hinges()
    mb.coupling("c1", leader="ja", follower="jb", ratio=2.0)
    with pytest.raises(ModelError, match="coupling 'c1' prescribes it already"):
        mb.coupling("c2", leader="jc", follower="jb")
    with pytest.raises(ModelError, match="do not chain"):
        mb.coupling("c3", leader="jb", follower="jc")
    with pytest.raises(ModelError, match="coupling 'c1' prescribes it already"):
        mb.drive("d", "jb", velocity=1.0)
    mb.drive("d", "ja", velocity=1.0)  # a driven leader: the follower follows the drive
    res = _run(mb.build(), 0.5, 1e-2)
    np.testing.assert_allclose(res.joint_velocities("jb")[:, 0], 2.0, rtol=1e-15)


def test_a_coupling_must_hold_at_the_start():
    mb = _two_hinges()
    mb.coupling("c", leader="ja", follower="jb", ratio=2.0, offset=0.3)
    with pytest.raises(ModelError, match=r"coupling 'c'.*offset"):
        _run(mb.build(), 0.1, 1e-2)
    with pytest.raises(ModelError, match="couplings"):
        sd.kinematics(_gears(), {"ja": lambda t: t}, [0.0])
