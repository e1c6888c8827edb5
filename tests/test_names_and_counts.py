"""Names other tools use for joint types, counts as the model file gives them, a readable list of
redundant equations (issue 16, section 5)."""

from __future__ import annotations

import subprocess
import sys

import pytest

import se3dyn as sd
from se3dyn.errors import ModelError
from se3dyn.modelfile import loads_model

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
