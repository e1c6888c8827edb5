"""URDF import (se3dyn.load_urdf, docs/urdf.md): one tiny URDF per bug the importers of other
codes have had, each against a closed form computed here; a closed four-bar against its loop
equation; hostile files refused in one line naming the element; real robots of the
example-robot-data wheel against Pinocchio (frame poses, masses, gravity torques)."""

from __future__ import annotations

import math
import re
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial.transform import Rotation

import se3dyn as sd
from se3dyn.engine.rank import rank_analysis
from se3dyn.errors import ModelError, Se3dynWarning

DATA = Path(__file__).parent / "data" / "urdf"
G = 9.81


def load(name: str, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Se3dynWarning)
        return sd.load_urdf(DATA / name, **kw)


def rot(rpy) -> np.ndarray:
    """URDF's rpy as scipy writes it: extrinsic x, y, z = Rz(y) Ry(p) Rx(r)."""
    return Rotation.from_euler("xyz", rpy).as_matrix()


def holding_torque(mb, joint: str, q: float) -> float:
    """Static torque a drive holding ``joint`` at ``q`` supplies (se3dyn statics)."""
    mb.drive("hold", joint, position=q)
    return float(sd.static_equilibrium(mb.build()).drive_effort("hold")[0])


# ---------------------------------------------------------------------------------------------
def test_rotated_inertial_frame_gives_the_moment_about_the_hinge_2_not_1():
    """MuJoCo #3559: iyy = 2 of an inertial frame turned 90 deg about z is the moment about
    the hinge's x axis: a torque of 2 N m gives 1 rad/s^2 (1 N m if the rotation is dropped)."""
    mb = load("rotated_inertial.urdf", gravity=(0, 0, 0))
    m = mb.build()
    assert np.allclose(m.node("rotor").inertia, np.diag([2.0, 1.0, 2.5]), atol=1e-15)
    mb = sd.ModelBuilder.from_model(m)
    mb.load("torque", "rotor", torque=(2.0, 0.0, 0.0), torque_frame="inertial")
    res = sd.simulate(mb.build(), t_end=1.0, step=1e-2, rho_inf=1.0)
    q = res.joint_coordinates("hinge")[:, 0]
    assert np.abs(q - 0.5 * res.t ** 2).max() < 1e-10  # alpha = tau / I = 2 / 2


def test_rotated_inertial_frame_agrees_with_pinocchio_inverse_dynamics():
    model = pin.buildModelFromUrdf(str(DATA / "rotated_inertial.urdf"))
    tau = pin.rnea(model, model.createData(), pin.neutral(model), np.zeros(1), np.ones(1))
    assert tau[0] == pytest.approx(2.0, abs=1e-14)


def _pendulum_closed_form(q: float) -> tuple[float, float, float]:
    """Mass, centre-of-mass x and the moment about the hinge's y axis of arm + tip
    (fixed_child_offset_com.urdf) at hinge angle q, by the parallel-axis theorem."""
    parts = [(1.0, np.eye(3), np.array([0.2, 0, 0.01]), rot([0, 0, 0.5]),
              np.diag([0.01, 0.02, 0.025])),
             (2.0, rot([0.3, 0.2, 0.1]), np.array([0.5, 0.03, 0]) + rot([0.3, 0.2, 0.1])
              @ [0.05, 0.02, -0.03], rot([0.3, 0.2, 0.1]) @ rot([0.4, -0.2, 0.7]),
              np.array([[0.004, 0.0005, 0], [0.0005, 0.005, 0], [0, 0, 0.006]]))]
    Ry = Rotation.from_rotvec([0, q, 0]).as_matrix()
    M, mx, Iyy = 0.0, 0.0, 0.0
    for m, _, c, R, J in parts:
        cw, Rw = Ry @ c, Ry @ R
        Jw = Rw @ J @ Rw.T
        M, mx = M + m, mx + m * cw[0]
        Iyy += Jw[1, 1] + m * (cw[0] ** 2 + cw[2] ** 2)
    return M, mx / M, Iyy


@pytest.mark.parametrize("fixed", ["keep", "merge"])
def test_fixed_child_with_offset_com_static_torque_and_acceleration(fixed):
    """A pendulum whose tip sits on a fixed joint, both inertial frames offset and rotated:
    holding torque -M g x_c and initial acceleration M g x_c / I_O from the parallel-axis
    theorem; the same whether the fixed joint is kept (rigid joint) or merged."""
    q = 0.4
    M, xc, Io = _pendulum_closed_form(q)
    tau = holding_torque(load("fixed_child_offset_com.urdf", q0={"hinge": q}, fixed=fixed),
                         "hinge", q)
    assert tau == pytest.approx(-M * G * xc, rel=1e-12)
    res = sd.simulate(load("fixed_child_offset_com.urdf", q0={"hinge": q}, fixed=fixed).build(),
                      t_end=1e-3, step=1e-3)
    alpha0 = res.node_acceleration("arm", frame="inertial")[0, 4]
    assert alpha0 == pytest.approx(M * G * xc / Io, rel=1e-10)


def test_fixed_merge_lumps_the_tip_and_keeps_its_frame_as_a_marker():
    keep = load("fixed_child_offset_com.urdf", q0={"hinge": 0.4}).build()
    merged = load("fixed_child_offset_com.urdf", q0={"hinge": 0.4}, fixed="merge").build()
    assert [n.name for n in merged.nodes] == ["base", "arm"]
    assert merged.node("arm").mass == pytest.approx(3.0)
    tip = keep.node("tip")
    X = merged.marker("tip").X
    arm = merged.node("arm")
    assert np.allclose(arm.orientation @ X[:3, 3] + arm.position, tip.position, atol=1e-15)
    assert np.allclose(arm.orientation @ X[:3, :3], tip.orientation, atol=1e-15)


def test_mimic_multiplier_minus_one_with_offset_holds_exactly_through_a_run():
    mb = load("mimic.urdf", q0={"lead": 0.2})
    assert mb.urdf.couplings == {"follow": ("lead", -1.0, 0.3)}
    res = sd.simulate(mb.build(), t_end=1.0, step=1e-3, rho_inf=1.0)
    q1, q2 = res.joint_coordinates("lead")[:, 0], res.joint_coordinates("follow")[:, 0]
    assert q2[0] == pytest.approx(0.1, abs=1e-15)
    assert np.abs(q2 - (-q1 + 0.3)).max() < 1e-12
    assert np.ptp(q1) > 0.3  # it swings
    eb = res.energy_balance  # the coupling does no work: the energy balance holds
    assert np.abs(eb - eb[0]).max() < 1e-4 * np.ptp(res.kinetic)


def test_mimic_ignore_drops_the_coupling_and_says_so():
    with pytest.warns(Se3dynWarning, match="mimic"):
        mb = sd.load_urdf(DATA / "mimic.urdf", mimic="ignore")
    assert not mb.build().couplings and "dropped" in mb.urdf.report()


def test_mimic_refuses_an_inconsistent_follower_value():
    with pytest.raises(ModelError, match=r"q0\['follow'\].*<mimic>"):
        load("mimic.urdf", q0={"lead": 0.2, "follow": 0.2})


def test_continuous_joint_angle_passes_two_pi_unbounded():
    mb = load("continuous.urdf", gravity=(0, 0, 0), q0={"wheel_joint": 3.0},
              v0={"wheel_joint": 10.0})
    assert mb.urdf.limits["wheel_joint"].lower is None
    assert mb.urdf.limits["wheel_joint"].effort == 5.0
    assert mb.urdf.friction == {"wheel_joint": 0.05}
    res = sd.simulate(mb.build(), t_end=1.0, step=1e-2, rho_inf=1.0)
    q = res.joint_coordinates("wheel_joint")[:, 0]
    assert np.abs(q - (3.0 + 10.0 * res.t)).max() < 1e-9
    assert q[-1] > 4 * math.pi


def test_meshes_package_and_relative_resolved_missing_one_warned():
    with pytest.warns(Se3dynWarning, match=r"link 'arm'.*lost\.stl.*tried"):
        mb = sd.load_urdf(DATA / "meshes.urdf", package_dirs=[DATA / "pkgs"])
    m = mb.build()
    files = {v.name: v.file for v in m.visuals if v.shape == "mesh"}
    assert Path(files["base:visual:0"]) == (DATA / "pkgs/urdf_test_pkg/meshes/tet.stl").resolve()
    assert Path(files["arm:visual:0"]) == (DATA / "meshes/tet.stl").resolve()
    assert "arm:visual:1" not in files
    base = next(v for v in m.visuals if v.name == "base:visual:0")
    assert np.allclose(base.size, 2.0) and np.allclose(base.offset, (0, 0, 0.1))
    assert base.color == "#4582b5"


def test_meshes_found_through_ros_package_path(monkeypatch):
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(DATA / "pkgs"))
    m = load("meshes.urdf").build()
    assert any(v.name == "base:visual:0" for v in m.visuals)


def test_meshes_drawn_by_the_viewer():
    from se3dyn.viewer.shapes import build_scene

    mb = load("meshes.urdf", package_dirs=[DATA / "pkgs"])
    res = sd.simulate(mb.build(), t_end=0.01, step=1e-2)
    scene = build_scene(res)
    assert len(scene.meshes) == 2


def test_missing_inertial_is_massless_and_reported():
    mb = load("missing_inertial.urdf", q0={"hinge": -0.5})
    assert "without <inertial> have no mass" in mb.urdf.report()
    assert mb.build().node("rod").mass == 0.0
    tau = holding_torque(mb, "hinge", -0.5)
    assert tau == pytest.approx(-2.0 * G * 0.8 * math.cos(-0.5), rel=1e-12)


# ---------------------------------------------------------------------------------------------
def _fourbar_variant(tmp_path, kind: str) -> Path:
    txt = (DATA / "fourbar.urdf").read_text()
    loop = re.search(r"<se3dyn:loop.*?</se3dyn:loop>", txt, re.S).group(0)
    if kind == "isaac":
        txt = txt.replace(loop, '<loop_joint name="closure" type="spherical"><link1 '
                          'link="coupler" xyz="0.8 0 0.2"/><link2 link="rocker_link" '
                          'xyz="0.1 0 0.6"/></loop_joint>')
    elif kind == "drake":
        txt = txt.replace(loop, '<drake:ball_constraint><drake:ball_constraint_body_A '
                          'name="coupler"/><drake:ball_constraint_body_B name="rocker_link"/>'
                          '<drake:ball_constraint_p_AP value="0.8 0 0.2"/>'
                          '<drake:ball_constraint_p_BQ value="0.1 0 0.6"/>'
                          '</drake:ball_constraint>')
        txt = txt.replace('<robot name="fourbar"',
                          '<robot name="fourbar" xmlns:drake="http://drake.mit.edu"')
    elif kind == "side":
        txt = txt.replace(loop, "")
    p = tmp_path / f"fourbar_{kind}.urdf"
    p.write_text(txt)
    return p


def test_four_bar_loop_exact_over_a_passive_run_and_redundancy_reported():
    """The closed four-bar under gravity for 2 s: the closing hinge's point stays joined to
    1e-12 m at every step, the crank and rocker angles satisfy the loop equation |C - B| =
    |BC| to 1e-12, and the three redundant equations of a planar loop are reported."""
    m = load("fourbar.urdf").build()
    r = rank_analysis(sd.compile_model(m))
    assert r.dof == 1 and len(r.redundant) == 3
    res = sd.simulate(m, t_end=2.0, step=1e-3, tol_constraint=1e-13)
    Hc, Hr = res.node_frame("coupler"), res.node_frame("rocker_link")
    C = np.array([1.1, 0, 0.6, 1.0])
    pc, pr = np.linalg.solve(Hc[0], C), np.linalg.solve(Hr[0], C)
    gap = np.linalg.norm(Hc @ pc - Hr @ pr, axis=1)
    assert gap.max() <= 1e-12
    q1 = res.joint_coordinates("crank")[:, 0]
    q3 = res.joint_coordinates("rocker")[:, 0]
    assert np.abs(_loop_gap(q1, q3)).max() < 1e-12
    assert np.ptp(q1) > 0.5


@pytest.mark.parametrize("kind", ["isaac", "drake", "side"])
def test_loop_closures_of_isaac_drake_and_a_side_file(tmp_path, kind):
    """A spherical closure of the planar loop (Isaac's <loop_joint>, Drake's ball
    constraint, or a side file): mobility 1, one redundant equation."""
    loops = None
    if kind == "side":
        side = tmp_path / "loops.yaml"
        side.write_text("loops:\n  - {name: closure, type: spherical, link1: {link: coupler, "
                        "xyz: [0.8, 0, 0.2]}, link2: {link: rocker_link, xyz: [0.1, 0, 0.6]}}\n")
        loops = side
    m = sd.load_urdf(_fourbar_variant(tmp_path, kind), loops=loops).build()
    r = rank_analysis(sd.compile_model(m))
    assert r.dof == 1 and len(r.redundant) == 1
    assert any(j.type == "spherical" for j in m.joints)


def _loop_gap(q1: float, q3: float) -> float:
    """|C(q3) - B(q1)| - |BC| of the four-bar (hinges about y)."""
    bx, bz = 0.3 * np.cos(q1) + 0.4 * np.sin(q1), -0.3 * np.sin(q1) + 0.4 * np.cos(q1)
    cx, cz = 1.0 + 0.1 * np.cos(q3) + 0.6 * np.sin(q3), -0.1 * np.sin(q3) + 0.6 * np.cos(q3)
    return np.hypot(cx - bx, cz - bz) - math.hypot(0.8, 0.2)


def test_loop_closed_by_the_joints_not_given_in_q0():
    """Only the crank angle given: the knee and rocker angles are solved so that the loop
    closes (the loop equation holds to round-off), and the report says so."""
    mb = load("fourbar.urdf", q0={"crank": 0.3})
    m = mb.build()
    q3 = float(m.joint("rocker").initial[0])
    assert m.joint("crank").initial[0] == 0.3
    assert abs(_loop_gap(0.3, q3)) < 1e-13
    assert "q0 of rocker, knee solved" in mb.urdf.report()


def test_loop_that_q0_cannot_close_is_refused_with_the_gap():
    with pytest.raises(ModelError, match=r"loop 'closure'.*m apart.*could not close"):
        load("fourbar.urdf", q0={"crank": 0.3, "rocker": 0.0, "knee": 0.0})


# ---------------------------------------------------------------------------------------------
def _robot(body: str, head: str = "") -> str:
    return f'<?xml version="1.0"?>\n{head}<robot name="r">{body}</robot>\n'


LINK = ('<link name="{n}"><inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1"/>'
        '</inertial></link>')


def _joint(name, parent, child, extra=""):
    return (f'<joint name="{name}" type="revolute"><parent link="{parent}"/>'
            f'<child link="{child}"/><axis xyz="0 0 1"/>{extra}</joint>')


HOSTILE = {
    "billion laughs": (_robot(LINK.format(n="a") + "<link name='&lol9;'/>", '<!DOCTYPE r [\n'
                       '<!ENTITY lol "lol">\n' + "".join(
                           f'<!ENTITY lol{i} "{("&lol" + str(i - 1) + ";") * 10}">\n'
                           .replace("&lol0;", "&lol;") for i in range(1, 10)) + "]>\n"),
                       r"<!ENTITY>.*entity"),
    "external entity": (_robot('<link name="&x;"/>', '<!DOCTYPE r [<!ENTITY x SYSTEM '
                               '"file:///etc/passwd">]>\n'), r"<!ENTITY>"),
    "cycle": (_robot(LINK.format(n="a") + LINK.format(n="b") + LINK.format(n="c")
                     + _joint("j1", "a", "b") + _joint("j2", "b", "c") + _joint("j3", "c", "b")),
              r"joint 'j3'.*<child> link.*'b'"),
    "closed cycle": (_robot(LINK.format(n="a") + LINK.format(n="b") + LINK.format(n="r")
                            + _joint("j1", "a", "b") + _joint("j2", "b", "a")),
                     r"joint 'j1'.*<child> link.*cycle"),
    "unknown link": (_robot(LINK.format(n="a") + LINK.format(n="b") + _joint("j", "a", "bb")),
                     r"joint 'j'.*<child> link.*'bb'.*did you mean 'b'"),
    "NaN origin": (_robot(LINK.format(n="a") + LINK.format(n="b") + _joint(
        "j", "a", "b", '<origin xyz="0 nan 0"/>')), r"joint 'j'.*<origin> xyz.*finite"),
    "negative mass": (_robot('<link name="a"><inertial><mass value="-1"/></inertial></link>'),
                      r"link 'a'.*<mass> value.*non-negative"),
    "non-positive-definite inertia": (
        _robot('<link name="a"><inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" '
               'ixy="2"/></inertial></link>'), r"link 'a'.*<inertia>.*positive-definite"),
    "triangle inequality": (
        _robot('<link name="a"><inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="3"/>'
               '</inertial></link>'), r"link 'a'.*<inertia>.*triangle inequality"),
    "duplicate link": (_robot(LINK.format(n="a") + LINK.format(n="a")),
                       r"link 'a'.*name.*unique.*defined twice"),
    "duplicate joint": (_robot(LINK.format(n="a") + LINK.format(n="b") + LINK.format(n="c")
                               + _joint("j", "a", "b") + _joint("j", "a", "c")),
                        r"joint 'j'.*unique joint name"),
    "zero axis": (_robot(LINK.format(n="a") + LINK.format(n="b") + _joint(
        "j", "a", "b").replace('xyz="0 0 1"', 'xyz="0 0 0"')), r"joint 'j'.*<axis> xyz.*non-zero"),
    "two roots": (_robot(LINK.format(n="a") + LINK.format(n="b")), r"one root link"),
    "bad type": (_robot(LINK.format(n="a") + LINK.format(n="b") + _joint("j", "a", "b")
                        .replace("revolute", "hinge")), r"joint 'j'.*type.*revolute"),
    "not XML": ("<robot><link name='a'></robot>", r"XML.*well-formed"),
}


@pytest.mark.parametrize("case", list(HOSTILE))
def test_hostile_urdf_refused_in_one_line_naming_the_element(tmp_path, case):
    text, pattern = HOSTILE[case]
    p = tmp_path / "hostile.urdf"
    p.write_text(text)
    with pytest.raises(ModelError) as err:
        sd.load_urdf(p)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith("hostile.urdf")
    assert re.search(pattern, msg), msg


def test_hundred_thousand_links_refused_while_reading(tmp_path):
    p = tmp_path / "huge.urdf"
    links = "".join(f'<link name="l{i}"/>' for i in range(100_000))
    p.write_text(_robot(links))
    t0 = time.process_time()
    with pytest.raises(ModelError, match=r"at most 10000 links"):
        sd.load_urdf(p)
    assert time.process_time() - t0 < 5.0  # refused after 10^4 links, not after 10^5


def test_two_thousand_link_chain_loads(tmp_path):
    n = 2000
    body = LINK.format(n="l0") + "".join(
        LINK.format(n=f"l{i}") + _joint(f"j{i}", f"l{i - 1}", f"l{i}", '<origin xyz="0.1 0 0"/>')
        for i in range(1, n))
    p = tmp_path / "chain.urdf"
    p.write_text(_robot(body))
    m = load(str(p)).build()
    assert len(m.nodes) == n and len(m.joints) == n - 1


def test_unknown_tags_reported_once(tmp_path):
    p = tmp_path / "extra.urdf"
    p.write_text(_robot(LINK.format(n="a").replace("</link>", "<sensor/></link>")
                        + "<gazebo/><transmission/><gazebo/>"))
    with pytest.warns(Se3dynWarning) as rec:
        mb = sd.load_urdf(p)
    assert len(rec) == 1
    text = mb.urdf.report()
    assert "<gazebo> x2" in text and "<transmission> x1" in text and "<sensor>" in text


def test_bad_options_refused():
    with pytest.raises(ModelError, match="mimic"):
        load("mimic.urdf", mimic="drop")
    with pytest.raises(ModelError, match=r"q0\['nope'\].*valid: lead"):
        load("mimic.urdf", q0={"nope": 1.0})


# ---------------------------------------------------------------------------------------------
ROBOTS = Path(sys.prefix) / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}" \
    / "site-packages" / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
REAL = {"ur5": "ur_description/urdf/ur5_robot.urdf", "panda": "panda_description/urdf/panda.urdf",
        "solo12": "solo_description/robots/solo12.urdf",
        "double_pendulum_continuous":
            "double_pendulum_description/urdf/double_pendulum_continuous.urdf"}


def _robots_dir() -> Path:
    import importlib.metadata as md

    for f in md.distribution("example-robot-data").files:
        if str(f).endswith("ur_description/urdf/ur5_robot.urdf"):
            return Path(f.locate()).parents[2]
    return ROBOTS


@pytest.mark.parametrize("name", list(REAL))
def test_real_robot_matches_pinocchio_frames_mass_and_gravity_torques(name):
    """example-robot-data's robots: every link's pose at a random configuration, the total
    mass and the static gravity torques (se3dyn statics holding every joint) against
    Pinocchio's forward kinematics and computeGeneralizedGravity."""
    path = str(_robots_dir() / REAL[name])
    pm = pin.buildModelFromUrdf(path)
    data = pm.createData()
    names = [pm.names[i] for i in range(1, pm.njoints)]
    theta = np.random.default_rng(7).uniform(-1.0, 1.0, len(names))
    q0 = dict(zip(names, theta.tolist(), strict=True))
    q = pin.neutral(pm)
    for jt, th in zip(list(pm.joints)[1:], theta, strict=True):
        q[jt.idx_q:jt.idx_q + jt.nq] = (th,) if jt.nq == 1 else (math.cos(th), math.sin(th))
    mb = load(path, q0=q0, mimic="ignore")
    m = mb.build()
    pin.framesForwardKinematics(pm, data, q)
    for fr in pm.frames:
        if fr.type == pin.FrameType.BODY:
            T, nd = data.oMf[pm.getFrameId(fr.name)], m.node(fr.name)
            assert np.abs(nd.position - T.translation).max() < 1e-12, fr.name
            assert np.abs(nd.orientation - T.rotation).max() < 1e-12, fr.name
    free = load(path, floating_base=True).build()  # the root's own mass kept
    assert sum(n.mass for n in free.nodes) == pytest.approx(
        sum(i.mass for i in pm.inertias), rel=1e-12)
    for n in mb.urdf.joints:
        mb.drive(f"hold:{n}", n, position=q0[n])
    st = sd.static_equilibrium(mb.build())
    g = pin.computeGeneralizedGravity(pm, data, q)
    ours = np.array([st.drive_effort(f"hold:{n}")[0] for n in names])
    assert np.abs(ours - g).max() <= 1e-10 * max(1.0, np.abs(g).max())


@pytest.mark.parametrize("name", ["ur5", "panda", "solo12"])
def test_real_robot_imports_builds_and_simulates(name):
    path = _robots_dir() / REAL[name]
    mb = load(str(path), floating_base=name == "solo12")
    res = sd.simulate(mb.build(), t_end=0.1, step=1e-3)
    assert np.all(np.isfinite(res.alpha)) and res.t[-1] == pytest.approx(0.1)
    if name == "solo12":  # free fall of the whole robot: its centre of mass falls g t^2 / 2
        z = res.node_position("base_link")[:, 2]
        assert z[-1] - z[0] == pytest.approx(-0.5 * G * 0.1 ** 2, rel=1e-10)
    if name == "panda":  # the fingers' <mimic> enforced
        assert [c.name for c in mb.build().couplings] == ["panda_finger_joint2:mimic"]


# ---------------------------------------------------------------------------------------------
def test_cli_checks_runs_and_imports_a_urdf(tmp_path, capsys):
    from se3dyn.cli import main
    from se3dyn.io.modelfile import load_model

    assert main(["check", str(DATA / "fourbar.urdf")]) == 0
    out = capsys.readouterr().out
    assert "loop closure 'closure'" in out and "redundant constraint equations (3)" in out
    assert main(["run", str(DATA / "mimic.urdf"), "--t-end", "0.05", "--step", "1e-2",
                 "--out", str(tmp_path), "--quiet"]) == 0
    assert "<limit> of 1 joints kept" in capsys.readouterr().err
    out = tmp_path / "m.yaml"
    assert main(["import-urdf", str(DATA / "fixed_child_offset_com.urdf"), "-o", str(out),
                 "--fixed", "merge"]) == 0
    model, _ = load_model(out)
    assert [n.name for n in model.nodes] == ["base", "arm"] and model.marker("tip")
    assert main(["check", str(tmp_path / "none.urdf")]) == 2


def test_point_mass_on_a_fixed_joint_lumped_into_its_parent(tmp_path):
    """A sensor frame with mass and no inertia (as real files have): lumped into its parent
    by the parallel-axis theorem (holding torque with the point mass at 0.5 m), its frame
    kept as a marker; on a moving joint it is refused."""
    point = ('<link name="cam"><inertial><origin xyz="0.1 0 0"/><mass value="0.5"/>'
             '<inertia ixx="0" iyy="0" izz="0"/></inertial></link>')
    weld = '<joint name="w" type="fixed"><parent link="b"/><child link="cam"/>' \
           '<origin xyz="0.4 0 0"/></joint>'
    p = tmp_path / "point.urdf"
    p.write_text(_robot(LINK.format(n="a") + LINK.format(n="b") + point
                        + _joint("j", "a", "b").replace('xyz="0 0 1"', 'xyz="0 1 0"') + weld))
    mb = load(str(p), q0={"j": 0.0})
    m = mb.build()
    assert "cam" not in m.node_names and m.marker("cam").node == "b"
    assert holding_torque(mb, "j", 0.0) == pytest.approx(-0.5 * G * 0.5, rel=1e-12)
    p.write_text(p.read_text().replace('type="fixed"', 'type="continuous"'))
    with pytest.raises(ModelError, match=r"link 'cam'.*point mass"):
        sd.load_urdf(p)


def test_planar_and_floating_joints_placed_by_q0_and_the_floating_child_falls_freely(tmp_path):
    body = (LINK.format(n="a") + LINK.format(n="p") + LINK.format(n="f")
            + '<joint name="pl" type="planar"><parent link="a"/><child link="p"/>'
              '<origin xyz="1 0 0"/><axis xyz="0 0 1"/></joint>'
            + '<joint name="fl" type="floating"><parent link="a"/><child link="f"/>'
              '<origin xyz="0 2 0"/></joint>')
    p = tmp_path / "pf.urdf"
    p.write_text(_robot(body))
    mb = load(str(p), q0={"pl": (0.3, -0.2, 0.5), "fl": (0, 0, 1.0, 0.1, 0.2, 0.3)},
              v0={"fl": (0.5, 0, 0, 0, 0, 0)})
    m = mb.build()
    pn, fn = m.node("p"), m.node("f")
    assert np.allclose(pn.position, (1.3, -0.2, 0.0), atol=1e-15)
    assert np.allclose(pn.orientation, rot([0, 0, 0.5]), atol=1e-15)
    assert np.allclose(fn.position, (0, 2, 1.0)) and np.allclose(fn.orientation, rot([.1, .2, .3]))
    assert [j.name for j in m.joints] == ["pl"]  # the floating child is a free node
    res = sd.simulate(m, t_end=0.5, step=1e-2)
    x = res.node_position("f")
    assert np.allclose(x[:, 2], 1.0 - 0.5 * G * res.t ** 2, atol=1e-12)
    assert np.allclose(x[:, 0], 0.5 * res.t, atol=1e-12)
    assert np.allclose(res.node_position("p"), (1.3, -0.2, 0.0), atol=1e-12)  # held in plane


def _joint_space_pair(name: str, floating: bool):
    """Pinocchio's model of an example-robot-data URDF and se3dyn's JointSpace of its import,
    the permutation of se3dyn's velocity coordinates into Pinocchio's and the URDF's joint
    damping (se3dyn applies it; Pinocchio's RNEA leaves it out)."""
    path = str(_robots_dir() / REAL[name])
    pm = (pin.buildModelFromUrdf(path, pin.JointModelFreeFlyer()) if floating
          else pin.buildModelFromUrdf(path))
    model = load(path, floating_base=floating, mimic="ignore").build()
    js = sd.JointSpace(model)
    perm = []
    for label in js.joint_names:
        kind, name_, comp = (part.strip() for part in label.split("'"))
        perm.append(["U_x", "U_y", "U_z", "Omega_x", "Omega_y", "Omega_z"].index(comp)
                    if kind == "node" else pm.joints[pm.getJointId(name_)].idx_v)
    damping = np.zeros(pm.nv)
    for j in model.joints:
        if j.k == 1 and j.name in pm.names:
            damping[pm.joints[pm.getJointId(j.name)].idx_v] = j.damping[0]
    return pm, js, np.array(perm), damping


def _random_state(pm, js, perm, rng, floating: bool):
    """One random state in both conventions: Pinocchio's q (continuous joints as cos, sin;
    the free flyer x, y, z, qx, qy, qz, qw) and se3dyn's (angles; the same root pose)."""
    q, qs = pin.neutral(pm), js.neutral().copy()
    joints = list(pm.joints)[1:]
    if floating:
        quat = rng.normal(size=4)
        q[:7] = qs[:7] = np.r_[rng.normal(size=3), quat / np.linalg.norm(quat)]
        joints = joints[1:]
    angle = {}
    for jt in joints:
        angle[jt.idx_v] = th = rng.uniform(-1.5, 1.5)
        q[jt.idx_q:jt.idx_q + jt.nq] = (th,) if jt.nq == 1 else (math.cos(th), math.sin(th))
    first = 7 if floating else 0
    for i, p in enumerate(p for p in perm if not (floating and p < 6)):
        qs[first + i] = angle[p]
    return q, qs, rng.normal(size=pm.nv), rng.normal(size=pm.nv)


@pytest.mark.parametrize("name", ["ur5", "panda", "double_pendulum_continuous", "solo12"])
def test_imported_robot_joint_space_matches_pinocchio(name):
    """The mass matrix and the inverse dynamics of the imported robot (sd.JointSpace) at 20
    random states against Pinocchio's CRBA and RNEA on its own parse of the same URDF
    (Panda's fingers uncoupled: mimic ignored; the URDF's joint damping added to RNEA)."""
    floating = name == "solo12"
    pm, js, perm, damping = _joint_space_pair(name, floating)
    data, rng = pm.createData(), np.random.default_rng(5)
    for _ in range(20):
        q, qs, v, a = _random_state(pm, js, perm, rng, floating)
        M = pin.crba(pm, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        assert np.abs(js.mass_matrix(qs) - M[np.ix_(perm, perm)]).max() <= 1e-10 * np.abs(M).max()
        tau = pin.rnea(pm, data, q, v, a) + damping * v
        ours = js.inverse_dynamics(qs, v[perm], a[perm])
        assert np.abs(ours - tau[perm]).max() <= 1e-10 * np.abs(tau).max()


def test_imported_arm_falls_as_pinocchio_aba_at_order_2():
    """The UR5 released from a bent pose for 1 s with no torque: the joint angles at 1 s
    against Pinocchio's ABA integrated by DOP853 at 1e-13 converge at order 2 in the step
    (rho_inf = 1), and so does the energy balance error (no damping in this file)."""
    from scipy.integrate import solve_ivp

    path = str(_robots_dir() / REAL["ur5"])
    pm = pin.buildModelFromUrdf(path)
    data = pm.createData()
    names = [pm.names[i] for i in range(1, pm.njoints)]
    q0 = np.array([0.3, -1.0, 0.8, -0.5, 0.4, 0.2])

    def rhs(t, y):
        return np.r_[y[6:], pin.aba(pm, data, y[:6], y[6:], np.zeros(6))]

    ref = solve_ivp(rhs, (0.0, 1.0), np.r_[q0, np.zeros(6)], method="DOP853", rtol=1e-13,
                    atol=1e-13).y[:6, -1]
    model = load(path, q0=dict(zip(names, q0.tolist(), strict=True))).build()
    err, drift = [], []
    for h in (4e-3, 2e-3, 1e-3):
        res = sd.simulate(model, t_end=1.0, step=h, rho_inf=1.0)
        q = np.array([res.joint_coordinates(n)[-1, 0] for n in names])
        err.append(np.abs(q - ref).max())
        drift.append(np.abs(res.energy_balance - res.energy_balance[0]).max())
    assert np.all(np.abs(np.log2(np.array(err[:-1]) / err[1:]) - 2.0) < 0.1), err
    assert np.all(np.abs(np.log2(np.array(drift[:-1]) / drift[1:]) - 2.0) < 0.1), drift
    assert err[-1] < 1e-4


def test_visual_mesh_the_viewer_cannot_read_drawn_with_the_collision_mesh():
    mb = load("dae_visual.urdf")
    (v,) = mb.build().visuals
    assert Path(v.file) == (DATA / "meshes/tet.stl").resolve()
    assert np.allclose(v.offset, (0, 0, 0.3))
    text = mb.urdf.report()
    assert "tet.dae" in text and "drawn with their <collision> mesh instead: base" in text


def test_imported_panda_with_mimic_mass_matrix_matches_pinocchio():
    """Panda's second finger follows the first (<mimic>, an exact coupling): the mass matrix
    in the 8 independent coordinates at 20 random states against Pinocchio's CRBA on its model
    with mimic joints (``buildModelFromUrdf(..., mimic=True)``)."""
    path = str(_robots_dir() / REAL["panda"])
    pm = pin.buildModelFromUrdf(path, mimic=True)
    data = pm.createData()
    js = sd.JointSpace(load(path).build())
    ids = [pm.getJointId(label.split("'")[1]) for label in js.joint_names]
    perm = [pm.joints[i].idx_v for i in ids]
    rng = np.random.default_rng(2)
    for _ in range(20):
        q, qs = pin.neutral(pm), js.neutral().copy()
        for k, i in enumerate(ids):
            qs[k] = q[pm.joints[i].idx_q] = rng.uniform(-1, 1) * (0.03 if k == 7 else 1.0)
        M = pin.crba(pm, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        assert np.abs(js.mass_matrix(qs) - M[np.ix_(perm, perm)]).max() <= 1e-10 * np.abs(M).max()


def test_inertias_no_body_can_have_are_refused_or_repaired_on_request(tmp_path):
    """Principal moments (1, 1, 3) break J3 <= J1 + J2: refused by default (naming the
    option), or repaired with the same principal axes to (1.5, 1.5, 3) (the two smaller raised
    equally to the triangle's equality, a plate's) and listed in the report; the repaired link
    turns about its hinge (x, one of the two raised axes) at tau / 1.5."""
    link = ('<link name="b"><inertial><origin rpy="0 0 0.3"/><mass value="2"/>'
            '<inertia ixx="1" iyy="1" izz="3"/></inertial></link>')
    joint = ('<joint name="h" type="continuous"><parent link="a"/><child link="b"/>'
             '<axis xyz="0 0 1"/></joint>')
    p = tmp_path / "bad_inertia.urdf"
    p.write_text(_robot('<link name="a"/>' + link + joint))
    with pytest.raises(ModelError, match="triangle inequality.*inertia='repair'"):
        sd.load_urdf(p)
    with pytest.warns(Se3dynWarning, match="made physical"):
        mb = sd.load_urdf(p, inertia="repair", gravity=(0, 0, 0))
    assert any("(1, 1, 3) -> (1.5, 1.5, 3)" in n for n in mb.urdf.notes)
    J = mb.build().node("b").inertia
    np.testing.assert_allclose(np.linalg.eigvalsh(J), [1.5, 1.5, 3.0], rtol=1e-12)
    # the hinge is about z, the tensor's third principal axis (rotated about z): 3 kept
    mb.load("t", "b", torque=(0.0, 0.0, 0.6))
    res = sd.simulate(mb.build(), 0.1, 1e-3)
    np.testing.assert_allclose(res.joint_coordinates("h")[-1, 0], 0.5 * (0.6 / 3.0) * 0.01,
                               rtol=1e-9)
    with pytest.raises(ModelError, match="field 'inertia'"):
        sd.load_urdf(p, inertia="fix")


def test_real_robots_with_placeholder_inertias_load_with_inertia_repair():
    """example-robot-data's Allegro hand has inertias no body can have (refused by default);
    with ``inertia="repair"`` it loads, the report lists the links, and it simulates."""
    p = _robots_dir() / "allegro_hand_description/urdf/allegro_right_hand.urdf"
    with pytest.raises(ModelError, match="inertia"):
        sd.load_urdf(p)
    with pytest.warns(Se3dynWarning, match="made physical"):
        mb = sd.load_urdf(p, inertia="repair")
    assert any("made physical" in n for n in mb.urdf.notes)
    res = sd.simulate(mb.build(), 0.02, 1e-3)
    assert np.all(np.isfinite(res.H))
