"""Compliant contact (se3dyn.elements.contact, docs/contact.md) against closed forms of rigid
bodies: the exact restitution of the damping law for any stiffness and impact speed, the apex
heights of a bouncing ball, Coulomb's stick and slide on an incline, a sphere rolling down an
incline and a spinning ball dropped on the floor; no energy gain at any step a user would pick;
errors on bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

import se3dyn as sd
from se3dyn.errors import ModelError
from se3dyn.model.contact import contact_pairs, restitution_constant

G = 9.81
R = 0.1


def ball(e=0.5, k=1e10, h0=1.0, v0=0.0, g=G, mu=0.0, spin=0.0):
    """A ball of radius R and 1 kg (solid sphere) at h0 above a floor, falling at v0."""
    mb = sd.ModelBuilder(gravity=(0, 0, -g))
    mb.node("ground", fixed=True)
    mb.node("ball", position=(0, 0, h0 + R), mass=1.0, inertia=(0.4 * R * R,) * 3,
            velocity=(0, 0, v0), angular_velocity=(0, spin, 0))
    mat = sd.ContactMaterial(stiffness=k, restitution=e, friction=mu)
    mb.collision("floor", "ground", "plane", material=mat)
    mb.collision("ball", "ball", "sphere", size=R, material=mat)
    return mb.build()


def test_the_damping_constant_solves_the_restitution_equation():
    """c(e) is the root of c - ln(1 + c) = -c e - ln(1 - c e) (Carvalho & Martins 2019): the
    rebound of m x'' = -k x^n (1 + c x'/v) is e v; checked by scipy's ODE solver."""
    from scipy.integrate import solve_ivp

    for e in (0.1, 0.5, 0.9):
        c = restitution_constant(e)
        assert abs(c - math.log1p(c) + c * e + math.log1p(-c * e)) < 1e-12
        for k, v in ((1e5, 0.3), (1e9, 7.0)):
            def f(t, y, k=k, v=v, c=c):
                return [y[1], -k * max(y[0], 0) ** 1.5 * max(0.0, 1 + c * y[1] / v)]

            def apart(t, y):
                return y[0]
            apart.terminal, apart.direction = True, -1
            sol = solve_ivp(f, [0, 10], [0, v], events=apart, rtol=1e-12, atol=1e-15,
                            first_step=1e-9)
            assert abs(-sol.y_events[0][0][1] / v - e) < 1e-8


@pytest.mark.parametrize("e", [0.1, 0.3, 0.5, 0.8, 1.0])
def test_effective_restitution_is_the_requested_one_for_any_stiffness_and_speed(e):
    """Without gravity the ball leaves the floor at e times its impact speed (within 5e-3),
    whatever the stiffness (1e5 to 1e10 N/m^1.5) and speed (0.1 to 10 m/s), at h = 1 ms
    (the contact-aware substeps resolve the contact)."""
    for k in (1e5, 1e10):
        for v in (0.1, 10.0):
            res = sd.simulate(ball(e=e, k=k, h0=0.01, v0=-v, g=0.0), 0.03 / v + 0.1, 1e-3)
            vout = res.node_velocity("ball", "inertial")[-1, 2]
            assert abs(vout / v - e) < 5e-3, (e, k, v, vout / v)


def _flight_apexes(res):
    """Apex heights of the flights: z + vz^2 / (2 g) at the middle row of each flight (exact
    in free flight, which the scheme integrates exactly under constant gravity)."""
    z = res.node_position("ball")[:, 2] - R
    vz = res.node_velocity("ball", "inertial")[:, 2]
    up = np.where((z > 0) & (vz > 0))[0]
    flights = np.split(up, np.where(np.diff(up) > 1)[0] + 1)
    return [float(z[f[-1]] + vz[f[-1]] ** 2 / (2 * G)) for f in flights if len(f)]


def _law_apexes(e, k, n=2):
    """Apexes of the compliant law itself (1 kg, 1 m drop) with gravity acting during the
    contacts, by scipy's ODE solver (an independent reference)."""
    from scipy.integrate import solve_ivp

    c, out, vin = restitution_constant(e), [], math.sqrt(2 * G)
    for _ in range(n):
        def f(t, y, vin=vin):
            d = max(-y[0], 0.0)
            return [y[1], -G + k * d ** 1.5 * max(0.0, 1 - c * y[1] / vin)]

        def apart(t, y):
            return y[0]
        apart.terminal, apart.direction = True, 1
        sol = solve_ivp(f, [0, 1], [0.0, -vin], events=apart, rtol=1e-12, atol=1e-14,
                        max_step=1e-5)
        vin = sol.y_events[0][0][1]
        out.append(vin ** 2 / (2 * G))
    return out


def test_bouncing_ball_apex_heights():
    """1 m drop, e = 0.5: apexes e^2 = 0.25 and e^4 = 0.0625 m. The compliant law itself
    (scipy) reaches them within the finite contact time's share: gravity acts during the
    contact t_c (Hertz: 3.2145 (m/k)^(2/5) v^(-1/5)) and changes the rebound speed by up to
    g t_c, the apex by up to v_out t_c (1.9e-4 and 1.5e-4 m at k = 1e10 N/m^1.5). se3dyn at
    h = 1 ms is within 0.5 % of the law's apexes (the restitution's discretisation error,
    <= 1e-3 per impact, twice for a height, over two impacts)."""
    k = 1e10
    res = sd.simulate(ball(e=0.5, k=k), 1.1, 1e-3)
    apex, law = _flight_apexes(res), _law_apexes(0.5, k)
    vin = math.sqrt(2 * G)
    for i, ref in enumerate((0.25, 0.0625)):
        tc = 3.2145 * (1.0 / k) ** 0.4 * vin ** -0.2
        assert abs(law[i] - ref) <= 0.5 * vin * tc, (i, law[i], ref, 0.5 * vin * tc)
        assert abs(apex[i] / law[i] - 1) <= 5e-3, (i, apex[i], law[i])
        vin *= 0.5


@pytest.mark.parametrize("h", [1e-2, 5e-3, 2e-3, 1e-3, 1e-4])
def test_no_energy_gain_at_any_fixed_step(h):
    """The energy of the bouncing ball never exceeds its initial energy, for stiffnesses from
    1e6 to 1e10 N/m^1.5 and fixed steps from 0.1 to 10 ms (without the contact-aware steps: up to
    900 times the energy at h = 10 ms)."""
    for k in (1e6, 1e8, 1e10):
        res = sd.simulate(ball(e=0.5, k=k), 1.5, h)
        E = res.total_energy
        assert E.max() <= E[0] * (1 + 1e-12), (k, h, E.max() / E[0] - 1)


@pytest.mark.parametrize("tol", [1e-3, 1e-5])
def test_no_energy_gain_with_adaptive_steps(tol):
    """Adaptive steps: no energy gain, and the first apex that of the law (scipy) to 0.5 %."""
    for k in (1e6, 1e10):
        res = sd.simulate(ball(e=0.5, k=k), 1.5, 1e-3, tol=tol)
        E = res.total_energy
        assert E.max() <= E[0] * (1 + 1e-12), (k, tol, E.max() / E[0] - 1)
        assert abs(_flight_apexes(res)[0] / _law_apexes(0.5, k, 1)[0] - 1) < 5e-3


def block(theta_deg, mu=0.5, k=1e8):
    """A 1 kg block (0.2 x 0.2 x 0.1 m) on a floor with gravity tilted by theta about y, i.e.
    an incline; resting on four small spheres at its bottom corners."""
    th = math.radians(theta_deg)
    mb = sd.ModelBuilder(gravity=(G * math.sin(th), 0, -G * math.cos(th)))
    mb.node("ground", fixed=True)
    r = 0.01
    mb.node("block", position=(0, 0, r + 0.05), mass=1.0,
            inertia=(1 / 12 * (0.04 + 0.01), 1 / 12 * (0.04 + 0.01), 1 / 12 * 0.08))
    mat = sd.ContactMaterial(stiffness=k, restitution=0.5, friction=mu)
    mb.collision("floor", "ground", "plane", material=mat)
    for i, (x, y) in enumerate(((0.1, 0.1), (0.1, -0.1), (-0.1, 0.1), (-0.1, -0.1))):
        mb.collision(f"corner{i}", "block", "sphere", size=r, at=(x, y, r), material=mat)
    return mb.build()


def test_block_sticks_on_a_20_degree_incline_with_mu_half():
    """tan 20 deg = 0.364 < mu = 0.5: the block stays; creep at most 1e-6 m/s once the
    touch-down has settled (velocity-regularised friction creeps: 1.8 mm/s in MuJoCo)."""
    res = sd.simulate(block(20.0), 1.0, 1e-3)
    v = res.node_velocity("block", "inertial")[:, :3]
    late = res.t >= 0.5
    assert np.abs(v[late]).max() <= 1e-6, np.abs(v[late]).max()


def test_block_slides_down_a_30_degree_incline_at_the_coulomb_rate():
    """tan 30 deg = 0.577 > mu = 0.5: a = g (sin - mu cos) within 1e-3 relative."""
    th = math.radians(30.0)
    res = sd.simulate(block(30.0), 0.6, 1e-3)
    vx = res.node_velocity("block", "inertial")[:, 0]
    i1, i2 = np.searchsorted(res.t, [0.3, 0.6 - 1e-9])
    a = (vx[i2] - vx[i1]) / (res.t[i2] - res.t[i1])
    ref = G * (math.sin(th) - 0.5 * math.cos(th))
    assert abs(a / ref - 1) < 1e-3, (a, ref)


def test_sphere_rolls_down_an_incline_at_five_sevenths_g_sin_theta():
    """Rolling without slip (mu = 0.5 > 2/7 tan 30 deg): a = 5/7 g sin(theta) within 1e-4."""
    th = math.radians(30.0)
    mb = sd.ModelBuilder(gravity=(G * math.sin(th), 0, -G * math.cos(th)))
    mb.node("ground", fixed=True)
    mb.node("ball", position=(0, 0, R), mass=1.0, inertia=(0.4 * R * R,) * 3)
    mat = sd.ContactMaterial(stiffness=1e10, restitution=0.5, friction=0.5)
    mb.collision("floor", "ground", "plane", material=mat)
    mb.collision("ball", "ball", "sphere", size=R, material=mat)
    res = sd.simulate(mb.build(), 0.5, 1e-3)
    vx = res.node_velocity("ball", "inertial")[:, 0]
    i1, i2 = np.searchsorted(res.t, [0.2, 0.5 - 1e-9])
    a = (vx[i2] - vx[i1]) / (res.t[i2] - res.t[i1])
    ref = 5 / 7 * G * math.sin(th)
    assert abs(a / ref - 1) < 1e-4, (a, ref)


def test_spinning_ball_dropped_on_the_floor_ends_rolling_at_two_sevenths_r_omega():
    """A ball spinning at 50 rad/s dropped from 2 cm: friction at the contact conserves the
    angular momentum about the contact line, so it ends rolling at 2/7 r omega0 = 1.428571 m/s
    (within 1e-4 relative); MuJoCo ends 4.7 % too fast."""
    res = sd.simulate(ball(e=0.5, k=1e10, h0=0.02, mu=0.3, spin=50.0), 1.0, 1e-3)
    vx = res.node_velocity("ball", "inertial")[:, 0]
    wy = res.node_velocity("ball", "inertial")[:, 4]
    ref = 2 / 7 * R * 50.0
    assert abs(vx[-1] / ref - 1) < 1e-4, (vx[-1], ref)
    assert abs(wy[-1] * R / vx[-1] - 1) < 1e-4  # rolling: v = omega r


def test_pair_rule_and_exclusions():
    """Spheres touch planes and spheres of other nodes; not shapes of their own node, not
    shapes on two fixed nodes, not what they exclude or a disabled pair; planes no planes."""
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("g2", fixed=True)
    for n in "abc":
        mb.node(n, mass=1.0, inertia=(1, 1, 1))
    mb.collision("floor", "g", "plane")
    mb.collision("wall", "g2", "plane", normal=(1, 0, 0))
    mb.collision("fixed_ball", "g2", "sphere", size=0.1)
    mb.collision("a1", "a", "sphere", size=0.1)
    mb.collision("a2", "a", "sphere", size=0.1, exclude=("wall",))
    mb.collision("b1", "b", "sphere", size=0.1, exclude=("a",))
    mb.collision("c1", "c", "sphere", size=0.1)
    mb.contact_pair("c1", "floor", enabled=False)
    names = {p.name for p in contact_pairs(mb.build())}
    assert names == {"floor/a1", "wall/a1", "fixed_ball/a1", "floor/a2",
                     "fixed_ball/a2", "floor/b1", "wall/b1", "fixed_ball/b1", "a1/c1",
                     "a2/c1", "b1/c1", "wall/c1", "fixed_ball/c1"}


@pytest.mark.parametrize("call, words", [
    (lambda mb: mb.collision("s", "a", "sphere", size=0.0), ["collision 's'", "size"]),
    (lambda mb: mb.collision("s", "a", "sphere", size=-1.0), ["collision 's'", "size"]),
    (lambda mb: mb.collision("s", "a", "sphere", size=float("nan")), ["collision 's'"]),
    (lambda mb: mb.collision("s", "a", "sphere", size=0.1,
                             material={"stiffness": float("nan")}),
     ["collision 's'", "material.stiffness"]),
    (lambda mb: mb.collision("s", "m", "sphere", size=0.1), ["collision 's'", "massless"]),
    (lambda mb: mb.collision("s", "a", "cube", size=0.1), ["collision 's'", "shape"]),
    (lambda mb: mb.collision("s", "nowhere", "sphere", size=0.1), ["collision 's'", "node"]),
    (lambda mb: mb.collision("p", "g", "plane", normal=(0, 0, 0)), ["collision 'p'", "normal"]),
    (lambda mb: sd.ContactMaterial(stiffness=float("nan")), ["stiffness"]),
    (lambda mb: sd.ContactMaterial(restitution=1.5), ["restitution"]),
    (lambda mb: sd.ContactMaterial(friction=-1), ["friction"]),
])
def test_bad_input_is_a_one_line_error_naming_the_shape(call, words):
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("a", mass=1.0, inertia=(1, 1, 1))
    mb.node("m")
    with pytest.raises(ModelError) as ei:
        call(mb)
    msg = str(ei.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg, msg


BALL_FILE = """\
se3dyn: 1
name: drop
gravity: [0, 0, -9.81]
nodes:
  ground: {fixed: true}
  ball: {position: [0, 0, 1.1], mass: 1, inertia: [0.004, 0.004, 0.004]}
collisions:
  floor: {node: ground, shape: plane, material: {stiffness: 1.0e+10, restitution: 0.5}}
  ball: {node: ball, shape: sphere, size: 0.1,
         material: {stiffness: 1.0e+10, restitution: 0.5}}
"""


def test_model_file_collisions_and_check(tmp_path):
    """The collisions: section gives the model of the Python API (the same bits), saves back
    to itself, and `se3dyn check` lists the shapes and the pair with its law."""
    import subprocess
    import sys

    from se3dyn.io.modelfile import loads_model, save_model

    m, _ = loads_model(BALL_FILE)
    a = sd.simulate(m, 0.5, 1e-3)
    b = sd.simulate(ball(e=0.5, k=1e10, mu=0.5), 0.5, 1e-3)
    assert np.array_equal(a.H, b.H)
    text = save_model(m)
    assert save_model(loads_model(text)[0]) == text
    p = tmp_path / "drop.yaml"
    p.write_text(BALL_FILE)
    out = subprocess.run([sys.executable, "-m", "se3dyn.cli", "check", str(p)],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "collision shapes: 2 (floor: plane on ground, ball: sphere r=0.1 on ball)" in out.stdout
    assert "contact pairs: 1 (floor/ball: k=1e+10 N/m^1.5, e=0.5, mu=0.5)" in out.stdout
    bad = BALL_FILE.replace("size: 0.1", "size: -0.1")
    with pytest.raises(ModelError, match="ball.*size"):
        loads_model(bad)


def test_contact_outputs_of_a_ball_at_rest_and_an_impact():
    """A ball set on the floor settles where Hertz's force carries its weight: normal force
    m g, penetration (m g / k)^(2/3), the point in the middle of the overlap, the normal +z.
    Over an impact the force's impulse is the change of momentum m (v_out + v_in)."""
    k = 1e8
    res = sd.simulate(ball(e=0.5, k=k, h0=0.0), 0.5, 1e-3)
    name = "floor/ball"
    assert res.contact_pairs() == [name]
    d0 = (G / k) ** (2 / 3)
    assert abs(res.contact_normal_force(name)[-1] / G - 1) < 1e-6
    assert abs(res.contact_penetration(name)[-1] / d0 - 1) < 1e-6
    np.testing.assert_allclose(res.contact_force(name)[-1], (0, 0, G), atol=1e-6 * G)
    np.testing.assert_allclose(res.contact_normal(name)[-1], (0, 0, 1), atol=1e-12)
    np.testing.assert_allclose(res.contact_point(name)[-1], (0, 0, -d0 / 2), atol=1e-9)
    from se3dyn.results.channels import get_channel, list_channels

    ch = "contact/floor%2Fball/force/z"
    assert ch in list_channels(res)
    assert np.array_equal(get_channel(res, ch), res.contact_force(name)[:, 2])
    # an impact at 1 m/s without gravity: the impulse of the stored forces (trapezoidal rule
    # on the rows, h = 1e-5 << contact time 1.2 ms) is m (v_out + v_in)
    res = sd.simulate(ball(e=0.5, k=k, h0=0.001, v0=-1.0, g=0.0), 0.005, 1e-5)
    F = res.contact_force(name)[:, 2]
    impulse = float(np.sum(0.5 * (F[1:] + F[:-1]) * np.diff(res.t)))
    vout = res.node_velocity("ball", "inertial")[-1, 2]
    assert abs(impulse / (vout + 1.0) - 1) < 1e-4, (impulse, vout + 1.0)


def test_the_simulator_refuses_contacts_clearly():
    """sd.Simulator steps in the compiled loop, which has no contact-aware substeps yet."""
    with pytest.raises(ModelError, match="Simulator.*contact"):
        sd.Simulator(ball(), 1e-3)


def test_a_model_with_contacts_keeps_its_rigid_joints():
    """Condensing rigid joints would need the shapes moved to the group's root: not done, so a
    model with contact pairs runs uncondensed (and the same as with condense=False)."""
    mb = sd.ModelBuilder.from_model(ball(h0=0.05))
    mb.node("cap", position=(0, 0, 0.3), mass=0.1, inertia=(1e-4,) * 3)
    mb.joint("weld", "rigid", "ball", "cap")
    m = mb.build()
    a = sd.simulate(m, 0.2, 1e-3)
    b = sd.simulate(m, 0.2, 1e-3, condense=False)
    assert a.stats["condensed"] == []
    assert np.array_equal(a.H, b.H)


def test_dense_output_of_fixed_steps_with_contacts_is_refused_clearly():
    with pytest.raises(ModelError, match="output_step.*contact"):
        sd.simulate(ball(), 0.1, 1e-3, output_step=0.01)


def _capsule_model(theta_deg=0.0, mu=0.5, k=1e10):
    """A 1 kg capsule (r = 0.1, segment 0.4 along y) lying on a floor, gravity tilted about y
    by theta (an incline down +x); its inertia about its axis m r^2 / 2."""
    th = math.radians(theta_deg)
    mb = sd.ModelBuilder(gravity=(G * math.sin(th), 0, -G * math.cos(th)))
    mb.node("ground", fixed=True)
    mb.node("cap", position=(0, 0, R), mass=1.0, inertia=(0.02, 0.5 * R * R, 0.02))
    mat = sd.ContactMaterial(stiffness=k, restitution=0.5, friction=mu)
    mb.collision("floor", "ground", "plane", material=mat)
    mb.collision("cap", "cap", "capsule", size=R, length=0.4, axis=(0, 1, 0), material=mat)
    return mb.build()


def test_capsule_lying_on_the_floor_rests_on_its_two_ends():
    """The deepest points of a capsule on a plane are its two end spheres' (pairs cap:0 and
    cap:1): at rest each carries half the weight."""
    res = sd.simulate(_capsule_model(), 0.3, 1e-3)
    assert res.contact_pairs() == ["floor/cap:0", "floor/cap:1"]
    for name in res.contact_pairs():
        assert abs(res.contact_normal_force(name)[-1] / (G / 2) - 1) < 1e-6
    np.testing.assert_allclose(res.contact_point("floor/cap:1")[-1, :2], (0, 0.2), atol=1e-9)


def test_capsule_rolls_down_an_incline_at_two_thirds_g_sin_theta():
    """Lying across a 30 deg incline, its inertia about the axis m r^2 / 2: rolling without
    slip at a = g sin(theta) / (1 + 1/2) within 1e-4."""
    th = math.radians(30.0)
    res = sd.simulate(_capsule_model(30.0), 0.5, 1e-3)
    vx = res.node_velocity("cap", "inertial")[:, 0]
    i1, i2 = np.searchsorted(res.t, [0.2, 0.5 - 1e-9])
    a = (vx[i2] - vx[i1]) / (res.t[i2] - res.t[i1])
    assert abs(a / (2 / 3 * G * math.sin(th)) - 1) < 1e-4, a


def test_sphere_on_a_capsule_touches_the_closest_point_of_its_segment():
    """A ball dropped without gravity onto a fixed horizontal capsule, off its middle: it
    leaves at e times its speed, along the normal through the segment's closest point; at rest
    under gravity the normal force is its weight and the normal vertical."""
    def model(g, v0):
        mb = sd.ModelBuilder(gravity=(0, 0, -g))
        mb.node("ground", fixed=True)
        mb.node("ball", position=(0.13, 0, 0.2 + 0.001), mass=1.0, inertia=(0.004,) * 3,
                velocity=(0, 0, -v0))
        mat = sd.ContactMaterial(stiffness=1e9, restitution=0.6, friction=0.3)
        mb.collision("bar", "ground", "capsule", size=R, length=0.5, axis=(1, 0, 0),
                     material=mat)
        mb.collision("ball", "ball", "sphere", size=R, material=mat)
        return mb.build()

    res = sd.simulate(model(0.0, 2.0), 0.01, 1e-3)
    v = res.node_velocity("ball", "inertial")[-1, :3]
    np.testing.assert_allclose(v, (0, 0, 0.6 * 2.0), atol=5e-3 * 2.0)
    res = sd.simulate(model(G, 0.0), 0.3, 1e-3)
    assert abs(res.contact_normal_force("bar/ball")[-1] / G - 1) < 1e-6
    np.testing.assert_allclose(res.contact_normal("bar/ball")[-1], (0, 0, 1), atol=1e-9)


def test_capsule_errors_and_pairs():
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("a", mass=1.0, inertia=(1, 1, 1))
    mb.node("b", mass=1.0, inertia=(1, 1, 1))
    for bad, words in (({"length": 0.0}, "length"), ({"length": 0.2, "axis": (0, 0, 0)}, "axis"),
                       ({"length": 0.2, "size": -1.0}, "size")):
        kw = dict(size=0.1, **{k: v for k, v in bad.items() if k != "size"})
        if "size" in bad:
            kw["size"] = bad["size"]
        with pytest.raises(ModelError, match=f"collision 'c'.*{words}"):
            mb.collision("c", "a", "capsule", **kw)
    mb.collision("floor", "g", "plane")
    mb.collision("c1", "a", "capsule", size=0.1, length=0.3)
    mb.collision("c2", "b", "capsule", size=0.1, length=0.3)
    mb.collision("s", "b", "sphere", size=0.1)
    names = [p.name for p in contact_pairs(mb.build())]
    assert names == ["floor/c1:0", "floor/c1:1", "floor/c2:0", "floor/c2:1", "floor/s", "c1/s"]
