"""The spatial slider-crank of Sec. 11 of the multibody paper with a flexible connecting rod
(``examples/slider_crank_flexible.yaml``, issue 13): the rigid limit and the energy balance.

Multibody paper: V. Sonneville, O. Bruls, "A formulation on the special Euclidean group for
dynamic analysis of multibody systems", J. Comput. Nonlinear Dynam. 9(4) (2014) 041002,
doi:10.1115/1.4026569. Beam: V. Sonneville, A. Cardona, O. Bruls, Comput. Methods Appl. Mech.
Engrg. 268 (2014) 451-474, doi:10.1016/j.cma.2013.10.008.

The rigid counterpart is the same model with the rod's beam nodes welded by rigid joints
(consecutive nodes): the rigid slider-crank with exactly the rod's lumped mass distribution, so
that the difference to it is the rod's compliance only. (The paper's rigid rod of Table 3 has
another inertia tensor, (4e-3, 4e-4, 4e-3) kg m^2 about inertial axes; the example script
compares with it.)
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

import se3dyn as sd
from se3dyn.io.modelfile import load_model, loads_model

ROOT = Path(__file__).resolve().parents[1]
FLEX_YAML = ROOT / "examples" / "slider_crank_flexible.yaml"
T_END = 1.0
RHO = 0.9


def _script() -> list[str]:
    """The installed ``se3dyn`` command (as tests/test_cli.py finds it)."""
    exe = Path(sys.executable).parent / "se3dyn"
    if exe.exists():
        return [str(exe)]
    found = shutil.which("se3dyn")
    return [found] if found else [sys.executable, "-m", "se3dyn.cli"]


def _model(stiffness_factor: float = 1.0, rigid: bool = False):
    """The example model with EA, GA, GJ, EI of the rod scaled by ``stiffness_factor`` (E and G
    scaled alike), or with its beam nodes welded together (``rigid``)."""
    d = yaml.safe_load(FLEX_YAML.read_text())
    rod = d["beams"]["rod"]
    for k in ("EA", "GA", "GJ", "EI"):
        rod[k] = float(rod[k] * stiffness_factor)
    if rigid:
        n = rod["elements"]
        names = [rod["a"]] + [f"rod/{i}" for i in range(1, n)] + [rod["b"]]
        for i in range(n):
            d["joints"][f"weld{i}"] = {"type": "rigid", "a": names[i], "b": names[i + 1]}
    return loads_model(yaml.safe_dump(d))[0]


def _run(model, h, t_end=T_END):
    return sd.simulate(model, t_end=t_end, step=h, rho_inf=RHO)


def test_example_file_loads_checks_and_runs_with_its_settings(tmp_path):
    """The model file as shipped: `se3dyn check` passes (no redundant constraints, one beam of
    4 elements) and `se3dyn run` runs its 5 s; the rod weighs the 0.5 kg of Table 3 to 0.3 %."""
    chk = subprocess.run([*_script(), "check", str(FLEX_YAML)],
                         capture_output=True, text=True, timeout=120)
    assert chk.returncode == 0, chk.stdout + chk.stderr
    assert "beams: 1 with 4 elements" in chk.stdout
    assert "no redundant constraints" in chk.stdout
    run = subprocess.run([*_script(), "run", str(FLEX_YAML), "--out",
                          str(tmp_path), "--quiet"], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    assert (tmp_path / "slider_crank_flexible.h5").exists()
    _, settings = load_model(FLEX_YAML)
    rod = yaml.safe_load(FLEX_YAML.read_text())["beams"]["rod"]
    length = np.linalg.norm(np.subtract([0.2, 0.0, 0.0], [0.0, 0.1, 0.2]))
    assert abs(rod["mass_per_length"] * length - 0.5) < 0.0015
    assert settings["t_end"] == 5.0 and settings["rho_inf"] == 0.9

    # beam channels of the results file (the file's model text is compiled for them) equal the
    # section forces of the same run in memory
    from se3dyn.elements.beam import section_forces
    from se3dyn.io.h5 import read_results
    from se3dyn.results.channels import get_channel, list_channels

    fres = read_results(tmp_path / "slider_crank_flexible.h5")
    names = list_channels(fres)
    for e in range(4):
        assert f"beam/rod/{e}/force/N" in names and f"beam/rod/{e}/energy" in names
    model, _ = load_model(FLEX_YAML)
    mem = sd.simulate(model, **settings)
    ref = section_forces(mem.system, mem.H, vq=mem.v)
    for e in (0, 3):
        for q, c, col in (("force", "N", 0), ("force", "M3", 5), ("strain", "k2", 4)):
            x = get_channel(fres, f"beam/rod/{e}/{q}/{c}")
            y = ref[q][:, e, col]
            assert np.abs(x - y).max() <= 1e-9 * (np.abs(y).max() + 1e-30)
        np.testing.assert_allclose(get_channel(fres, f"beam/rod/{e}/energy"),
                                   ref["energy"][:, e], rtol=1e-9, atol=1e-18)


def test_stiffer_rod_converges_to_the_rigid_slider_crank_like_one_over_E():
    """E (and G) x 1, 10, 100 from 0.7 GPa to the file's 70 GPa aluminium: the crank angle
    (hinge (1)) and slider position (node 8) differ from the rigid counterpart's by amounts
    that fall by ~10 per factor 10 (quasi-static compliance, first order in 1/E), as does the
    rod's midpoint deflection from its chord. A small step (h = 1/6400 s, same for both) keeps
    the time-discretization difference between the stiff and the rigid model (O(h^2), ~5e-6
    rad here) below the compliance effect."""
    h = 1.0 / 6400.0
    rig = _run(_model(rigid=True), h)
    a_r = rig.joint_coordinates("1")[:, 0]
    x_r = rig.node_position("8")[:, 0]
    assert a_r[-1] > 1.0  # the crank has turned (the torque acts for t < 2 s)
    da, dx, mid = [], [], []
    for f in (0.01, 0.1, 1.0):
        res = _run(_model(f), h)
        da.append(np.abs(res.joint_coordinates("1")[:, 0] - a_r).max())
        dx.append(np.abs(res.node_position("8")[:, 0] - x_r).max())
        chord_mid = 0.5 * (res.node_position("5") + res.node_position("7"))
        mid.append(np.linalg.norm(res.node_position("rod/2") - chord_mid, axis=1).max())
    for d in (da, dx, mid):
        r1, r2 = d[0] / d[1], d[1] / d[2]
        assert 6.0 < r1 < 16.0 and 6.0 < r2 < 16.0, d
    assert da[-1] < 1e-4 and dx[-1] < 3e-6  # the aluminium rod: nearly rigid


def test_energy_balance_of_the_flexible_slider_crank_converges_with_the_step():
    """Kinetic + gravity potential + elastic energy - crank torque work + damping dissipation
    (cylindrical joint (8)) is constant for the exact solution; the generalized-alpha scheme
    (rho_inf = 0.9) keeps it to O(h^2): the error falls by ~4 per halving of h, and stays a
    small part of the mechanism's energy."""
    errs = []
    for h in (0.004, 0.002, 0.001):
        res = _run(_model(), h)
        assert res.spring.max() > 0.0  # the rod's elastic energy enters the balance
        errs.append(np.ptp(res.energy_balance))
        scale = np.abs(res.total_energy).max() + np.abs(res.work_actuators).max()
        assert errs[-1] < 2e-2 * scale
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(orders > 1.6), (errs, orders)


@pytest.mark.parametrize("h", [0.005])
def test_rod_section_forces_stay_small_and_finite(h):
    """Beam outputs over a run of the example: the axial force stays within what the mechanism
    can load the rod with (a few newtons here: crank torque 0.015 N m on a 0.04 m crank, 2 kg
    slider, 1 N s/m damper, gravity), not the round-off of EA ~ 4e7 N."""
    from se3dyn.elements.beam import section_forces

    res = _run(_model(), h)
    out = section_forces(res.system, res.H, vq=res.v)
    N = out["force"][..., 0]
    assert np.isfinite(N).all()
    assert np.abs(N).max() < 100.0
    assert np.abs(N).max() > 1e-3
