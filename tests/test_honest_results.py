"""Results that do not mislead (issue 16, section 1): initial velocities the joints do not
allow are reported (stats, warning, run summary) or refused (strict); a large energy balance
error is reported against the energy exchanged in the run."""

from __future__ import annotations

import math
import subprocess
import sys
import warnings

import numpy as np
import pytest

import se3dyn as sd
from se3dyn.errors import ModelError, Se3dynWarning


def _hinged_wheel(omega):
    """A wheel on a hinge about z through its centre, given the angular velocity ``omega``."""
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("wheel", mass=2.0, inertia=(0.5, 0.5, 1.0), angular_velocity=omega)
    mb.joint("axle", "hinge", "g", "wheel", axis=(0, 0, 1))
    return mb.build()


def test_an_angular_velocity_out_of_the_hinge_plane_is_projected_and_reported():
    # given w = (1, 0, 3): the hinge allows w_z only; the projection keeps the consistent part
    # (the body velocities are held where the constraints allow: the least-squares projection
    # in the mass metric removes w_x): used (0, 0, 3), kinetic energy 0.5 * 1.0 * 9 = 4.5 J
    with pytest.warns(Se3dynWarning, match="'wheel'"):
        res = sd.simulate(_hinged_wheel((1.0, 0.0, 3.0)), t_end=0.1, step=1e-2)
    ch = res.stats["initial_velocity_changes"]
    assert [c["node"] for c in ch] == ["wheel"]
    assert ch[0]["dw"] == pytest.approx(1.0, rel=1e-9)
    assert np.allclose(ch[0]["used"], [0, 0, 0, 0, 0, 3.0], atol=1e-9)
    assert res.stats["initial_kinetic_energy_given"] == pytest.approx(0.5 * (0.5 + 9.0))
    assert res.stats["initial_kinetic_energy_used"] == pytest.approx(4.5)
    assert res.kinetic[0] == pytest.approx(4.5)


def test_strict_initial_velocities_are_refused_with_the_node_named():
    with pytest.raises(ModelError, match="node 'wheel'.*velocity"):
        sd.simulate(_hinged_wheel((1.0, 0.0, 3.0)), t_end=0.1, step=1e-2,
                    initial_velocities="strict")
    # consistent velocities pass strict, and nothing is reported
    with warnings.catch_warnings():
        warnings.simplefilter("error", Se3dynWarning)
        res = sd.simulate(_hinged_wheel((0.0, 0.0, 3.0)), t_end=0.1, step=1e-2,
                          initial_velocities="strict")
    assert res.stats["initial_velocity_changes"] == []


def test_a_large_energy_balance_error_is_reported_against_the_energy_exchanged():
    """A spring-mass at h = T/10 with rho_inf = 0 loses nearly all its energy to the scheme's
    numerical dissipation within 10 periods (no damper: the true motion keeps it)."""
    k, m = 40.0, 2.0
    T = 2 * math.pi / math.sqrt(k / m)

    def model():
        mb = sd.ModelBuilder()
        mb.node("g", fixed=True)
        mb.node("m", position=(0.8, 0, 0), mass=m, inertia=(1e-2, 1e-2, 1e-2))
        mb.spring_damper("s", "g", "m", stiffness=k, length=0.5)
        mb.joint("slide", "prismatic", "g", "m", axis=(1, 0, 0))
        return mb.build()

    with pytest.warns(Se3dynWarning, match="energy balance error"):
        bad = sd.simulate(model(), t_end=10 * T, step=T / 10, rho_inf=0.0)
    E0 = 0.5 * k * 0.3 ** 2
    assert bad.stats["energy_scale"] == pytest.approx(E0, rel=0.05)
    assert bad.stats["energy_balance_error"] > 0.9 * E0
    with warnings.catch_warnings():
        warnings.simplefilter("error", Se3dynWarning)
        good = sd.simulate(model(), t_end=10 * T, step=T / 200, rho_inf=1.0)
    assert good.stats["energy_balance_error"] < 1e-3 * good.stats["energy_scale"]


def test_the_run_summary_reports_projected_velocities_and_strict_refuses(tmp_path):
    f = tmp_path / "wheel.yaml"
    f.write_text("""se3dyn: 1
nodes:
  g: {fixed: true}
  wheel: {mass: 2.0, inertia: [0.5, 0.5, 1.0], angular_velocity: [1.0, 0.0, 3.0]}
joints:
  axle: {type: hinge, a: g, b: wheel, axis: [0, 0, 1]}
simulation: {t_end: 0.1, step: 0.01}
""")
    cli = [sys.executable, "-m", "se3dyn.cli"]
    p = subprocess.run([*cli, "run", str(f), "--out", str(tmp_path / "o")],
                       capture_output=True, text=True)  # (not --quiet: the summary is read)
    assert p.returncode == 0, p.stderr
    assert "initial velocities projected" in p.stdout and "'wheel'" in p.stdout
    assert "Warning" not in p.stderr  # reported once, in the summary
    p = subprocess.run([*cli, "run", str(f), "--out", str(tmp_path / "o2"), "--quiet",
                        "--initial-velocities", "strict"], capture_output=True, text=True)
    assert p.returncode == 2
    assert "node 'wheel'" in p.stderr and p.stderr.count("\n") <= 2


@pytest.mark.parametrize("text, expect", [
    # a ground node without fixed: true: the hinge lets it float with no mass
    ("""se3dyn: 1
nodes:
  ground: {}
  arm: {position: [0.5, 0, 0], mass: 1.0, inertia: [0.01, 0.1, 0.1]}
joints:
  h: {type: hinge, a: ground, b: arm, axis: [0, 1, 0], at: [0, 0, 0]}
""", "node 'ground'"),
    ("""se3dyn: 1
nodes:
  g: {fixed: true}
  arm: {position: [0.5, 0, 0], mass: 1.0, inertia: [0.01, 0.1, 0.1]}
joints:
  h: {type: hinge, a: g, b: arm, axis: [0, 1, 0], at: [0, 0, 0]}
simulation: {t_start: 2.0, t_end: 1.0, step: 0.01}
""", "t_end"),
    ("""se3dyn: 1
nodes:
  g: {fixed: true}
  arm: {position: [0.5, 0, 0], mass: 1.0, inertia: [0.01, 0.1, 0.1]}
joints:
  h: {type: hinge, a: g, b: arm, axis: [0, 1, 0], at: [0, 0, 0]}
simulation: {t_end: 1.0, step: 0.01, tol: 1.0e-6, h_min: 0.1, h_max: 0.01}
""", "h_min"),
    ("""se3dyn: 1
nodes:
  g: {fixed: true}
  arm: {position: [0.5, 0, 0], mass: 1.0, inertia: [0.01, 0.1, 0.1],
        angular_velocity: [0, 0, 2.0]}
joints:
  h: {type: hinge, a: g, b: arm, axis: [0, 1, 0], at: [0, 0, 0]}
simulation: {t_end: 1.0, step: 0.01, initial_velocities: strict}
""", "node 'arm'"),
])
def test_check_finds_what_run_would_refuse_at_t0(tmp_path, text, expect):
    f = tmp_path / "m.yaml"
    f.write_text(text)
    cli = [sys.executable, "-m", "se3dyn.cli"]
    chk = subprocess.run([*cli, "check", str(f)], capture_output=True, text=True)
    assert chk.returncode == 2, chk.stdout
    assert expect in chk.stderr and "Traceback" not in chk.stderr
    run = subprocess.run([*cli, "run", str(f), "--out", str(tmp_path / "o"), "--quiet"],
                         capture_output=True, text=True)
    assert run.returncode != 0  # run refuses it too
