"""URDF parsers compared (docs/design.md, "URDF import"): import cost in a fresh process, parse
time of real robots, and whether loop-closure and mimic tags survive.

    python benchmarks/urdf_parsers.py [--yourdfpy PYTHON]

se3dyn's reader (the standard library's expat through defusedxml), Pinocchio's (urdfdom, C++,
through ``pin.buildModelFromUrdf``) in this interpreter; yourdfpy (lxml) in the interpreter
given by ``--yourdfpy`` (a venv with ``pip install yourdfpy``), so that this project's
environment does not need it. Timings: best of 5 warm calls; imports: one fresh process each.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

ROBOTS = ["ur_description/urdf/ur5_robot.urdf", "panda_description/urdf/panda.urdf",
          "solo_description/robots/solo12.urdf", "talos_data/robots/talos_full_v2.urdf"]
LOOP = ('<loop_joint name="c" type="spherical"><link1 link="{a}"/><link2 link="{b}"/>'
        '</loop_joint>')


def robots_dir() -> Path:
    import importlib.metadata as md

    for f in md.distribution("example-robot-data").files:
        if str(f).endswith("ur_description/urdf/ur5_robot.urdf"):
            return Path(f.locate()).parents[2]
    raise SystemExit("pip install example-robot-data")


def fresh(python: str, code: str) -> float:
    """Wall time of ``code`` in a new process (s), the interpreter's own start taken off."""
    def run(c):
        t = time.perf_counter()
        subprocess.run([python, "-c", c], check=True, capture_output=True)
        return time.perf_counter() - t
    base = min(run("pass") for _ in range(3))
    return min(run(code) for _ in range(3)) - base


def best(fn, n: int = 5) -> float:
    out = []
    for _ in range(n):
        t = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t)
    return min(out)


def with_loop(path: Path, tmp: Path) -> Path:
    """The URDF with an Isaac <loop_joint> between its first two links added."""
    import re

    txt = path.read_text()
    a, b = re.findall(r'<link name="([^"]+)"', txt)[:2]
    out = tmp / path.name
    out.write_text(txt.replace("</robot>", LOOP.format(a=a, b=b) + "</robot>"))
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--yourdfpy", help="a Python with yourdfpy installed")
    args = ap.parse_args()
    import tempfile
    import warnings

    import pinocchio as pin

    from se3dyn.io.urdf import load_urdf
    from se3dyn.io.urdf.loops import read_loop_tags
    from se3dyn.io.urdf.parse import read_robot

    warnings.simplefilter("ignore")
    d = robots_dir()
    print("import in a fresh process (s): se3dyn.io.urdf "
          f"{fresh(sys.executable, 'import se3dyn.io.urdf.build, defusedxml'):.3f}, "
          f"pinocchio {fresh(sys.executable, 'import pinocchio'):.3f}"
          + (f", yourdfpy {fresh(args.yourdfpy, 'import yourdfpy'):.3f}" if args.yourdfpy
             else ""))
    print(f"{'robot':<22}{'links':>6}{'se3dyn read':>13}{'load+build':>12}{'pin':>10}"
          + ("{:>11}".format("yourdfpy") if args.yourdfpy else "") + "   (ms)")
    for rel in ROBOTS:
        p = d / rel
        n = len(read_robot(p).links)
        t_read = best(lambda p=p: read_robot(p))
        t_all = best(lambda p=p: load_urdf(p).build())
        t_pin = best(lambda p=p: pin.buildModelFromUrdf(str(p)))
        line = f"{p.name:<22}{n:>6}{1e3 * t_read:>13.2f}{1e3 * t_all:>12.2f}{1e3 * t_pin:>10.2f}"
        if args.yourdfpy:
            code = ("import time, yourdfpy; ts=[]\nfor _ in range(5):\n t=time.perf_counter();"
                    f"yourdfpy.URDF.load({str(p)!r}, load_meshes=False, build_scene_graph=True,"
                    " load_collision_meshes=False); ts.append(time.perf_counter()-t)\n"
                    "print(min(ts))")
            out = subprocess.run([args.yourdfpy, "-c", code], capture_output=True, text=True)
            line += f"{1e3 * float(out.stdout.split()[-1]):>11.2f}"
        print(line)
    with tempfile.TemporaryDirectory() as tmp:
        p = with_loop(d / ROBOTS[1], Path(tmp))
        kept = len(read_robot(p, read_loop_tags).loops)
        print(f"<loop_joint> kept: se3dyn {kept}; pin: not read (urdfdom parses the tree only)"
              + ("" if not args.yourdfpy else "; yourdfpy " + subprocess.run(
                  [args.yourdfpy, "-c", f"import yourdfpy; u=yourdfpy.URDF.load({str(p)!r}, "
                   "load_meshes=False); print('loop_joint' in str(vars(u.robot)))"],
                  capture_output=True, text=True).stdout.strip()))


if __name__ == "__main__":
    main()
