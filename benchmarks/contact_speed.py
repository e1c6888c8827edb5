"""Compliant contact: cost per step and accuracy against closed forms, se3dyn beside MuJoCo at
its defaults (issue 33). Not a test: timings of this machine, printed.

Cases (closed forms of rigid bodies):
  * one contact: a ball spinning at 50 rad/s dropped on the floor ends rolling at
    2/7 r omega0 = 1.428571 m/s (r = 0.1 m);
  * a block on a 20 deg incline with mu = 0.5 sticks (creep 0);
  * a 1 m drop with e = 0.5 rebounds to 0.25 m (se3dyn's law; MuJoCo has no restitution
    parameter: its default soft contact is shown as it is);
  * 100 spheres in a box (every pair in se3dyn's fixed pattern: no broad phase yet).

    python benchmarks/contact_speed.py          (MuJoCo: pip install -e ".[bench]")
"""

from __future__ import annotations

import math
import subprocess
import sys
import time

import numpy as np

import se3dyn as sd

G, R = 9.81, 0.1


def ball(spin=0.0, h0=0.02, e=0.5, k=1e10, mu=0.3):
    mb = sd.ModelBuilder(gravity=(0, 0, -G))
    mb.node("ground", fixed=True)
    mb.node("ball", position=(0, 0, h0 + R), mass=1.0, inertia=(0.4 * R * R,) * 3,
            angular_velocity=(0, spin, 0))
    mat = sd.ContactMaterial(stiffness=k, restitution=e, friction=mu)
    mb.collision("floor", "ground", "plane", material=mat)
    mb.collision("ball", "ball", "sphere", size=R, material=mat)
    return mb.build()


def block(theta=20.0):
    th = math.radians(theta)
    mb = sd.ModelBuilder(gravity=(G * math.sin(th), 0, -G * math.cos(th)))
    mb.node("ground", fixed=True)
    mb.node("block", position=(0, 0, 0.06), mass=1.0, inertia=(0.0042, 0.0042, 0.0067))
    mat = sd.ContactMaterial(stiffness=1e8, restitution=0.5, friction=0.5)
    mb.collision("floor", "ground", "plane", material=mat)
    for i, (x, y) in enumerate(((0.1, 0.1), (0.1, -0.1), (-0.1, 0.1), (-0.1, -0.1))):
        mb.collision(f"c{i}", "block", "sphere", size=0.01, at=(x, y, 0.01), material=mat)
    return mb.build()


def spheres_in_box(n=100):
    rng = np.random.default_rng(0)
    mb = sd.ModelBuilder(gravity=(0, 0, -G))
    mb.node("box", fixed=True)
    mat = sd.ContactMaterial(stiffness=1e7, restitution=0.5, friction=0.3)
    for i, (nrm, at) in enumerate((((0, 0, 1), (0, 0, 0)), ((1, 0, 0), (-0.5, 0, 0)),
                                   ((-1, 0, 0), (0.5, 0, 0)), ((0, 1, 0), (0, -0.5, 0)),
                                   ((0, -1, 0), (0, 0.5, 0)))):
        mb.collision(f"wall{i}", "box", "plane", normal=nrm, at=at, material=mat)
    for i in range(n):
        p = (-0.4 + 0.2 * (i % 5), -0.4 + 0.2 * ((i // 5) % 5), 0.06 + 0.12 * (i // 25))
        mb.node(f"s{i}", position=p, mass=0.1, inertia=(4e-5,) * 3,
                velocity=tuple(0.2 * rng.normal(size=3)))
        mb.collision(f"s{i}", f"s{i}", "sphere", size=0.05, material=mat)
    return mb.build()


def timed(model, t_end, h):
    t0 = time.perf_counter()
    res = sd.simulate(model, t_end, h)
    return res, (time.perf_counter() - t0) / res.stats["steps"]


def se3dyn_cases():
    out = {}
    res, per = timed(ball(spin=50.0), 1.0, 1e-3)
    sd.simulate(ball(spin=50.0), 0.01, 1e-3)
    res, per = timed(ball(spin=50.0), 1.0, 1e-3)
    v = res.node_velocity("ball", "inertial")[-1, 0]
    out["spinning ball"] = (per, f"v_end {v:.6f} m/s (closed form {2 / 7 * R * 50:.6f}, "
                                 f"error {v / (2 / 7 * R * 50) - 1:+.1e})")
    res, per = timed(block(), 1.0, 1e-3)
    creep = np.abs(res.node_velocity("block", "inertial")[res.t >= 0.5, :3]).max()
    out["block 20 deg"] = (per, f"creep {creep:.1e} m/s (closed form 0)")
    res, per = timed(ball(h0=1.0, mu=0.0), 1.1, 1e-3)
    z = res.node_position("ball")[:, 2] - R
    vz = res.node_velocity("ball", "inertial")[:, 2]
    up = np.where((z > 0) & (vz > 0))[0]
    apex = z[up[0]] + vz[up[0]] ** 2 / (2 * G)
    out["1 m drop, e = 0.5"] = (per, f"first apex {apex:.4f} m (rigid closed form 0.25)")
    m = spheres_in_box()
    t0 = time.perf_counter()
    s = sd.compile_model(m)
    tc = time.perf_counter() - t0
    res, per = timed(s, 0.02, 1e-3)
    out["100 spheres in a box"] = (per, f"{len(s.contacts)} pairs in the pattern, compile "
                                        f"{tc:.2f} s")
    return out


MJ_BALL = """<mujoco><option gravity="0 0 -9.81"/><worldbody>
<geom type="plane" size="5 5 .1"/>
<body pos="0 0 {z}"><freejoint/><geom type="sphere" size="0.1" mass="1"/></body>
</worldbody></mujoco>"""
MJ_BLOCK = """<mujoco><option gravity="{gx} 0 {gz}"/><worldbody>
<geom type="plane" size="5 5 .1" friction="0.5 0.005 0.0001"/>
<body pos="0 0 0.05"><freejoint/><geom type="box" size="0.1 0.1 0.05" mass="1"
 friction="0.5 0.005 0.0001"/></body></worldbody></mujoco>"""


def mujoco_cases():
    try:
        import mujoco
    except ImportError:
        return None
    out = {}

    def run(xml, t_end, init=None):
        m = mujoco.MjModel.from_xml_string(xml)
        d = mujoco.MjData(m)
        if init:
            init(d)
        n = int(round(t_end / m.opt.timestep))
        t0 = time.perf_counter()
        for _ in range(n):
            mujoco.mj_step(m, d)
        return d, (time.perf_counter() - t0) / n, m.opt.timestep

    def spin(d):
        d.qvel[4] = 50.0

    d, per, h = run(MJ_BALL.format(z=0.12), 1.0, spin)
    v = d.qvel[0]
    out["spinning ball"] = (per, f"v_end {v:.6f} m/s (error {v / (2 / 7 * R * 50) - 1:+.1e}), "
                                 f"h {h:g}")
    th = math.radians(20)
    d, per, h = run(MJ_BLOCK.format(gx=G * math.sin(th), gz=-G * math.cos(th)), 1.0)
    out["block 20 deg"] = (per, f"creep {abs(d.qvel[0]):.1e} m/s, h {h:g}")
    m = mujoco.MjModel.from_xml_string(MJ_BALL.format(z=1.1))
    dd = mujoco.MjData(m)
    apex, prev = 0.0, None
    t0 = time.perf_counter()
    n = int(1.1 / m.opt.timestep)
    for _ in range(n):
        mujoco.mj_step(m, dd)
        if prev is not None and prev < 0 <= dd.qvel[2]:
            apex = -1.0
        if apex < 0 and dd.qvel[2] <= 0:
            apex = dd.qpos[2] - R
        prev = dd.qvel[2]
    out["1 m drop, e = 0.5"] = ((time.perf_counter() - t0) / n,
                                f"top after the first impact {apex:.4f} m (its default soft "
                                "contact has no restitution parameter)")
    bodies = "".join(
        f'<body pos="{-0.4 + 0.2 * (i % 5)} {-0.4 + 0.2 * ((i // 5) % 5)} '
        f'{0.06 + 0.12 * (i // 25)}"><freejoint/><geom type="sphere" size="0.05" '
        f'mass="0.1"/></body>' for i in range(100))
    walls = ('<geom type="plane" size="5 5 .1"/>'
             '<geom type="box" pos="-0.55 0 0.5" size="0.05 0.6 0.6"/>'
             '<geom type="box" pos="0.55 0 0.5" size="0.05 0.6 0.6"/>'
             '<geom type="box" pos="0 -0.55 0.5" size="0.6 0.05 0.6"/>'
             '<geom type="box" pos="0 0.55 0.5" size="0.6 0.05 0.6"/>')
    d, per, h = run(f"<mujoco><worldbody>{walls}{bodies}</worldbody></mujoco>", 0.2)
    out["100 spheres in a box"] = (per, f"h {h:g}")
    return out


def first_call() -> float:
    code = ("import time; t = time.perf_counter(); import se3dyn as sd; "
            "import benchmarks.contact_speed as b; sd.simulate(b.ball(spin=50.0), 0.1, 1e-3); "
            "print(time.perf_counter() - t)")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    return float(p.stdout.strip().splitlines()[-1])


def main():
    ours = se3dyn_cases()
    theirs = mujoco_cases()
    print(f"first call in a fresh process (import, compile, 0.1 s of the spinning ball): "
          f"{first_call():.2f} s")
    print(f"{'case':24s} {'se3dyn us/step':>15s}  accuracy | MuJoCo us/step  accuracy")
    for case, (per, acc) in ours.items():
        line = f"{case:24s} {1e6 * per:15.1f}  {acc}"
        if theirs and case in theirs:
            line += f" | {1e6 * theirs[case][0]:.1f}  {theirs[case][1]}"
        print(line)
    if theirs is None:
        print("(MuJoCo not installed: pip install -e \".[bench]\")")


if __name__ == "__main__":
    main()
