"""Names other tools use for joint types, counts as the model file gives them, a readable list of
redundant equations (issue 16, section 5)."""

from __future__ import annotations

import subprocess
import sys

import pytest

import se3dyn as sd
from se3dyn.errors import ModelError
from se3dyn.io.modelfile import loads_model

CLI = [sys.executable, "-m", "se3dyn.cli"]


@pytest.mark.parametrize("other, ours", [("revolute", "hinge"), ("ball", "spherical"),
                                         ("slider", "prismatic"), ("fixed", "rigid"),
                                         ("helical", "screw")])
def test_the_joint_names_of_other_tools_are_synonyms(other, ours):
    params = {"hinge": dict(axis=(0, 1, 0)), "prismatic": dict(axis=(1, 0, 0)),
              "screw": dict(axis=(0, 0, 1), pitch=0.01)}.get(ours, {})
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("b", position=(0, 0, -1), mass=1.0, inertia=(1, 1, 1))
    mb.joint("j", other, "g", "b", **params)
    assert mb.build().joint("j").type == ours


def test_a_misspelt_synonym_is_named_with_the_se3dyn_type():
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("b", position=(0, 0, -1), mass=1.0, inertia=(1, 1, 1))
    with pytest.raises(ModelError, match="did you mean 'revolute' \\(se3dyn's 'hinge'\\)"):
        mb.joint("j", "revolut", "g", "b", axis=(0, 1, 0))


def test_check_counts_a_universal_joint_as_one_joint_and_no_node(tmp_path):
    f = tmp_path / "u.yaml"
    f.write_text("""se3dyn: 1
nodes:
  g: {fixed: true}
  shaft: {position: [0, 0, -0.5], mass: 1.0, inertia: [0.1, 0.1, 0.01]}
joints:
  u: {type: cardan, a: g, b: shaft, axes: [[1, 0, 0], [0, 1, 0]], at: [0, 0, 0]}
""")
    m, _ = loads_model(f.read_text())
    assert len(m.nodes) == 3 and len(m.joints) == 2  # the cross node, two hinges inside
    p = subprocess.run([*CLI, "check", str(f)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    assert "2 nodes (1 free, 1 with mass), 1 joints" in p.stdout


def test_a_long_list_of_redundant_equations_is_wrapped_and_cut(tmp_path):
    # a box held by 4 spherical joints at its corners: 12 constraint equations, 6 freedoms
    lines = ["se3dyn: 1", "nodes:", "  g: {fixed: true}",
             "  box: {mass: 1.0, inertia: [0.1, 0.1, 0.1]}", "joints:"]
    for i in range(12):
        lines.append(f"  s{i}: {{type: ball, a: g, b: box, at: [{0.1 * i}, {0.05 * i % 0.3},"
                     f" {0.02 * i}]}}")
    f = tmp_path / "box.yaml"
    f.write_text("\n".join(lines) + "\n")
    p = subprocess.run([*CLI, "check", str(f)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    assert "redundant constraint equations (" in p.stdout
    assert max(len(line) for line in p.stdout.splitlines()) <= 110
    assert "more" in p.stdout  # 36 - 6 + ... > 24: the list is cut


def test_info_tells_a_complete_run_from_a_failed_one(tmp_path):
    ok = tmp_path / "ok.yaml"
    ok.write_text("""se3dyn: 1
nodes:
  g: {fixed: true}
  bob: {position: [0.5, 0, 0], mass: 1.0, inertia: [0.001, 0.001, 0.001]}
joints:
  h: {type: revolute, a: g, b: bob, axis: [0, 1, 0], at: [0, 0, 0]}
gravity: [0, 0, -9.81]
simulation: {t_end: 0.2, step: 0.01}
""")
    bad = tmp_path / "bad.yaml"  # Newton fails: a one-iteration budget
    bad.write_text(ok.read_text().replace("step: 0.01}", "step: 0.01, max_iter: 1}"))
    for f in (ok, bad):
        subprocess.run([*CLI, "run", str(f), "--out", str(tmp_path / "o"), "--quiet"],
                       capture_output=True, text=True)
    p = subprocess.run([*CLI, "info", str(tmp_path / "o" / "ok.h5")], capture_output=True,
                       text=True)
    assert p.returncode == 0, p.stderr
    assert "status: complete: t = 0 .. 0.2 s" in p.stdout and "Newton iterations" in p.stdout
    assert "settings: " in p.stdout and "t_end=0.2" in p.stdout
    p = subprocess.run([*CLI, "info", str(tmp_path / "o" / "bad.h5")], capture_output=True,
                       text=True)
    assert p.returncode == 0, p.stderr
    assert "status: failed at t = 0" in p.stdout and "max_iter" in p.stdout


def test_types_lists_every_joint_type_and_element_section():
    from se3dyn.io.modelfile import ELEMENT_SECTIONS
    from se3dyn.model.joint_types import JOINT_TYPES

    p = subprocess.run([*CLI, "types"], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    for key in [*JOINT_TYPES, "universal"]:
        assert f"\n  {key} " in p.stdout
    for es in ELEMENT_SECTIONS:
        assert f"\n  {es.key}: " in p.stdout
    assert "also called revolute" in p.stdout


def test_plot_writes_where_it_says_and_refuses_what_it_cannot_write(tmp_path):
    model = tmp_path / "p.yaml"
    model.write_text("""se3dyn: 1
nodes:
  g: {fixed: true}
  bob: {position: [0.5, 0, 0], mass: 1.0, inertia: [0.001, 0.001, 0.001]}
joints:
  h: {type: hinge, a: g, b: bob, axis: [0, 1, 0], at: [0, 0, 0]}
gravity: [0, 0, -9.81]
simulation: {t_end: 0.5, step: 0.01}
""")
    subprocess.run([*CLI, "run", str(model), "--out", str(tmp_path), "--quiet"], check=True,
                   capture_output=True)
    h5 = str(tmp_path / "p.h5")
    figs = tmp_path / "figs"
    figs.mkdir()
    # a folder gets the default name inside it; panels per unit; an x-y plot
    p = subprocess.run([*CLI, "plot", h5, "joint/h/alpha/0", "node/bob/position/[xz]",
                        "-o", str(figs)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    assert (figs / "p.png").stat().st_size > 0
    p = subprocess.run([*CLI, "plot", h5, "node/bob/position/z", "--x", "node/bob/position/x",
                        "-o", str(tmp_path / "xy.svg")], capture_output=True, text=True)
    assert p.returncode == 0 and (tmp_path / "xy.svg").read_text().startswith("<?xml")
    p = subprocess.run([*CLI, "plot", h5, "joint/h/alpha/0", "-o", str(tmp_path / "f.xyz")],
                       capture_output=True, text=True)
    assert p.returncode == 2 and "f.xyz" in p.stderr and "Traceback" not in p.stderr
    assert not (tmp_path / "f.xyz").exists() and not (tmp_path / "f.xyz.png").exists()
