"""What a newcomer tripped on (issue 28, part 4), each as the behaviour a new user sees.

* An initial velocity on an over-constrained planar four-bar (four hinges on parallel axes: three
  redundant equations): the crank keeps its given speed and the other links get the velocities
  of the analytic velocity constraint of the four-bar; nothing but se3dyn's own report is
  printed; ``assemble`` keeps the speed too and says which velocities it changed.
"""

from __future__ import annotations

import importlib
import warnings

import numpy as np
import pytest

import se3dyn as sd
from se3dyn.analysis.assemble import assemble
from se3dyn.errors import Se3dynWarning
from se3dyn.io.modelfile import loads_model
from test_cli import run

kin = importlib.import_module("se3dyn.engine.projection")

W2 = 12.566  # crank speed, rad/s
# pivots and joint points of the planar four-bar (m): ground A0-D0, crank A0-B, coupler B-C,
# rocker C-D0; bodies at the link centres
A0, B, C, D0 = (np.array(p, float) for p in ((0, 0), (0, 0.1), (0.2, 0.2), (0.3, 0)))
FOUR_BAR = f"""\
se3dyn: 1
name: four_bar
gravity: [0.0, -9.81, 0.0]
nodes:
  ground: {{position: [0, 0, 0], fixed: true}}
  crank: {{position: [0.0, 0.05, 0.0], mass: 0.2, inertia: [1.0e-4, 1.0e-4, 2.0e-4],
          angular_velocity: [0, 0, {W2}]}}
  coupler: {{position: [0.1, 0.15, 0.0], mass: 0.5, inertia: [1.0e-4, 2.0e-3, 2.0e-3]}}
  rocker: {{position: [0.25, 0.1, 0.0], mass: 0.3, inertia: [1.0e-4, 6.0e-4, 6.0e-4]}}
joints:
  A: {{type: hinge, a: ground, b: crank, axis: [0, 0, 1], at: [0, 0, 0]}}
  B: {{type: hinge, a: crank, b: coupler, axis: [0, 0, 1], at: [0, 0.1, 0]}}
  C: {{type: hinge, a: coupler, b: rocker, axis: [0, 0, 1], at: [0.2, 0.2, 0]}}
  D: {{type: hinge, a: rocker, b: ground, axis: [0, 0, 1], at: [0.3, 0, 0]}}
simulation: {{t_end: 0.05, step: 0.001}}
"""


def four_bar(text=FOUR_BAR):
    return loads_model(text, filename="four_bar.yaml")[0]


def analytic_rates(w2):
    """Coupler and rocker rates of the four-bar from its velocity constraint: the velocity of C
    is the same seen from the coupler and from the rocker,
    ``w2 x (B - A0) + w3 x (C - B) = w4 x (C - D0)`` (planar, z-rotations)."""
    perp = lambda r: np.array([-r[1], r[0]])  # noqa: E731  (z x r)
    M = np.column_stack([perp(C - B), -perp(C - D0)])
    w3, w4 = np.linalg.solve(M, -w2 * perp(B - A0))
    return w3, w4


def _planar_velocities_ok(node_velocity, w2):
    """The inertial velocities of the three links are those of the four-bar turning at w2."""
    w3, w4 = analytic_rates(w2)
    perp = lambda r: np.array([-r[1], r[0], 0.0])  # noqa: E731
    want = {"crank": (w2 * perp(np.array([0, 0.05])), w2),
            "coupler": (w2 * perp(B - A0) + w3 * perp(np.array([0.1, 0.15]) - B), w3),
            "rocker": (w4 * perp(np.array([0.25, 0.1]) - D0), w4)}
    for name, (u, w) in want.items():
        v = node_velocity(name)
        np.testing.assert_allclose(v[:3], u, atol=1e-12 * W2)
        np.testing.assert_allclose(v[3:], [0, 0, w], atol=1e-12 * W2)


def test_the_model_is_over_constrained_with_three_redundant_equations():
    from se3dyn.engine.rank import rank_analysis
    from se3dyn.engine.system import compile_model

    rep = rank_analysis(compile_model(four_bar()))
    assert len(rep.redundant) == 3 and rep.dof == 1


def test_initial_crank_speed_is_kept_and_the_links_follow_the_velocity_constraint():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = sd.simulate(four_bar(), t_end=0.02, step=1e-3)
    foreign = [w for w in caught if not issubclass(w.category, Se3dynWarning)]
    assert foreign == [], [str(w.message) for w in foreign]  # no scipy MatrixRankWarning
    assert not any("conflict" in str(w.message) for w in caught)
    _planar_velocities_ok(lambda n: res.node_velocity(n, frame="inertial")[0], W2)
    # the crank's linear velocity was changed (w x r), and reported as such
    changed = {c["node"] for c in res.stats["initial_velocity_changes"]}
    assert changed == {"crank", "coupler", "rocker"}


def test_run_on_the_command_line_starts_and_prints_no_foreign_warning(tmp_path):
    (tmp_path / "four_bar.yaml").write_text(FOUR_BAR)
    p = run("run", tmp_path / "four_bar.yaml", "--out", tmp_path / "out", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert "Warning" not in p.stderr and ".py:" not in p.stderr, p.stderr
    assert "singular" not in p.stderr + p.stdout


def test_assemble_keeps_the_crank_speed_and_says_what_changed():
    a = assemble(four_bar())

    def inertial(name):
        R = a.H[a.system.node_names.index(name), :3, :3]
        v = a.node_velocity(name)  # material
        return np.concatenate([R @ v[:3], R @ v[3:]])

    _planar_velocities_ok(inertial, W2)
    assert a.speeds_kept
    text = str(a)
    assert "initial velocities changed" in text
    for name in ("crank", "coupler", "rocker"):
        assert f"'{name}'" in text


def test_conflicting_speeds_are_replaced_by_the_closest_consistent_ones_and_said():
    text = FOUR_BAR.replace("rocker: {position: [0.25, 0.1, 0.0], mass: 0.3,",
                            "rocker: {position: [0.25, 0.1, 0.0], angular_velocity: [0, 0, 1.0],"
                            " mass: 0.3,")
    with pytest.warns(Se3dynWarning, match="initial velocities projected") as caught:
        res = sd.simulate(four_bar(text), t_end=0.005, step=1e-3)
    assert any("'rocker'" in str(w.message) for w in caught)
    w2 = res.node_velocity("crank", frame="inertial")[0, 5]
    assert abs(w2) < W2  # not kept: no motion of the four-bar has w2 = 12.566 and w4 = 1
    _planar_velocities_ok(lambda n: res.node_velocity(n, frame="inertial")[0], w2)
    assert not assemble(four_bar(text)).speeds_kept


def test_sparse_and_dense_projections_agree():
    """The two solvers of the projection (one sparse saddle-point solve, tried first; the
    rank-revealing dense one) give the same velocities on the four-bar."""
    import scipy.sparse as sp

    from se3dyn.engine.evaluate import evaluate
    from se3dyn.engine.inputs import step_inputs
    from se3dyn.engine.linsolve import LinearSolver
    from se3dyn.engine.rank import redundant_equations
    from se3dyn.engine.system import compile_model

    s = compile_model(four_bar())
    v0 = np.zeros(s.nq)
    v0[s.node_dofidx] = s.node_v0[s.node_free]
    z = np.zeros(s.nq)
    ev = evaluate(s, s.node_H0, s.joint_H0, s.alpha0, z, v0, z, np.zeros(s.nm),
                  step_inputs(s, 0.0), (1.0, 0.0, 0.0), accel=True)
    drop = redundant_equations(s)
    A = np.asarray(LinearSolver(s, drop=drop).matrix(ev.values))
    nq = s.nq
    rows = np.setdiff1d(np.arange(s.nm), drop)
    L = s.length_scale
    Bs = kin._row_scale(s, L)[rows, None] * A[nq:, :nq][rows]
    E = kin._held_rows(s, v0)
    sparse = kin._project_sparse(s, sp.csr_matrix(A[:nq, :nq]), Bs, v0, E)
    dense, kept = kin._project_dense(s, A[:nq, :nq], Bs, v0, E, L)
    assert kept and sparse is not None
    np.testing.assert_allclose(sparse[s.node_dofidx], dense[s.node_dofidx], atol=1e-9 * W2)
    _planar = {n: dense[s.node_dofidx[i]] for i, n in enumerate(
        s.node_names[j] for j in s.node_free)}
    assert _planar["crank"][5] == pytest.approx(W2, rel=1e-12)


# ---------------------------------------------------------------------------------------------
# a massless moving node: run and simulate give check's diagnosis
MASSLESS = """\
se3dyn: 1
name: massless
gravity: [0, 0, -9.81]
nodes:
  ground: {fixed: true}
  pivot: {position: [0, 0, 0]}
  bob: {position: [0.5, 0, 0], mass: 1.0, inertia: [1e-3, 1e-2, 1e-2]}
  tip: {position: [1.0, 0, 0]}      # massless, hangs on a ball joint: free to spin
joints:
  hinge: {type: hinge, a: ground, b: pivot, axis: [0, 1, 0]}
  arm: {type: rigid, a: pivot, b: bob}
  link: {type: spherical, a: bob, b: tip}
simulation: {t_end: 0.1, step: 0.01}
"""


def test_simulate_names_the_massless_node_and_its_joint():
    model = loads_model(MASSLESS, filename="massless.yaml")[0]
    with pytest.raises(sd.SimulationError) as exc:
        sd.simulate(model, t_end=0.1, step=0.01)
    msg = str(exc.value)
    assert "node 'tip'" in msg and "joint 'link'" in msg and "no mass" in msg
    assert "\n" not in msg


def test_run_and_check_give_the_same_diagnosis(tmp_path):
    f = tmp_path / "massless.yaml"
    f.write_text(MASSLESS)
    chk = run("check", f)
    p = run("run", f, "--out", tmp_path / "out")
    assert chk.returncode == 2 and p.returncode == 1
    cause = chk.stderr.strip().splitlines()[-1].split("t = 0: ", 1)[1]
    assert "node 'tip'" in cause
    assert cause in p.stderr


# ---------------------------------------------------------------------------------------------
# the energy balance warning says when its largest jump happened and how large it was
PULSE = """\
se3dyn: 1
name: pulse
gravity: [0, 0, 0]
nodes:
  g: {{fixed: true}}
  p: {{position: [0, 0, 0]}}
  b: {{position: [0.5, 0, 0], mass: 1.0, inertia: [1.0e-3, 1.0e-2, 1.0e-2]}}
joints:
  h: {{type: hinge, a: g, b: p, axis: [0, 1, 0],
       torque: {{step: {{value: 5.0, start: 0.0, stop: {stop}}}}}}}
  r: {{type: rigid, a: p, b: b}}
simulation: {{t_end: 0.5, step: 0.01}}
"""


def _balance(res):
    return (res.kinetic + res.potential + res.spring - res.work_actuators - res.work_loads
            + res.dissipation)


@pytest.mark.parametrize("stop, first", [(0.002, True), (0.015, False)])
def test_energy_warning_says_when_and_how_large_the_largest_jump_was(stop, first):
    """A torque pulse of 2 ms, shorter than the 10 ms step (an impulsive start), makes the whole
    balance error in the first step; a pulse over one and a half steps makes it in the second.
    The warning gives the step and the size that the rows' energies show."""
    model = loads_model(PULSE.format(stop=stop), filename="pulse.yaml")[0]
    with pytest.warns(Se3dynWarning, match="energy balance error") as caught:
        res = sd.simulate(model, t_end=0.5, step=0.01)
    (msg,) = [str(w.message) for w in caught if "energy balance" in str(w.message)]
    d = np.diff(_balance(res))
    k = int(np.argmax(np.abs(d)))
    assert k == (0 if first else 1)
    assert abs(d[k]) > 0.9 * res.stats["energy_balance_error"]  # nearly all the error
    assert f"between t = {res.t[k]:.6g} and {res.t[k + 1]:.6g} s" in msg
    assert f"{d[k]:+.3g} J" in msg
    assert ("impulsive start" in msg) == first
    assert ("the step is probably too large" in msg) == (not first)


def test_run_summary_says_when_the_largest_jump_was(tmp_path):
    f = tmp_path / "pulse.yaml"
    f.write_text(PULSE.format(stop=0.002))
    p = run("run", f, "--out", tmp_path / "out")
    assert p.returncode == 0, p.stderr
    (line,) = [x for x in p.stdout.splitlines() if "energy balance error" in x]
    assert "WARNING" in line and "between t = 0 and 0.01 s" in line
    assert "impulsive start" in line
    info = run("info", tmp_path / "out" / "pulse.h5")
    assert "between t = 0 and 0.01 s" in info.stdout


# ---------------------------------------------------------------------------------------------
# a hinge without `at` between a pivot and a body node off its axis
OFF_AXIS = """\
se3dyn: 1
name: off_axis
gravity: [0, 0, -9.81]
nodes:
  ground: {{fixed: true}}
  bob: {{position: [0.5, 0, 0], mass: 1.0, inertia: [1.0e-3, 1.0e-2, 1.0e-2]}}
joints:
  hinge: {{type: hinge, a: ground, b: bob, axis: [0, 1, 0]{at}}}
simulation: {{t_end: 0.3, step: 0.01}}
"""


def test_check_warns_of_a_body_turning_about_itself_and_its_at_makes_the_pendulum(tmp_path):
    f = tmp_path / "off_axis.yaml"
    f.write_text(OFF_AXIS.format(at=""))
    p = run("check", f)
    assert p.returncode == 0
    (line,) = [x for x in p.stdout.splitlines() if "WARNING" in x]
    assert "joint 'hinge'" in line and "'ground'" in line and "'bob'" in line
    assert "0.5 m" in line
    # as warned, the bob turns about itself: it stays where it is under gravity
    res = sd.simulate(four_bar(OFF_AXIS.format(at="")), t_end=0.3, step=0.01)
    np.testing.assert_allclose(res.node_position("bob")[-1], [0.5, 0, 0], atol=1e-12)
    # the 'at' the warning offers puts the axis through the pivot: a pendulum of 0.5 m
    at = line.split("an axis through node 'ground': at: ", 1)[1].split(";", 1)[0]
    model = four_bar(OFF_AXIS.format(at=f", at: {at}"))
    res = sd.simulate(model, t_end=0.3, step=0.01)
    x = res.node_position("bob")
    np.testing.assert_allclose(np.linalg.norm(x, axis=1), 0.5, rtol=1e-9)
    assert x[-1, 2] < -0.1  # it fell
    f.write_text(OFF_AXIS.format(at=f", at: {at}"))
    assert "WARNING" not in run("check", f).stdout


def test_run_warns_once_and_the_paper_models_not_at_all(tmp_path):
    f = tmp_path / "off_axis.yaml"
    f.write_text(OFF_AXIS.format(at=""))
    p = run("run", f, "--out", tmp_path / "out")
    assert p.returncode == 0
    assert p.stderr.count("joint 'hinge' (hinge): field 'at'") == 1
    from pathlib import Path

    for name in ("slider_crank.yaml", "a02_n_four_bar.yaml", "a05_flyball_governor.yaml"):
        out = run("check", Path(__file__).parents[1] / "examples" / name).stdout
        assert "WARNING" not in out, name


# ---------------------------------------------------------------------------------------------
# what se3dyn does not do yet, units, the length scale in check
ROOT = __import__("pathlib").Path(__file__).resolve().parents[1]


def test_readme_says_what_is_not_there_yet_and_the_units():
    text = (ROOT / "README.md").read_text()
    assert "## Not yet" in text
    section = text.split("## Not yet", 1)[1].split("\n## ", 1)[0]
    for word in ("URDF", "contact", "limits", "Coulomb", "Campbell", "sensor"):
        assert word in section, word
    assert "SI" in text and "lengths in m" in text


def _span_line(out):
    (line,) = [x for x in out.splitlines() if "length scale" in x]
    return float(line.split("the nodes span ", 1)[1].split(" m", 1)[0])


def test_check_prints_the_length_scale_so_millimetres_show(tmp_path):
    """The same four-bar written in metres and in millimetres: check's span is the diagonal of
    the nodes' bounding box, 1000 times larger for the second."""
    model = four_bar()
    x = np.array([n.position for n in model.nodes])
    f = tmp_path / "m.yaml"
    f.write_text(FOUR_BAR)
    span_m = _span_line(run("check", f).stdout)
    assert span_m == pytest.approx(np.linalg.norm(np.ptp(x, axis=0)), rel=1e-3)
    mm = FOUR_BAR
    for a, b in (("[0.0, 0.05, 0.0]", "[0.0, 50.0, 0.0]"), ("[0.1, 0.15, 0.0]", "[100, 150, 0]"),
                 ("[0.25, 0.1, 0.0]", "[250, 100, 0]"), ("at: [0, 0.1, 0]", "at: [0, 100, 0]"),
                 ("at: [0.2, 0.2, 0]", "at: [200, 200, 0]"),
                 ("at: [0.3, 0, 0]", "at: [300, 0, 0]")):
        assert a in mm
        mm = mm.replace(a, b)
    f.write_text(mm)
    assert _span_line(run("check", f).stdout) == pytest.approx(1000 * span_m, rel=1e-3)


def test_readme_energy_numbers_are_what_run_prints():
    """The README's slider-crank energy balance (index 2 and index 3) against a run of
    examples/slider_crank.yaml at its settings."""
    from se3dyn.io.modelfile import load_model

    text = " ".join((ROOT / "README.md").read_text().split())
    part = text.split("The energy balance error at h = 1e-2", 1)[1][:400]
    import re

    e2, scale, e3 = (float(v) for v in re.findall(r"(\d\.\d+e-\d+|0\.\d+) J", part)[:3])
    model, settings = load_model(ROOT / "examples" / "slider_crank.yaml")
    for form, err in (("index2", e2), ("index3", e3)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Se3dynWarning)
            st = sd.simulate(model, **dict(settings, formulation=form)).stats
        assert st["energy_balance_error"] == pytest.approx(err, rel=1e-3), form
        if form == "index2":
            assert st["energy_scale"] == pytest.approx(scale, rel=1e-3)


# ---------------------------------------------------------------------------------------------
# --quiet, CSV units, plot --x with equal axes
@pytest.fixture(scope="module")
def crank_file(tmp_path_factory):
    d = tmp_path_factory.mktemp("crank")
    p = run("run", ROOT / "examples" / "slider_crank.yaml", "--t-end", "2", "--out", d)
    assert p.returncode == 0, p.stderr
    return d / "slider_crank.h5"


def test_quiet_prints_no_summary_but_still_says_what_it_changed(tmp_path):
    (tmp_path / "four_bar.yaml").write_text(FOUR_BAR)
    p = run("run", tmp_path / "four_bar.yaml", "--out", tmp_path / "out", "--quiet")
    assert p.returncode == 0, p.stderr
    assert p.stdout == ""
    assert (tmp_path / "out" / "four_bar.h5").exists()
    # the initial velocities were completed to satisfy the joints: one line on stderr
    (line,) = p.stderr.strip().splitlines()
    assert line.startswith("se3dyn: warning: initial velocities projected")
    (tmp_path / "pulse.yaml").write_text(PULSE.format(stop=0.002))
    p = run("run", tmp_path / "pulse.yaml", "--out", tmp_path / "out", "--quiet")
    assert p.stdout == "" and "energy balance error" in p.stderr and "WARNING" in p.stderr


def test_csv_header_carries_the_units(crank_file, tmp_path):
    """Each column is labelled ``name [unit]`` in SI: node 6 starts at x = 0.1 m (Table 2), the
    hinge angle in rad, energies in J, Newton iterations dimensionless."""
    csv = tmp_path / "c.csv"
    p = run("export", crank_file, "--csv", csv, "node/6/position/x", "joint/1/alpha/0",
            "energy/kinetic", "solver/iterations")
    assert p.returncode == 0, p.stderr
    lines = csv.read_text().splitlines()
    assert lines[0].split(",") == ["time [s]", "node/6/position/x [m]", "joint/1/alpha/0 [rad]",
                                   "energy/kinetic [J]", "solver/iterations [1]"]
    first = [float(v) for v in lines[1].split(",")]
    assert first[1] == pytest.approx(0.1)


def test_plot_of_lengths_against_a_length_has_equal_axes(crank_file, tmp_path):
    """The crank's node 3 turns on a circle of radius 0.04 m about the x axis (Table 2: node 3
    at z = 0.16, hinge (1) at z = 0.12): plotted z against y it must come out round."""
    from PIL import Image

    png = tmp_path / "circle.png"
    p = run("plot", crank_file, "node/3/position/z", "--x", "node/3/position/y", "-o", png)
    assert p.returncode == 0, p.stderr
    img = np.asarray(Image.open(png).convert("RGB")).astype(int)
    curve = np.all(np.abs(img - [31, 119, 180]) < 40, axis=-1)  # matplotlib's first colour
    curve[:, int(0.8 * img.shape[1]):] = False  # the legend's swatch, right of the axes
    ys, xs = np.nonzero(curve)
    w, h = np.ptp(xs), np.ptp(ys)
    assert h > 100  # pixels: the circle fills the panel's height
    assert w == pytest.approx(h, rel=0.06)
