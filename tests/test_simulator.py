"""The stepping simulator (:class:`se3dyn.Simulator`, issue 30 item 5).

What is asserted (bit for bit against ``sd.simulate``, or against mechanics):

* Stepping to T in pieces (``advance`` several times, ``step`` repeatedly) gives the rows of
  ONE ``simulate`` to T bit for bit: frames, velocities, accelerations, multipliers (those
  of the condensed rigid joints too), coordinates, energies and works; at the defaults
  (compiled loop, rigid joints condensed, index 2), with ``output_every``, index 3, full
  Newton, the rigid joints kept; on the paper's slider-crank and on an arm with time-function
  actuators, a PD law, a follower load on a rigidly attached node and a marker.
* A state saved mid-run continues, after more steps and a restore, and in a new Simulator of
  the same model, exactly as the uninterrupted run.
* Inputs: a value held equal to the number the model's time function gives is the plain
  run, bit for bit (actuators, PD targets, loads); ``clear_input`` returns to the model's
  function; a held input acts from the next step on (zero-order hold); a rotor of inertia J
  under a constant held torque turns by ``tau t^2 / (2 J)`` to the integrator's accuracy and
  the actuator's work equals its kinetic energy.
* ``read`` gives what ``results()`` gives for the current row, for every kind of channel.
* Bad input names, shapes and values, times off the step grid or in the past, and foreign
  states are one-line errors naming what was wrong.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import se3dyn as sd
from se3dyn.dynamics.recorder import SCALARS

FIELDS = ("t", "H", "v", "vd", "lam", "alpha", "kinetic", "potential", "spring",
          "work_actuators", "work_loads", "dissipation", "iterations", "residual",
          "constraint")


def _same(a: sd.Results, b: sd.Results, rows=slice(None), rows_b=None):
    """Every stored array of two results equal bit for bit (rows ``rows`` of a against rows
    ``rows_b`` of b)."""
    rows_b = rows if rows_b is None else rows_b
    for f in FIELDS:
        x, y = getattr(a, f)[rows], getattr(b, f)[rows_b]
        assert x.shape == y.shape, f
        assert np.array_equal(x, y), f"{f} differs"


def arm(actuated: bool = True, held_load: bool = True) -> sd.Model:
    """Three links on hinges (time-function actuators or none), the last one with a PD law,
    the third link built of two nodes joined rigidly (condensed) carrying a follower load on
    the member node, and a marker."""
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81), name="arm3")
    mb.node("base", fixed=True)
    L = 0.4
    axes = ((0, 0, 1), (0, 1, 0), (0, 1, 0))
    prev = "base"
    for i in range(3):
        n = f"l{i + 1}"
        mb.node(n, position=(L * i + L / 2, 0.0, 0.0), mass=1.5,
                inertia=(1e-3, 0.02, 0.02))
        kw = {}
        if i < 2 and actuated:
            kw["actuator"] = sd.Sine(amplitude=0.8 + i, frequency=1.3, phase=0.2 * i)
        if i == 2:
            kw["control"] = sd.PD(kp=40.0, kd=2.0, target=sd.Ramp(0.5, 0.0, 1.0))
        mb.joint(f"j{i + 1}", "hinge", prev, n, axis=axes[i], at=(L * i, 0.0, 0.0), **kw)
        prev = n
    mb.node("tip", position=(3 * L, 0.0, 0.0), mass=0.3, inertia=(1e-4, 1e-4, 1e-4))
    mb.joint("fix", "rigid", "l3", "tip")
    if held_load:
        mb.load("push", "tip", force=sd.Sine(amplitude=(0.0, 2.0, 1.0), frequency=0.7),
                force_frame="body")
    mb.marker("m", "tip", at=(3 * L, 0.05, 0.0))
    return mb.build()


def _pieces(model, T, h, plan, **kw) -> sd.Simulator:
    sim = sd.Simulator(model, step=h, **kw)
    for p in plan:
        if p == "step":
            sim.step()
        elif isinstance(p, int):
            for _ in range(p):
                sim.step()
        else:
            sim.advance(p)
    sim.advance(T)
    return sim


# -- stepping in pieces is one simulate ------------------------------------------------------
@pytest.mark.parametrize("kw", [{}, dict(output_every=3), dict(formulation="index3"),
                                dict(newton="full"), dict(condense=False)],
                         ids=["defaults", "output_every", "index3", "full_newton", "kept"])
def test_slider_crank_in_pieces_is_one_simulate(kw):
    model = sd.examples.slider_crank()
    T, h = 2.5, 1e-2  # (the actuator switches off at 2 s: inside the run)
    ref = sd.simulate(model, T, h, **kw)
    sim = _pieces(model, T, h, [0.3, "step", 7, 0.5, 0.5, 1.0, 13, 2.0], **kw)
    assert sim.t == T == ref.t[-1]
    assert sim.steps == ref.stats["steps"]
    res = sim.results()
    _same(res, ref)
    assert res.stats["newton_iterations"] == ref.stats["newton_iterations"]
    assert res.stats["condensed"] == ref.stats["condensed"]
    assert res.stats["energy_balance_error"] == ref.stats["energy_balance_error"]
    fin, rfin = res.stats["final_state"], ref.stats["final_state"]
    for f in ("H", "HJ", "v", "vd", "a", "lam", "alpha", "power"):
        assert np.array_equal(getattr(fin, f), getattr(rfin, f)), f


def test_actuated_arm_in_pieces_is_one_simulate():
    """Sine actuators, a PD law on a ramp, a follower load on a condensed member node: the
    tabulated inputs and the condensed rigid joint's multipliers are those of simulate."""
    model = arm()
    T, h = 1.5, 2e-3
    ref = sd.simulate(model, T, h)
    assert ref.stats["condensed"] == ["fix"]
    sim = _pieces(model, T, h, [100, 0.4, "step", 0.9, 1.2])
    res = sim.results()
    _same(res, ref)
    assert np.any(res.joint_multipliers("fix") != 0)  # (the condensed joint's reactions)


def test_more_than_a_table_block_of_steps():
    """Steps across the blocks in which times and inputs are tabulated (1024 steps)."""
    model = arm()
    h = 1e-3
    ref = sd.simulate(model, 2.5, h)
    sim = _pieces(model, 2.5, h, [1.023, 1, 1.025, 2.047, 2.049])
    _same(sim.results(), ref)


# -- state and restore --------------------------------------------------------------------------
def test_restore_continues_bit_for_bit():
    model = arm()
    h, T = 2e-3, 1.2
    ref = sd.simulate(model, T, h)
    sim = sd.Simulator(model, step=h)
    sim.advance(0.5)
    saved = sim.state
    sim.advance(0.9)
    sim.restore(saved)
    assert sim.t == 0.5 and sim.steps == 250
    sim.advance(T)
    _same(sim.results(), ref)  # (the rows recorded up to the state kept)
    # in a new Simulator of the same model (its record starts at the state)
    other = sd.Simulator(model, step=h)
    other.restore(saved)
    other.advance(T)
    _same(other.results(), ref, slice(None), slice(250, None))


def test_restore_off_the_output_grid_and_with_held_inputs():
    """A state between stored rows (output_every) with inputs held: the continuation, here
    and in a new Simulator, is the uninterrupted one; the held inputs come with the state."""
    model = arm()
    h = 2e-3
    run = sd.Simulator(model, step=h, output_every=4)
    run.set_input("joint/j1/actuator", 0.3)
    run.advance(0.202)  # 101 steps: not a stored row
    saved = run.state
    run.set_input("load/push/force", [0.0, 0.0, -1.0])
    run.advance(0.5)
    whole = run.results()
    run.restore(saved)
    assert run.held.keys() == {"joint/j1/actuator"}
    run.set_input("load/push/force", [0.0, 0.0, -1.0])
    run.advance(0.5)
    _same(run.results(), whole, slice(-10, None))
    other = sd.Simulator(model, step=h, output_every=4)
    other.restore(saved)
    other.set_input("load/push/force", (0.0, 0.0, -1.0))
    other.advance(0.5)
    _same(other.results(), whole, slice(-10, None))
    assert other.results().t[0] == saved.t


def test_restore_the_current_state_changes_nothing():
    model = sd.examples.slider_crank()
    sim = sd.Simulator(model, step=1e-2, output_every=3)
    sim.advance(0.37)
    before = sim.results()
    sim.restore(sim.state)
    _same(sim.results(), before)
    sim.advance(1.0)
    _same(sim.results(), sd.simulate(model, 1.0, 1e-2, output_every=3))


def test_state_is_immutable():
    sim = sd.Simulator(sd.examples.slider_crank(), step=1e-2)
    sim.step()
    st = sim.state
    with pytest.raises(ValueError):
        st.state.v[0] = 1.0
    with pytest.raises(ValueError):
        st.row[0] = 1.0
    sim.step()
    assert st.t == 1e-2


# -- inputs ------------------------------------------------------------------------------------
def test_inputs_are_named_like_the_channels():
    sim = sd.Simulator(arm(), step=1e-3)
    assert sim.inputs == {"gravity": 3, "load/push/force": 3, "joint/j1/actuator": 1,
                          "joint/j2/actuator": 1, "joint/j3/target": 1,
                          "joint/j3/target_rate": 1}


def test_held_values_equal_to_the_time_functions_are_the_plain_run():
    """The paper's slider-crank is driven by 0.015 N m for 2 s: held at that number, and a
    PD target and a load held at their constant values, the run is simulate's."""
    model = sd.examples.slider_crank()
    ref = sd.simulate(model, 1.0, 1e-2)
    sim = sd.Simulator(model, step=1e-2)
    sim.set_input("joint/1/actuator", 0.015)
    sim.advance(0.5)
    sim.set_input("joint/1/actuator", np.array([0.015]))
    sim.advance(1.0)
    _same(sim.results(), ref)

    mb_args = dict(actuated=False, held_load=False)
    m2 = arm(**mb_args)
    ref2 = sd.simulate(m2, 0.6, 2e-3)
    sim2 = sd.Simulator(m2, step=2e-3)
    sim2.advance(0.2)
    sim2.set_input("gravity", (0.0, 0.0, -9.81))
    sim2.set_input("joint/j3/target", 0.5 * 0.2)  # (not the ramp: the rate held at 0 ...)
    sim2.clear_input("joint/j3/target")  # (... and cleared before any step: the model's)
    sim2.advance(0.6)
    _same(sim2.results(), ref2)


def test_clear_input_returns_to_the_time_function():
    model = sd.examples.slider_crank()
    ref = sd.simulate(model, 0.6, 1e-2)
    sim = sd.Simulator(model, step=1e-2)
    sim.set_input("joint/1/actuator", 0.2)
    sim.clear_input("joint/1/actuator")
    sim.advance(0.6)
    _same(sim.results(), ref)
    assert sim.held == {}


def test_a_held_input_acts_from_the_next_step_on():
    """Zero-order hold: the step after set_input sees the value; the state at which it was
    set does not change, and the actuator power of the next row is tau times the rate."""
    model = sd.examples.slider_crank()
    sim = sd.Simulator(model, step=1e-2)
    sim.advance(0.1)
    before = sim.read("joint/1/alpha/0"), sim.read("energy/work_actuators")
    sim.set_input("joint/1/actuator", 0.5)
    assert (sim.read("joint/1/alpha/0"), sim.read("energy/work_actuators")) == before
    assert sim.input_value("joint/1/actuator") == [0.015]  # (the model's: this state's)
    w0 = sim.read("joint/1/velocity/0")
    sim.step()
    w1 = sim.read("joint/1/velocity/0")
    assert sim.input_value("joint/1/actuator") == [0.5]
    # trapezoidal actuator work of the step: h/2 (p0 + p1), p1 = 0.5 w1 (the held torque)
    p0 = 0.015 * w0
    work = sim.read("energy/work_actuators") - before[1]
    assert work == pytest.approx(0.5 * 1e-2 * (p0 + 0.5 * w1), rel=1e-12)


def rotor(J: float = 0.05) -> sd.Model:
    """A disc on a hinge about its own axis through its centre of mass, no gravity."""
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    mb.node("ground", fixed=True)
    mb.node("disc", mass=1.0, inertia=(J, J / 2, J / 2))
    mb.joint("shaft", "hinge", "ground", "disc", axis=(1.0, 0.0, 0.0), actuator=0.0)
    return mb.build()


def test_rotor_under_a_held_torque():
    """J phi'' = tau from t0 = 0 on: phi = tau t^2 / (2 J), omega = tau t / J. The held torque
    acts from the first step (the initial acceleration is the model's, zero), which costs
    the second-order scheme one step's start: the errors fall as h (first order); and the
    actuator's work equals the kinetic energy (the energy balance of the run)."""
    J, tau, T = 0.05, 0.3, 1.0
    errs = []
    for h in (1e-2, 5e-3, 2.5e-3):
        sim = sd.Simulator(rotor(J), step=h)
        sim.set_input("joint/shaft/actuator", tau)
        sim.advance(T)
        phi, om = sim.read("joint/shaft/alpha/0"), sim.read("joint/shaft/velocity/0")
        errs.append((abs(phi - tau * T**2 / (2 * J)) / (tau * T**2 / (2 * J)),
                     abs(om - tau * T / J) / (tau * T / J)))
        kin, work = sim.read("energy/kinetic"), sim.read("energy/work_actuators")
        assert kin == pytest.approx(0.5 * J * om**2, rel=1e-12)
        assert work == pytest.approx(kin, rel=h * h)  # (second order: 2.6e-5 at h = 1e-2)
    e = np.array(errs)
    assert np.all(e < 0.05)
    rates = e[:-1] / e[1:]  # halving h: at least first order
    assert np.all(rates[:, 0] > 1.8), e


def test_rotor_energy_balance_closes_when_the_hold_starts_at_rest():
    """From the first step on the held torque gives a constant acceleration; once a second
    hold follows, kinetic energy = actuator work to the integrator's accuracy."""
    J = 0.05
    sim = sd.Simulator(rotor(J), step=1e-3)
    sim.set_input("joint/shaft/actuator", 0.2)
    sim.advance(0.5)
    sim.set_input("joint/shaft/actuator", -0.1)
    sim.advance(1.0)
    res = sim.results()
    bal = res.kinetic - res.work_actuators
    assert np.abs(bal).max() < 1e-3 * res.kinetic.max()


# -- read --------------------------------------------------------------------------------------
@pytest.mark.parametrize("ch", ["joint/j1/alpha/0", "joint/j2/velocity/0", "joint/j3/torque/0",
                                "joint/fix/multiplier/3", "joint/j2/reaction/inertial/fz",
                                "marker/m/position/y", "marker/m/accelerometer/z",
                                "node/tip/displacement/x", "node/l2/velocity/inertial/wz",
                                "energy/kinetic", "energy/balance", "solver/iterations",
                                "time"])
def test_read_is_the_results_channel_of_the_current_row(ch):
    from se3dyn.results.channels import get_channel

    sim = sd.Simulator(arm(), step=2e-3, output_every=5)
    sim.advance(0.3)
    sim.step()
    sim.set_input("joint/j1/actuator", 1.0)  # (changes nothing of the current row)
    assert sim.read(ch) == get_channel(sim.results(), ch)[-1]


def test_read_unknown_channel():
    sim = sd.Simulator(arm(), step=2e-3)
    with pytest.raises(KeyError, match="did you mean 'joint/j1/alpha/0'"):
        sim.read("joint/j1/alpa/0")


# -- errors ------------------------------------------------------------------------------------
def _one_line(exc_info) -> str:
    msg = str(exc_info.value)
    assert "\n" not in msg
    assert isinstance(exc_info.value, sd.Se3dynError)
    return msg


@pytest.mark.parametrize("name, value, says", [
    ("joint/j1/actuatr", 1.0, "did you mean 'joint/j1/actuator'"),
    ("joint/j3/actuator", 1.0, "joint 'j3' has no actuator"),
    ("joint/j1/actuator", [1.0, 2.0], "expected a number"),
    ("load/push/force", 1.0, "expected 3 number(s)"),
    ("load/push/force", [0.0, float("nan"), 0.0], "expected finite numbers"),
    ("joint/j1/actuator", math.inf, "expected finite numbers"),
    ("joint/j1/actuator", "fast", "expected 1 number(s)"),
])
def test_bad_inputs_are_one_line_errors_naming_the_input(name, value, says):
    sim = sd.Simulator(arm(), step=1e-3)
    with pytest.raises(sd.ModelError) as ei:
        sim.set_input(name, value)
    msg = _one_line(ei)
    assert name in msg and says in msg
    assert sim.held == {}
    with pytest.raises(sd.ModelError):
        sim.clear_input("gravit")


def test_times_off_the_grid_or_in_the_past():
    sim = sd.Simulator(arm(), step=1e-3, t_start=0.25)
    with pytest.raises(sd.ModelError) as ei:
        sim.advance(0.2505)
    assert "step grid" in _one_line(ei)
    sim.advance(0.3)
    with pytest.raises(sd.ModelError) as ei:
        sim.advance(0.29)
    assert "not before the current time" in _one_line(ei)
    with pytest.raises(sd.ModelError):
        sim.advance(float("nan"))
    sim.advance(0.3)  # (the current time: nothing to do)
    assert sim.steps == 50


def test_bad_settings_and_foreign_states():
    with pytest.raises(sd.ModelError, match="Simulator: field 'step'"):
        sd.Simulator(arm(), step=-1e-3)
    with pytest.raises(sd.ModelError, match="rho_inf"):
        sd.Simulator(arm(), step=1e-3, rho_inf=2.0)
    sim = sd.Simulator(arm(), step=1e-3)
    other = sd.Simulator(arm(), step=2e-3)
    other.step()
    with pytest.raises(sd.ModelError) as ei:
        sim.restore(other.state)
    assert "time grid" in _one_line(ei)
    with pytest.raises(sd.ModelError):
        sim.restore(other.state.state)
    slider = sd.Simulator(sd.examples.slider_crank(), step=1e-3)
    with pytest.raises(sd.ModelError):
        sim.restore(slider.state)


def test_a_failing_step_names_time_and_item_and_keeps_the_results():
    """A huge held torque makes Newton fail: the error is simulate's (NewtonError naming the
    time), the results up to the last converged step come with it, and the state is the
    last converged one."""
    sim = sd.Simulator(sd.examples.slider_crank(), step=1e-2, condense=False, max_iter=3)
    sim.advance(0.1)
    sim.set_input("joint/1/actuator", 1e7)
    with pytest.raises(sd.NewtonError) as ei:
        sim.step()
    assert "t=0.11" in str(ei.value)
    assert ei.value.result.t[-1] == 0.1 == sim.t
    assert len(SCALARS) == 9


def test_a_failing_condensed_step_goes_on_with_the_rigid_joints_kept():
    """As in simulate: the failing step is repeated on the model itself; when that fails too
    the error is raised, the rows so far are simulate's, and the simulator goes on (with the
    rigid joints kept) once the input is sane again."""
    model = sd.examples.slider_crank()
    ref = sd.simulate(model, 0.3, 1e-2, max_iter=3)
    sim = sd.Simulator(model, step=1e-2, max_iter=3)
    sim.advance(0.1)
    sim.set_input("joint/1/actuator", 1e7)
    with pytest.raises(sd.NewtonError):
        sim.step()
    assert sim.t == 0.1
    sim.set_input("joint/1/actuator", 0.015)
    sim.advance(0.3)
    res = sim.results()
    assert res.stats["condensed_until"] == 0.1
    _same(res, ref, slice(0, 11))
    assert not sim.state.condensed
    # the motion after it: the unreduced model's, within the O(h^2) by which the index-2
    # projection of a body split into rigidly joined nodes differs (docs/design.md)
    assert np.abs(res.H - ref.H).max() < 1e-5


def test_a_held_pd_target_is_a_fixed_set_point():
    """A PD law whose model target ramps (rate 0.05 rad/s) held at 0.3 rad: the rotor comes to
    rest at 0.3 (a held target's rate is 0); with the ramp's rate it would rest at
    0.3 + kd rate / kp = 0.3025. Holding the rate too moves the rest point there."""
    J, kp, kd = 0.05, 100.0, 5.0  # (critically damped: kd = 2 sqrt(kp J) = 4.47)
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    mb.node("ground", fixed=True)
    mb.node("disc", mass=1.0, inertia=(J, J / 2, J / 2))
    mb.joint("shaft", "hinge", "ground", "disc", axis=(1.0, 0.0, 0.0),
             control=sd.PD(kp=kp, kd=kd, target=sd.Ramp(0.5, 0.0, 10.0)))
    sim = sd.Simulator(mb.build(), step=1e-3)
    sim.set_input("joint/shaft/target", 0.3)
    sim.advance(1.5)
    assert sim.read("joint/shaft/alpha/0") == pytest.approx(0.3, abs=1e-9)
    assert abs(sim.read("joint/shaft/velocity/0")) < 1e-8
    sim.set_input("joint/shaft/target_rate", 0.05)
    sim.advance(3.0)
    assert sim.read("joint/shaft/alpha/0") == pytest.approx(0.3 + kd * 0.05 / kp, abs=1e-9)
    sim.clear_input("joint/shaft/target_rate")  # (the target still held: its rate 0 again)
    sim.advance(4.5)
    assert sim.read("joint/shaft/alpha/0") == pytest.approx(0.3, abs=1e-9)
