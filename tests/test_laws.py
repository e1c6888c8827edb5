"""Actuator laws of the user's, ``torque=lambda t, q, v: ...`` (sd.Law, issue 30).

References: the built-in PD law (a law written as the same formula must give its numbers), the
closed form of a rotor under PD (``scipy.linalg.expm``), the energy balance (the law's work is
the actuators' work), and a static balance solved by scipy's root finder.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.optimize as so

import se3dyn as sd
from se3dyn.errors import ModelError, NewtonError, Se3dynWarning
from se3dyn.io.modelfile import save_model

J, KP, KD, R = 0.5, 20.0, 4.0, 1.0


def _rotor(torque=None, control=None):
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("rotor", mass=1.0, inertia=(J, J, J))
    mb.joint("axle", "hinge", "g", "rotor", axis=(0, 0, 1), torque=torque, control=control)
    return mb.build()


def _run(model, t_end, h, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Se3dynWarning)
        return sd.simulate(model, t_end, h, **kw)


def pd_law(t, q, v):
    return -KP * (q - R) - KD * v


@pytest.mark.parametrize("law", [pd_law, sd.Law(pd_law, jacobian=lambda t, q, v: (
    np.array([[-KP]]), np.array([[-KD]])))], ids=["differences", "jacobian"])
def test_a_law_written_as_the_pd_formula_gives_the_pd_laws_motion(law):
    pd = _run(_rotor(control=sd.PD(KP, KD, target=R)), 2.0, 1e-2)
    res = _run(_rotor(torque=law), 2.0, 1e-2)
    np.testing.assert_allclose(res.joint_coordinates("axle"), pd.joint_coordinates("axle"),
                               rtol=0, atol=1e-11)
    # one Newton iteration a step, as the PD law (an exact tangent)
    assert res.stats["newton_iterations"] <= pd.stats["newton_iterations"] + 2
    A = np.array([[0.0, 1.0], [-KP / J, -KD / J]])
    errs = []
    for h in (1e-2, 5e-3, 2.5e-3):
        th = _run(_rotor(torque=law), 2.0, h).joint_coordinates("axle")[-1, 0]
        errs.append(abs(th - R - (sla.expm(A * 2.0) @ [-R, 0.0])[0]))
    assert np.all(np.log2(np.array(errs[:-1]) / np.array(errs[1:])) > 1.9), errs


def test_a_nonlinear_law_on_a_pendulum_balances_energy_and_statics():
    def law(t, q, v):  # a spring toward 0.4 rad, a cubic damper, a slow sine
        return -30.0 * np.sin(q - 0.4) - 0.5 * v ** 3 + 0.2 * math.sin(3 * t)

    mb = sd.ModelBuilder(gravity=(0, -9.81, 0))
    mb.node("g", fixed=True)
    mb.node("bar", (0.5, 0, 0), mass=2.0, inertia=(0.01, 0.1, 0.1))
    mb.joint("pin", "hinge", "g", "bar", axis=(0, 0, 1), at=(0, 0, 0), torque=law)
    model = mb.build()
    res = _run(model, 2.0, 1e-3)
    E = res.total_energy
    bal = E - E[0] + res.dissipation - res.work_actuators
    assert np.abs(bal).max() < 1e-4 * np.ptp(E)
    st = sd.static_equilibrium(model, t=0.0)
    q = st.joint_coordinates("pin")[0]
    ref = so.brentq(lambda x: -30.0 * math.sin(x - 0.4) - 2.0 * 9.81 * 0.5 * math.cos(x),
                    -1.0, 1.0)
    assert q == pytest.approx(ref, abs=1e-10)


def test_simulator_steps_a_law_as_simulate_does():
    model = _rotor(torque=pd_law)
    full = _run(model, 0.3, 1e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Se3dynWarning)
        sim = sd.Simulator(model, step=1e-3)
        sim.advance(0.1)
        sim.advance(0.3)
    assert np.array_equal(sim.results().H, full.H)


def test_a_failing_law_is_named_with_the_time_and_the_state():
    def law(t, q, v):
        if t > 0.05:
            raise RuntimeError("sensor lost")
        return -KP * q

    with pytest.raises(NewtonError, match=r"t=0\.06.*joint 'axle'.*RuntimeError: sensor lost"):
        _run(_rotor(torque=law), 0.1, 1e-2)


@pytest.mark.parametrize("torque, text", [
    (lambda t, q, v: [1.0, 2.0], "1 finite value"),
    (lambda t, q, v: 1 / 0, "ZeroDivisionError"),
    (lambda t, q, v: float("nan"), "finite"),
])
def test_bad_laws_are_refused_when_built(torque, text):
    with pytest.raises(ModelError, match=r"joint 'axle'.*torque") as e:
        _rotor(torque=torque)
    assert text in str(e.value)


def test_laws_on_joints_that_cannot_take_them_and_model_files():
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("b", mass=1.0, inertia=(1, 1, 1))
    with pytest.raises(ModelError, match="abelian"):
        mb.joint("ball", "spherical", "g", "b", torque=lambda t, q, v: -q)
    with pytest.raises(ModelError, match="universal"):
        mb.joint("u", "universal", "g", "b", axes=[(1, 0, 0), (0, 1, 0)],
                 torque=lambda t, q, v: -q)
    with pytest.raises(ModelError, match=r"joint 'axle'.*cannot be saved"):
        save_model(_rotor(torque=pd_law))
    # a function of t alone stays a time function
    model = _rotor(torque=lambda t: 0.5)
    assert model.joint("axle").law is None and model.joint("axle").actuator is not None
