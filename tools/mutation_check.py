#!/usr/bin/env python3
"""Mutation check of the element kernels: delete one term of a kernel, rebuild, run the tests.

Each mutation replaces one exact source snippet (unique in its file) of an element kernel
(src/se3dyn/_core/elements/*.hpp, or the Python spec that feeds it) by the same code without
one physical term. For each: apply it in place, rebuild the engine, run a test selection with
``pytest -x`` and record whether a test fails (killed) and which one first; the file is restored
by ``git checkout -- FILE`` whatever happens. At the end the unmutated engine is rebuilt and the
table is printed and written to docs/mutation-check.md.

    .venv/bin/python tools/mutation_check.py                 # all mutations, default tests
    .venv/bin/python tools/mutation_check.py --only body-gyro spring-damping --no-write
    .venv/bin/python tools/mutation_check.py --tests tests/test_elements.py

Stdlib only. The files it mutates must be unmodified in git when it starts (it refuses
otherwise), so that the restore is exact.
"""

from __future__ import annotations

import argparse
import datetime
import glob
import os
import subprocess
import sys
from dataclasses import dataclass

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
K = "src/se3dyn/_core/elements/"
DEFAULT_TESTS = ("tests/test_elements.py", "tests/test_physics.py", "tests/test_new_elements.py",
                 "tests/test_bushing.py", "tests/test_beam.py", "tests/test_offsets.py",
                 "tests/test_condense.py")
C = "src/se3dyn/condense.py"


@dataclass(frozen=True)
class Mutation:
    name: str
    file: str
    old: str   # exact snippet, unique in the file
    new: str   # the snippet without the term
    kind: str  # residual, tangent or energy
    what: str  # the physical term removed
    note: str = ""  # why a surviving deletion is left surviving


M = Mutation
MUTATIONS = (
    # body: inertia and gravity (Eqs. (36), (47)-(53), (66)-(67))
    M("body-gyro", K + "body.hpp", "gin[i] = Mvd[i] - adTp[i];", "gin[i] = Mvd[i];",
      "residual", "gyroscopic force -ad(v)^T M v of the body"),
    M("body-com-mass", "src/se3dyn/elements/body.py",
      "    M[:, :3, 3:] = -m[:, None, None] * C\n    M[:, 3:, :3] = m[:, None, None] * C\n", "",
      "residual", "centre-of-mass offset coupling (off-diagonal blocks m hat(c)) of the mass "
      "matrix"),
    M("body-gravity-moment", K + "body.hpp", "cross(c, rtg, g + 3);", "g[3] = g[4] = g[5] = 0;",
      "residual", "moment c x m R^T g of gravity at an offset centre of mass"),
    M("body-gyro-tangent", K + "body.hpp", "X.cC * (L[i] + adTM[i])", "X.cC * adTM[i]",
      "tangent", "-Lambda(M v) part of the gyroscopic damping matrix C_T"),
    M("body-gravity-stiffness", K + "body.hpp", "K[6 * (3 + i) + 3 + j] = -CG[3 * i + j];",
      "K[6 * (3 + i) + 3 + j] = 0;", "tangent",
      "stiffness -m hat(c) hat(R^T g) of the gravity moment of an offset centre of mass"),
    M("body-com-potential", K + "body.hpp", " + dot3(X.gravity, Rc);", ";", "energy",
      "potential energy -m g . R c of an offset centre of mass"),
    M("body-kinetic", K + "body.hpp", "X.energy[KINETIC] += 0.5 *", "X.energy[KINETIC] += 0.0 *",
      "energy", "kinetic energy v^T M v / 2"),
    # joint: constraints and their forces (Eqs. (55)-(59))
    M("joint-frame-force", K + "joint.hpp", "frame_force(T, j, lam, 1.0, X.r);", "", "residual",
      "constraint force lambda on the joint frame (the joint's own coordinates)"),
    M("joint-geometric", K + "joint.hpp",
      "add_frame_block(T, S, X.vals, off_aj[e], a, j, K, -X.cK, true);", "", "tangent",
      "geometric stiffness -(Ad PA)^T Lambda(lambda) of the constraint forces"),
    M("joint-adG", K + "joint.hpp", "mm<6, 6, 6>(D, AdG, t);",
      "for (int i = 0; i < 36; ++i) t[i] = D[i];", "tangent",
      "Ad(G^-1) of node B's constraint rows (exact linearisation away from Phi = 0)"),
    M("joint-index2-ad", K + "joint.hpp", "add_block(X.vals, off_xj[e], 6, T.k[j], Y, cv_);", "",
      "tangent", "cv ad(w) T_J A of the index-2 velocity-constraint rows"),
    M("joint-accel-rhs", K + "joint.hpp", "mv<6, 6>(ad, wa, X.arhs + mult[e]);",
      "for (int i = 0; i < 6; ++i) X.arhs[mult[e] + i] = 0.0;", "residual",
      "ad(v_J) Ad PA v_A of the acceleration-level constraints (initial accelerations)"),
    # joint_force: springs, dampers, actuators, PD laws (Eqs. (60)-(66))
    M("pd-target-rate", K + "joint_force.hpp", "(v[c] - X.u[prate[e] + c])", "v[c]", "residual",
      "target rate of a PD law (kd acts on v, not on v - rate_ref)"),
    M("joint-spring-TA", K + "joint_force.hpp", "for (int c = 0; c < k; ++c) fs[c] = y[c];", "",
      "residual", "T_A(alpha)^-T of a spring on a non-abelian joint"),
    M("joint-spring-TA-tangent", K + "joint_force.hpp",
      "KG[6 * i + c] = (i == c ? K[6 * e + c] : 0.0) - G[6 * i + c];",
      "KG[6 * i + c] = -G[6 * i + c];", "tangent",
      "stiffness T_A^-T K T_A^-1 of a spring on a non-abelian joint"),
    M("joint-spring-TA-geometric", K + "joint_force.hpp",
      "KG[6 * i + c] = (i == c ? K[6 * e + c] : 0.0) - G[6 * i + c];",
      "KG[6 * i + c] = (i == c ? K[6 * e + c] : 0.0);", "tangent",
      "derivative -T_A^-T G T_A^-1 of T_A^-T at fixed force (spring on a non-abelian joint)"),
    M("pd-kd-tangent", K + "joint_force.hpp", "X.cC * (C[6 * e + c] + kd[6 * e + c])",
      "X.cC * C[6 * e + c]", "tangent", "kd of a PD law in the damping matrix"),
    M("actuator-power", K + "joint_force.hpp", "X.energy[P_ACTUATOR] += tpd[c] * v[c];", "",
      "energy", "power of joint actuators and PD laws"),
    M("joint-damper-power", K + "joint_force.hpp",
      "X.energy[P_DISSIPATION] += C[6 * e + c] * v[c] * v[c];", "", "energy",
      "power dissipated by joint dampers"),
    # load: forces and torques at a point (Eqs. (66)-(67))
    M("load-follower", K + "load.hpp",
      "if (force_body[e]) { Fm[0] = F[0]; Fm[1] = F[1]; Fm[2] = F[2]; }\n        else ",
      "", "residual", "rotation of a follower (body-frame) force with the body"),
    M("load-offset-moment", K + "load.hpp", "cross(ce, Fm, g + 3);", "g[3] = g[4] = g[5] = 0;",
      "residual", "moment c x F of a force applied away from the node"),
    M("load-offset-stiffness", K + "load.hpp", "K[6 * (3 + i) + 3 + j] -= CG[3 * i + j];", "",
      "tangent", "stiffness -hat(c) hat(R^T F) of the moment of an offset inertial force"),
    M("load-power", K + "load.hpp", "X.energy[P_LOADS] += g[0] * v[0] + g[1] * v[1] + g[2] * v[2]"
      " + g[3] * v[3] + g[4] * v[4] +\n                             g[5] * v[5];", "(void)v;",
      "energy", "power g . v of the loads"),
    # spring_damper: point-to-point spring and damper
    M("spring-damping", K + "spring_damper.hpp", "+ d[e] * Ldot;", ";", "residual",
      "damping force d dL/dt of a spring-damper"),
    M("spring-geometric", K + "spring_damper.hpp", " + N * PdQ[12 * i + c]", "", "tangent",
      "geometric stiffness N dq (rotation of the line of action)"),
    M("spring-damping-rotation", K + "spring_damper.hpp", "dLd[6 * s + 3 + i] += sg * row[i];",
      ";", "tangent", "rotational part of d(dL/dt)/dh (offset points on turning bodies)"),
    M("spring-dissipation", K + "spring_damper.hpp",
      "X.energy[P_DISSIPATION] += d[e] * Ldot * Ldot;", "", "energy",
      "power dissipated by a spring-damper"),
    # bushing: 6 x 6 stiffness and damping on d = log(H_a'^-1 H_b')
    M("bushing-coupling", K + "bushing.hpp", "mv<6, 6>(Ke, d, Kd);",
      "for (int i = 0; i < 6; ++i) Kd[i] = Ke[7 * i] * d[i];", "residual",
      "coupling (off-diagonal) stiffness of a bushing"),
    M("bushing-Tinv", K + "bushing.hpp", "mTv<6, 6>(Ti, p, f);",
      "for (int i = 0; i < 6; ++i) f[i] = p[i];", "residual",
      "T(d)^-T of the bushing forces (f = K d + D d_dot taken as the force)"),
    M("bushing-lambda", K + "bushing.hpp", "for (int i = 0; i < 72; ++i) KT[i] += PALJ[i];", "",
      "tangent", "geometric stiffness P_a^T A^T Lambda(f) Jg of a bushing"),
    M("bushing-Mp", K + "bushing.hpp", "df[i] = MJ[i] + Tdp[i];", "df[i] = Tdp[i];", "tangent",
      "derivative M_p of T(d)^-T in a bushing's stiffness"),
    M("bushing-dissipation", K + "bushing.hpp", "X.energy[P_DISSIPATION] += dot6(dd, Ddd);", "",
      "energy", "power dissipated by a bushing"),
    # beam: geometrically exact SE(3) beam
    M("beam-reference", K + "beam.hpp", "eps[i] = (d[i] - d0[6 * e + i]) / Le;",
      "eps[i] = d[i] / Le;", "residual",
      "reference deformation d0 (initial curvature and twist) of the strain"),
    M("beam-Tinv", K + "beam.hpp", "mTv<6, 6>(Ti, f, y);",
      "for (int i = 0; i < 6; ++i) y[i] = f[i];", "residual",
      "T(d)^-T of the section forces on the nodes"),
    M("beam-geometric", K + "beam.hpp", "for (int i = 0; i < 36; ++i) inner[i] -= M1[i];", "",
      "tangent", "derivative of T(d)^-T at fixed section forces (geometric stiffness)"),
    M("beam-lambda", K + "beam.hpp", "t1[i] = Y[i] - Lam[i];", "t1[i] = Y[i];", "tangent",
      "Lambda(y) term of the rows of node A (rotation of A_r^T y)"),
    M("beam-damping-ad", K + "beam.hpp", "Qc[i] = -adv[i] - M1[i];", "Qc[i] = -M1[i];",
      "tangent", "-ad(A_r v'_A) of the configuration derivative of the strain rate"),
    M("beam-elastic", K + "beam.hpp", "X.energy[ELASTIC] += 0.5 * Le * we;", "", "energy",
      "elastic energy L eps^T K eps / 2 of a beam element"),
    M("beam-dissipation", K + "beam.hpp", "X.energy[P_DISSIPATION] += Le * wd;", "", "energy",
      "power dissipated by the strain-rate damping of a beam"),
    # condensation of rigid joints for the time loop (se3dyn/condense.py)
    M("condense-parallel-axis", "src/se3dyn/system.py", "Js = Js + np.einsum(",
      "Js = Js + 0 * np.einsum(", "reduction",
      "parallel-axis terms of the combined inertia of a group (and of lumped beam masses)"),
    M("condense-com", C, "mass=M, inertia=J, com=com)", "mass=M, inertia=J, com=None)",
      "reduction", "centre of mass of a group (put at its root node)"),
    M("condense-joint-frame-a", C, "frames=(C[a] @ s.joint_XA[j]", "frames=(s.joint_XA[j]",
      "reduction", "attachment frame of a joint on a member (node A) moved to the root"),
    M("condense-joint-frame-b", C, "C[b] @ s.joint_XB[j], s.joint_H0",
      "s.joint_XB[j], s.joint_H0", "reduction",
      "attachment frame of a joint on a member (node B) moved to the root"),
    M("condense-load-point", C, "at=H0[i, :3, 3].copy() if ld.at is None else ld.at",
      "at=ld.at", "reduction", "point of a load on a member"),
    M("condense-member-frames", C, "Hf[:, mem] = np.matmul(Hf[:, mem], self.node_C[mem])",
      "pass", "output", "members' frames H_root C in the expanded rows"),
    M("condense-member-velocities", C,
      "y[:, dst] = np.matmul(self.node_Ad[members], x[:, src][..., None])[..., 0]",
      "y[:, dst] = x[:, src]", "output", "Ad(C^-1) of the members' velocities"),
    M("condense-reaction-parent", C,
      "r[:, self.parent_dofs[q]] += times(lq, self.parent_block[q])", "pass", "output",
      "a rigid joint's reaction on its parent member (leaf-first recovery)"),
    M("condense-reaction-order", C, 'order=np.argsort(-depth[child], kind="stable")',
      'order=np.argsort(depth[child], kind="stable")', "output",
      "leaf-first order of the reaction recovery"),
    M("condense-body-load-check", C,
      "            if body and root[i] != i and not np.array_equal(R0[i], R0[root[i]]):\n"
      "                bad.add(int(root[i]))", "            pass", "reduction",
      "refusal to move a body-frame load to a turned root"),
    M("condense-loop-check", C,
      "                bad.add(int(root[nidx[a]]))  # closes a loop inside a group",
      "                pass", "reduction", "refusal to condense a group closed by a loop"),
)


def run(cmd, **kw):
    return subprocess.run(cmd, cwd=ROOT, text=True, capture_output=True, **kw)


def git_clean(files):
    return run(["git", "diff", "--quiet", "HEAD", "--", *files]).returncode == 0


def engine_dir(python):
    """Directory of the installed se3dyn package holding the compiled _engine module."""
    out = run([python, "-c", "import importlib.util as u; "
               "print(u.find_spec('se3dyn._engine').origin)"], check=True)
    return os.path.dirname(os.path.dirname(out.stdout.strip()))


def rebuild(python):
    """Rebuild and install the engine: incrementally with the existing CMake build directory of
    the editable install (ninja), or else by pip."""
    dirs = sorted(glob.glob(os.path.join(ROOT, "build", "*", "CMakeCache.txt")))
    if dirs:
        b = os.path.dirname(dirs[0])
        p = run(["cmake", "--build", b])
        if p.returncode == 0:
            p = run(["cmake", "--install", b, "--prefix", engine_dir(python)])
    else:
        p = run([python, "-m", "pip", "install", "-q", "--no-build-isolation", "-e", "."])
    return p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]


def first_failure(out):
    for line in out.splitlines():
        if line.startswith(("FAILED ", "ERROR ")):
            return line.split(" ", 1)[1].split(" - ", 1)[0].strip()
    return None


def check(mut, python, tests, timeout):
    path = os.path.join(ROOT, mut.file)
    with open(path) as fh:
        src = fh.read()
    try:
        with open(path, "w") as fh:
            fh.write(src.replace(mut.old, mut.new, 1))
        ok, log = rebuild(python)
        if not ok:
            return "build error", log.strip().splitlines()[-1] if log.strip() else ""
        try:
            p = run([python, "-m", "pytest", "-x", "-q", "-rfE", "-p", "no:cacheprovider",
                     *tests], timeout=timeout)
        except subprocess.TimeoutExpired:
            return "killed", f"(timeout after {timeout} s)"
        if p.returncode == 0:
            return "survived", ""
        return "killed", first_failure(p.stdout) or f"(pytest exit {p.returncode})"
    finally:
        run(["git", "checkout", "--", mut.file], check=True)


def table(rows):
    out = ["| # | mutation | file | kind | term removed | result | first failing test |",
           "|---|---|---|---|---|---|---|"]
    for i, (mut, res, test) in enumerate(rows, 1):
        f = os.path.basename(mut.file)
        out.append(f"| {i} | `{mut.name}` | {f} | {mut.kind} | {mut.what} | {res} | "
                   f"{'`' + test + '`' if test and not test.startswith('(') else test} |")
    return "\n".join(out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--tests", nargs="+", default=list(DEFAULT_TESTS),
                    help="pytest arguments (files, node ids) run for each mutation")
    ap.add_argument("--only", nargs="+", metavar="NAME", help="run these mutations only")
    ap.add_argument("--python", default=sys.executable, help="interpreter with se3dyn installed")
    ap.add_argument("--timeout", type=float, default=1200.0, help="per test run (s)")
    ap.add_argument("--out", default="docs/mutation-check.md")
    ap.add_argument("--no-write", action="store_true", help="print the table only")
    args = ap.parse_args(argv)

    muts = [m for m in MUTATIONS if not args.only or m.name in args.only]
    if args.only and len(muts) != len(set(args.only)):
        ap.error("unknown mutation in --only; known: " + " ".join(m.name for m in MUTATIONS))
    files = sorted({m.file for m in muts})
    if not git_clean(files):
        ap.error("the files to mutate have changes against HEAD; commit or stash them first")
    for m in muts:
        with open(os.path.join(ROOT, m.file)) as fh:
            n = fh.read().count(m.old)
        if n != 1:
            ap.error(f"{m.name}: the snippet occurs {n} times in {m.file}, not once")

    rows = []
    try:
        for i, m in enumerate(muts, 1):
            res, test = check(m, args.python, args.tests, args.timeout)
            rows.append((m, res, test))
            print(f"[{i}/{len(muts)}] {m.name}: {res} {test}", flush=True)
    finally:
        ok, log = rebuild(args.python)  # the engine of the unmutated sources
        if not ok:
            print(log, file=sys.stderr)
        if not git_clean(files):
            print("WARNING: the working tree differs from HEAD after the run", file=sys.stderr)

    killed = sum(r[1] == "killed" for r in rows)
    notes = "".join(f"\n* `{m.name}` survives: {m.note}\n" for m, res, _ in rows
                    if res != "killed" and m.note)
    cmd = "python tools/mutation_check.py " + " ".join(
        a if " " not in a else repr(a) for a in (argv if argv is not None else sys.argv[1:]))
    text = table(rows)
    print(text)
    print(f"\n{killed} of {len(rows)} mutations killed\n{notes}")
    if not args.no_write and not args.only:
        date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        doc = (f"# Mutation check of the element kernels\n\n"
               f"Each row deletes one term of an element kernel (`src/se3dyn/_core/elements/`, "
               f"or the Python spec that feeds it), rebuilds the engine and runs the tests with "
               f"`pytest -x`: *killed* means a test failed (the first one is named). The "
               f"mutations, their exact source snippets and the procedure are in "
               f"`tools/mutation_check.py`.\n\n"
               f"Made by `{cmd.strip()}` on {date} (tests: {' '.join(args.tests)}).\n\n"
               f"{text}\n\n{killed} of {len(rows)} mutations killed.\n{notes}")
        with open(os.path.join(ROOT, args.out), "w") as fh:
            fh.write(doc)
    # success: every mutation killed, or surviving with a note saying why
    return 0 if all(res == "killed" or (res == "survived" and m.note) for m, res, _ in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
