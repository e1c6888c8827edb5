"""The compiled engine (se3dyn.fast) against the numpy reference implementation, and its Newton
variants against each other: same equations, same solution to the Newton tolerances.

The physics tests (conservation, convergence order, analytic solutions) run on the default
(compiled) engine; these tests check that the two implementations of Eqs. (38)-(46) agree and
that the fallbacks work.
"""

from __future__ import annotations

import numpy as np
import pytest

import se3dyn as sd
from se3dyn import fast, system
from se3dyn.errors import ModelError, NewtonError
from se3dyn.integrator import GeneralizedAlpha, step_inputs
from se3dyn.timefunc import Step


def _rich_model():
    """Every force element of Eqs. (60)-(67) on a small tree with offsets: springs, dampers,
    an actuator, a PD law, loads, gravity, a massless node."""
    mb = sd.ModelBuilder(gravity=(0.0, -9.81, 0.0), name="rich")
    mb.node("g", fixed=True)
    mb.node("a", position=(0.2, 0.0, 0.0), mass=1.0, inertia=(0.01, 0.02, 0.03),
            velocity=(0.0, 0.2, 0.0), angular_velocity=(0.0, 0.0, 1.0))
    mb.node("b", position=(0.5, 0.1, 0.0), mass=0.5, inertia=(0.004, 0.005, 0.006))
    mb.node("c", position=(0.5, 0.3, 0.1))
    mb.node("d", position=(0.5, 0.3, 0.1), mass=0.3, inertia=(0.001, 0.001, 0.001))
    mb.joint("h", "hinge", "g", "a", axis=(0.0, 0.0, 1.0), at=(0.0, 0.0, 0.0),
             stiffness=2.0, damping=0.05, torque=Step(0.3, 0.0, 0.5))
    mb.joint("s", "spherical", "a", "b", at=(0.4, 0.05, 0.0), damping=(0.01, 0.01, 0.01))
    mb.joint("r", "rigid", "b", "c")
    mb.joint("p", "cylindrical", "c", "d", axis=(0.0, 1.0, 0.0), stiffness=(10.0, 0.5),
             control=sd.PD(kp=(5.0, 0.0), kd=(0.5, 0.1), target=(0.01, 0.0)))
    mb.load("push", "b", force=lambda t: (0.1 * np.sin(3 * t), 0.0, 0.2),
            torque=(0.0, 0.01, 0.0))
    return mb.build()


MODELS = {"slider_crank": sd.examples.slider_crank,
          "slider_crank_bodies": sd.examples.slider_crank_bodies,
          "rich": _rich_model}


@pytest.mark.parametrize("formulation", ["index2", "index3"])
@pytest.mark.parametrize("name", list(MODELS))
def test_compiled_matches_numpy(name, formulation):
    s = sd.compile_model(MODELS[name]())
    kw = dict(t_end=0.6, step=1e-2, rho_inf=0.8, formulation=formulation)
    a = sd.simulate(s, engine="numpy", **kw)
    b = sd.simulate(s, engine="compiled", newton="full", **kw)
    c = sd.simulate(s, engine="compiled", **kw)
    assert a.stats["engine"] == "numpy" and b.stats["engine"] == "compiled"
    # full Newton in both: the same iterates up to round-off
    assert np.array_equal(a.iterations, b.iterations)
    # full Newton: round-off apart; modified Newton: apart by the Newton tolerances
    for x, y, tol in ((a, b, 1e-9), (a, c, 2e-8)):
        assert np.abs(x.H - y.H).max() < tol
        assert np.abs(x.v - y.v).max() < 100 * tol
        assert np.abs(x.alpha - y.alpha).max() < tol
        for f in ("kinetic", "potential", "spring", "work_actuators", "work_loads",
                  "dissipation"):
            assert np.abs(getattr(x, f) - getattr(y, f)).max() < tol * max(
                1.0, np.abs(getattr(x, f)).max()), f
        scale = max(np.abs(x.lam).max(), 1.0)
        assert np.abs(x.lam - y.lam).max() < 1000 * tol * scale


@pytest.mark.parametrize("index2", [False, True])
def test_kernel_values_match_numpy(index2):
    """Residual, constraints and iteration-matrix values of one iterate, element by element."""
    s = sd.compile_model(_rich_model())
    st = GeneralizedAlpha().init(s)
    rng = np.random.default_rng(3)
    n = 1e-2 * rng.standard_normal(s.nq)
    v, vd = rng.standard_normal(s.nq), rng.standard_normal(s.nq)
    lam = rng.standard_normal(s.nm)
    inp = step_inputs(s, 0.3)
    ev = system.evaluate(s, st.H, st.HJ, st.alpha, n, v, vd, lam, inp, full_alpha=False,
                         velocity=True)
    Adn = [sd.lie.adjoint_inv(st.HJ[g.ids]) for g in s.groups]
    coef = (1.0, 0.37, 0.021)
    ref = system.matrix_values(s, ev, coef, dict(cv=0.7, Adn=Adn) if index2 else None)
    F = fast.fast_system(s)
    Wk = F.work()
    for g, A in zip(s.groups, Adn, strict=True):
        Wk[7][g.ids] = A
    H, HJ = np.zeros_like(st.H), np.zeros_like(st.HJ)
    r, alpha = np.zeros(s.nq), np.zeros(s.nq)
    phi, psi = np.zeros(s.nm), np.zeros(s.nm)
    fs = fast._residual(F.S, Wk, st.H, st.HJ, st.alpha, n, v, vd, lam, inp["f"], inp["m"],
                        inp["tau"], inp["ref"], inp["rate"], True, H, HJ, r, phi, psi, alpha)
    assert fs == pytest.approx(ev.f_scale, rel=1e-14)
    assert np.abs(r - ev.r).max() < 1e-13 * ev.f_scale
    assert np.abs(phi - ev.phi).max() < 1e-15
    assert np.abs(psi - ev.psi).max() < 1e-13
    assert np.abs(H - ev.H).max() < 1e-15
    vals = np.zeros(system.pattern(s, index2)["nvals"])
    fast._values(F.S, Wk, n, HJ, v, lam, *coef, index2, 0.7, vals)
    keep = system.pattern(s, index2)["keep"]
    assert np.abs(vals[keep] - ref[keep]).max() < 1e-13 * np.abs(ref).max()


def test_energies_and_log_coordinates_match_numpy():
    from se3dyn.integrator import energies

    s = sd.compile_model(_rich_model())
    res = sd.simulate(s, 0.4, 1e-2, engine="numpy")
    st = res.stats["final_state"]
    inp = step_inputs(s, st.t)
    e = energies(s, st, inp)
    out = np.zeros(6)
    F = fast.fast_system(s)
    fast._energies(F.S, st.H, st.alpha, st.v, inp["f_load"], inp["m"], inp["tau"], inp["ref"],
                   inp["rate"], s.gravity, out)
    assert out[:3] == pytest.approx([e["kinetic"], e["potential"], e["spring"]], rel=1e-13)
    assert out[3:] == pytest.approx(e["power"], rel=1e-12, abs=1e-15)
    al = np.zeros(s.nq)
    fast._log_coordinates(F.S, st.HJ, al)
    nonab = np.concatenate([g.jdof[~g.abelian].ravel() for g in s.groups if g.k])
    assert np.abs(al[nonab] - st.alpha[nonab]).max() < 1e-14


def test_modified_newton_meets_the_same_tolerances():
    s = sd.compile_model(sd.examples.slider_crank_bodies())
    full = sd.simulate(s, 2.0, 1e-2, newton="full")
    mod = sd.simulate(s, 2.0, 1e-2)
    assert mod.residual.max() <= 1e-10 and mod.constraint.max() <= 1e-11 * s.length_scale
    assert mod.stats["factorizations"] < mod.stats["newton_iterations"]
    # the converged solutions differ by the Newton tolerance, not by the discretisation
    assert np.abs(full.H - mod.H).max() < 1e-7


def test_redundant_equations_are_dropped_in_the_compiled_engine():
    """Four-bar with all hinges parallel: 3 redundant equations; both engines agree."""
    mb = sd.ModelBuilder(gravity=(0.0, -9.81, 0.0))
    mb.node("g", fixed=True)
    mb.node("g2", position=(1.0, 0.0, 0.0), fixed=True)
    mb.node("c", position=(0.0, 0.25, 0.0), mass=1.0, inertia=(0.01, 0.01, 0.01),
            velocity=(-1.0, 0.0, 0.0), angular_velocity=(0.0, 0.0, 4.0))
    mb.node("r", position=(0.5, 0.5, 0.0), mass=1.0, inertia=(0.01, 0.1, 0.1),
            velocity=(-2.0, 0.0, 0.0))
    mb.node("f", position=(1.0, 0.25, 0.0), mass=1.0, inertia=(0.01, 0.01, 0.01),
            velocity=(-1.0, 0.0, 0.0), angular_velocity=(0.0, 0.0, 4.0))
    z = (0.0, 0.0, 1.0)
    mb.joint("A", "hinge", "g", "c", axis=z, at=(0.0, 0.0, 0.0))
    mb.joint("B", "hinge", "c", "r", axis=z, at=(0.0, 0.5, 0.0))
    mb.joint("C", "hinge", "r", "f", axis=z, at=(1.0, 0.5, 0.0))
    mb.joint("D", "hinge", "f", "g2", axis=z, at=(1.0, 0.0, 0.0))
    s = sd.compile_model(mb.build())
    a = sd.simulate(s, 0.5, 5e-3, engine="numpy")
    b = sd.simulate(s, 0.5, 5e-3)
    assert len(b.stats["redundant"]) == 3
    assert np.abs(a.H - b.H).max() < 1e-9
    assert b.constraint.max() < 1e-10


def test_non_abelian_springs_use_numpy_and_compiled_says_why():
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81))
    mb.node("g", fixed=True)
    mb.node("b", position=(0.1, 0.0, 0.0), mass=1.0, inertia=(0.01, 0.01, 0.01))
    mb.joint("s", "spherical", "g", "b", at=(0.0, 0.0, 0.0), stiffness=(1.0, 1.0, 1.0))
    s = sd.compile_model(mb.build())
    assert not fast.supported(s)
    res = sd.simulate(s, 0.05, 1e-2)
    assert res.stats["engine"] == "numpy"
    with pytest.raises(ModelError, match="engine"):
        sd.simulate(s, 0.05, 1e-2, engine="compiled")


def test_failed_step_is_reported_by_the_numpy_step_with_results_kept():
    """rho_inf = 1 on the index-3 form diverges (docs/accuracy.md): the compiled loop stops,
    the numpy step repeats the step and raises the named error with the results so far."""
    s = sd.compile_model(sd.examples.slider_crank())
    with pytest.raises(NewtonError) as exc:
        sd.simulate(s, 5.0, 1e-2, rho_inf=1.0, formulation="index3")
    res = exc.value.result
    assert res is not None and res.t[-1] > 0.5
    assert res.t[-1] == pytest.approx(exc.value.t - exc.value.h)


def test_per_step_paths_use_the_kernels():
    """Adaptive steps, dense output and callbacks go step by step through the kernels."""
    s = sd.compile_model(sd.examples.slider_crank_bodies())
    seen = []
    a = sd.simulate(s, 0.5, 1e-2, progress=lambda t, i: seen.append(t))
    b = sd.simulate(s, 0.5, 1e-2)
    assert len(seen) == 50
    assert np.abs(a.H - b.H).max() < 1e-8
    c = sd.simulate(s, 0.5, 1e-2, engine="numpy", output_step=0.05)
    d = sd.simulate(s, 0.5, 1e-2, output_step=0.05)
    assert np.abs(c.H - d.H).max() < 1e-8
