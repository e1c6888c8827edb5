"""Run the gallery models and write the comparison plots ``docs/gallery/<name>.png``.

Usage (from the repository root)::

    python3 docs/gallery/make_plots.py [a01 a02 a03 a04 a05] [--a01-t-end T] [--a02-t-end T]
                                       [--rho-inf R] [--formulation index2|index3] [--no-plot]

Each problem is run from its model file ``examples/<name>.yaml`` with the file's settings and
compared with the exact / independently computed solution used by ``tests/test_gallery.py``
(A03: the published reference of ``tests/test_a03_squeezer.py``), imported from there, so the
plots and the tests share one definition. The measured numbers
(error against the reference, steps, Newton iterations, wall time, redundant equations left
out, constraint violation) are printed; the pages in this folder quote them. ``--rho-inf`` and
``--formulation`` override the model files' settings (the comparisons quoted on the pages);
``--no-plot`` leaves the PNGs untouched.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import se3dyn as sd  # noqa: E402
from se3dyn.errors import NewtonError  # noqa: E402
from se3dyn.io.modelfile import load_model  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
OUT = Path(__file__).resolve().parent
sys.path.insert(0, str(ROOT / "tests"))
import test_a03_squeezer as a03ref  # noqa: E402
import test_gallery as ref  # noqa: E402

OVERRIDE = {}  # settings from the command line (--rho-inf, --formulation)
SAVE = True  # write the PNGs (--no-plot: print the numbers only)


def _save(fig, name):
    if SAVE:
        fig.savefig(OUT / name, dpi=110)
    plt.close(fig)


def _run(name, **override):
    model, settings = load_model(ROOT / "examples" / f"{name}.yaml")
    settings.update(override)
    settings.update(OVERRIDE)
    try:
        res = sd.simulate(model, **settings)
        failed = None
    except NewtonError as exc:
        res, failed = exc.result, str(exc).splitlines()[0]
    st = res.stats
    print(f"\n== {name}: t_end={settings['t_end']} h={settings['step']} "
          f"rho_inf={settings['rho_inf']} formulation={st.get('formulation')}")
    print(f"   steps {st['steps']}, Newton iterations {st['newton_iterations']} "
          f"({st['newton_iterations'] / max(st['steps'], 1):.2f}/step), "
          f"wall time {st['wall_time']:.1f} s, unknowns {st['unknowns']}, "
          f"multipliers {st['multipliers']}")
    print(f"   redundant equations left out {len(st.get('redundant', []))}; max constraint "
          f"violation (solver's measure, all equations) {res.constraint.max():.1e}")
    if failed:
        print(f"   FAILED: {failed}")
    return model, res


def a01(t_end=None):
    _, res = _run("a01_simple_pendulum", **({} if t_end is None else {"t_end": t_end}))
    th = ref._pendulum_exact(res.t)
    p = res.node_position("P1")
    ex, ey = p[:, 0] - np.sin(th), p[:, 1] + np.cos(th)
    T = 4 * math.sqrt(1 / ref.G) * ref.ellipk(0.5)
    tc = ref._crossings(res.t, p[:, 0])
    T_num = (tc[-1] - tc[0]) / ((len(tc) - 1) / 2)
    E = res.total_energy
    print(f"   max |x - x_exact| {np.abs(ex).max():.2e} m, max |y - y_exact| "
          f"{np.abs(ey).max():.2e} m (allowed 1e-3)")
    print(f"   period {T_num:.7f} s, exact {T:.7f} s, relative error {abs(T_num - T) / T:.1e}")
    print(f"   energy drift max |E - E0| {np.abs(E - E[0]).max():.2e} J of m g L = 9.81 J")
    win = [np.abs(E - E[0])[(res.t > a) & (res.t <= a + 10)].max()
           for a in np.arange(0.0, res.t[-1] - 1e-9, 10.0)]
    print(f"   max |E - E0| per 10 s window: {', '.join(f'{w:.2e}' for w in win)} J; "
          f"E - E0 at the end {E[-1] - E[0]:.2e} J")
    fig, ax = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    ax[0].plot(res.t, p[:, 0], label="x se3dyn")
    ax[0].plot(res.t, p[:, 1], label="y se3dyn")
    ax[0].plot(res.t, np.sin(th), "k--", lw=0.8, label="exact")
    ax[0].plot(res.t, -np.cos(th), "k--", lw=0.8)
    ax[0].set_ylabel("P1 (m)")
    ax[0].legend(loc="upper right", fontsize=8)
    ax[1].semilogy(res.t, np.abs(ex) + 1e-16, label="|x error|")
    ax[1].semilogy(res.t, np.abs(ey) + 1e-16, label="|y error|")
    ax[1].axhline(1e-3, color="r", lw=0.8, label="allowed (high precision)")
    ax[1].set_xlabel("t (s)")
    ax[1].set_ylabel("error (m)")
    ax[1].legend(loc="lower right", fontsize=8)
    fig.suptitle("A01 simple pendulum: P1 vs the exact solution")
    fig.tight_layout()
    _save(fig, "a01_simple_pendulum.png")


def a02(t_end):
    model, res = _run("a02_n_four_bar", t_end=t_end)
    n = (sum(nd.mass > 0 for nd in model.nodes) - 1) // 2
    psi, psid = ref._four_bar_exact(n, res.t)
    B0 = res.node_position("b0")
    v = res.node_velocity("b0", frame="inertial")[:, :3]
    ep = max(np.abs(B0[:, 0] - np.sin(psi)).max(), np.abs(B0[:, 1] - np.cos(psi)).max())
    ev = max(np.abs(v[:, 0] - np.cos(psi) * psid).max(),
             np.abs(v[:, 1] + np.sin(psi) * psid).max())
    print(f"   N = {n}; max B0 position error {ep:.2e} m, velocity error {ev:.2e} m/s "
          f"(max speed {np.abs(psid).max():.2f} m/s); revolutions {psi[-1] / (2 * math.pi):.2f}")
    # geometry: crank and coupler lengths (1 m) and parallel cranks, everywhere and near the
    # horizontal (singular) positions psi = pi/2 mod pi, |cos psi| < 0.05 (within 2.9 deg)
    B = [res.node_position(f"b{i}") for i in range(n + 1)]
    crank = max(np.abs(np.linalg.norm(B[i] - (i, 0.0, 0.0), axis=1) - 1).max()
                for i in range(n + 1))
    coupler = max(np.abs(np.linalg.norm(B[i] - B[i - 1], axis=1) - 1).max()
                  for i in range(1, n + 1))
    par = np.max([np.abs(B[i] - (i, 0.0, 0.0) - B[0]).max(axis=1) for i in range(1, n + 1)],
                 axis=0)
    sing = np.abs(np.cos(psi)) < 0.05
    eps = max(np.abs(B0[sing, 0] - np.sin(psi[sing])).max(initial=0),
              np.abs(B0[sing, 1] - np.cos(psi[sing])).max(initial=0))
    passes = np.count_nonzero(np.diff(np.floor(psi / math.pi - 0.5)) > 0)
    E = res.total_energy
    print(f"   link length errors: cranks {crank:.1e} m, couplers {coupler:.1e} m; cranks parallel "
          f"to {par.max():.1e} m; energy drift max |E - E0| {np.abs(E - E[0]).max():.2e} J "
          f"(E0 = {E[0]:.2f} J)")
    print(f"   singular (horizontal) positions passed: {passes}; closest |cos psi| at an output "
          f"step {np.abs(np.cos(psi)).min():.1e}; within |cos psi| < 0.05 ({sing.sum()} steps): "
          f"constraint violation {res.constraint[sing].max(initial=0):.1e}, cranks parallel "
          f"to {par[sing].max(initial=0):.1e} m, B0 position error {eps:.1e} m")
    fig, ax = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    ax[0].plot(res.t, B0[:, 0], label="x se3dyn")
    ax[0].plot(res.t, B0[:, 1], label="y se3dyn")
    ax[0].plot(res.t, np.sin(psi), "k--", lw=0.8, label="exact (1-dof reduction)")
    ax[0].plot(res.t, np.cos(psi), "k--", lw=0.8)
    ax[0].set_ylabel("B0 (m)")
    ax[0].legend(loc="upper right", fontsize=8)
    ax[1].plot(res.t, v[:, 0], label="vx se3dyn")
    ax[1].plot(res.t, v[:, 1], label="vy se3dyn")
    ax[1].plot(res.t, np.cos(psi) * psid, "k--", lw=0.8, label="exact")
    ax[1].plot(res.t, -np.sin(psi) * psid, "k--", lw=0.8)
    ax[1].set_xlabel("t (s)")
    ax[1].set_ylabel("B0 velocity (m/s)")
    ax[1].legend(loc="upper right", fontsize=8)
    fig.suptitle(f"A02 N-four-bar (N = {n}): B0 vs the exact motion")
    fig.tight_layout()
    _save(fig, "a02_n_four_bar.png")


def a03():
    model, res = _run("a03_andrews_squeezer")
    q, qd = a03ref.angles(res)
    eq, eqd = q[-1] - a03ref.Q_REF, qd[-1] - a03ref.QD_REF
    print("   at t = 0.03 s, se3dyn - published (angle rad, rate rad/s):")
    for name, a, b in zip(a03ref.ANGLES, eq, eqd, strict=True):
        print(f"     {name:8s} {a:+.2e} {b:+.2e}")
    gap = res.kinetic + res.spring - res.spring[0] - res.work_actuators
    W = a03ref.PAR["mom"] * (a03ref.Q_REF[0] - a03ref.Q0[0])
    T_ref = 0.5 * a03ref.QD_REF @ a03ref.mass_matrix(a03ref.Q_REF) @ a03ref.QD_REF
    print(f"   energy: max |T + V - V0 - W| {np.abs(gap).max():.2e} J (W = {W:.4f} J); "
          f"T(0.03) {res.kinetic[-1]:.6f} J (published state {T_ref:.6f} J)")
    s, kw = sd.compile_model(model), dict(rho_inf=res.stats["rho_inf"],
                                          formulation=res.stats["formulation"])
    hs = [8e-5, 4e-5, 2e-5, 1e-5, 5e-6]
    qs = [a03ref.angles(sd.simulate(s, a03ref.T_END, h, **kw))[0][-1] for h in hs]
    err = [np.abs(x - a03ref.Q_REF).max() for x in qs]
    extra = [np.abs(b + (b - a) / 3 - a03ref.Q_REF).max()  # Richardson, order 2
             for a, b in zip(qs[:-1], qs[1:], strict=True)]
    for i, h in enumerate(hs):
        order = f", order {math.log2(err[i - 1] / err[i]):.3f}" if i else ""
        rich = f", Richardson with 2h {extra[i - 1]:.1e} rad" if i else ""
        print(f"   h = {h:.0e}: max angle error {err[i]:.2e} rad{order}{rich}")
    fig, ax = plt.subplots(3, 1, figsize=(7, 8))
    for k, name in enumerate(a03ref.ANGLES):
        a = ax[0] if k < 2 else ax[1]
        (line,) = a.plot(res.t * 1e3, q[:, k], label=name)
        a.plot(a03ref.T_END * 1e3, a03ref.Q_REF[k], "o", mfc="none", color=line.get_color())
    ax[0].set_ylabel("angle (rad)")
    ax[0].legend(loc="upper left", fontsize=8, title="o: published at 0.03 s",
                 title_fontsize=8)
    ax[1].set_ylabel("angle (rad)")
    ax[1].set_xlabel("t (ms)")
    ax[1].set_ylim(-0.75, 1.75)
    ax[1].legend(loc="upper left", fontsize=8, ncol=5)
    ax[2].loglog(hs, err, "o-", label="se3dyn at h")
    ax[2].loglog(hs[1:], extra, "s--", label="Richardson extrapolation (h, 2h)")
    ax[2].loglog(hs, 3 * err[-1] * (np.array(hs) / hs[-1]) ** 2, "k:", lw=0.8, label="slope 2")
    ax[2].xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax[2].set_xlabel("h (s)")
    ax[2].set_ylabel("max angle error at 0.03 s (rad)")
    ax[2].legend(loc="lower right", fontsize=8)
    fig.suptitle("A03 Andrews' squeezing mechanism vs the published reference")
    fig.tight_layout()
    _save(fig, "a03_andrews_squeezer.png")


def a04():
    _, res = _run("a04_bricard")
    P3 = res.node_position("p3")
    E = res.total_energy
    print(f"   energy drift max |E - E0| {np.abs(E - E[0]).max():.2e} J (E0 = {E[0]:.2f} J); "
          f"P3 range {np.ptp(P3, axis=0).round(3)} m")
    pts = [res.node_position(f"p{i}") for i in range(6)]
    rods = max(np.abs(np.linalg.norm(b - a, axis=1) - 1).max()
               for a, b in zip(pts[:-1], pts[1:], strict=True))
    print(f"   rod length errors {rods:.1e} m; P5 hinge stays at (0, 0, 1) to "
          f"{np.abs(pts[5] - (0.0, 0.0, 1.0)).max():.1e} m")
    fig, ax = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    for k, c in enumerate("xyz"):
        ax[0].plot(res.t, P3[:, k], label=f"P3 {c}")
    ax[0].set_ylabel("P3 (m)")
    ax[0].legend(loc="upper right", fontsize=8)
    ax[1].plot(res.t, E - E[0])
    ax[1].set_xlabel("t (s)")
    ax[1].set_ylabel("E - E0 (J)")
    fig.suptitle("A04 Bricard mechanism: P3 and the energy variation")
    fig.tight_layout()
    _save(fig, "a04_bricard.png")


def a05():
    model, res = _run("a05_flyball_governor")
    s_ref, w_ref, L = ref._flyball_rigid_limit(res.t)
    s = res.node_position("slider")[:, 2]
    w = res.node_velocity("shaft")[:, 5]
    Lz = ref._axial_momentum(model, res)
    eb = res.energy_balance
    print(f"   max |s - s_rigid| {np.abs(s - s_ref).max():.2e} m, max |w - w_rigid| "
          f"{np.abs(w - w_ref).max():.2e} rad/s; momentum drift {np.abs(Lz - L).max() / L:.1e} "
          f"(relative); energy balance error {np.abs(eb - eb[0]).max():.2e} J of {eb[0]:.1f} J; "
          f"dissipated {res.dissipation[-1]:.2e} J")
    fig, ax = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    ax[0].plot(res.t, s, label="slider s, se3dyn (K = 8e5 N/m)")
    ax[0].plot(res.t, s_ref, "k--", lw=0.8, label="rigid-strut limit")
    ax[0].set_ylabel("s (m)")
    ax[0].legend(loc="upper right", fontsize=8)
    ax[1].plot(res.t, w, label="shaft rate, se3dyn")
    ax[1].plot(res.t, w_ref, "k--", lw=0.8, label="rigid-strut limit")
    ax[1].set_xlabel("t (s)")
    ax[1].set_ylabel("omega (rad/s)")
    ax[1].legend(loc="upper right", fontsize=8)
    fig.suptitle("A05 stiff flyball governor")
    fig.tight_layout()
    _save(fig, "a05_flyball_governor.png")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("problems", nargs="*", default=["a01", "a02", "a03", "a04", "a05"])
    ap.add_argument("--a02-t-end", type=float, default=20.0,
                    help="A02 horizon (the library's 20 s take long with N = 40)")
    ap.add_argument("--a01-t-end", type=float, help="A01 horizon (default: the model file's)")
    ap.add_argument("--rho-inf", type=float, help="override the model files' rho_inf")
    ap.add_argument("--formulation", choices=("index2", "index3"),
                    help="override the integrator formulation (default: simulate's, index2)")
    ap.add_argument("--no-plot", action="store_true", help="print the numbers only")
    args = ap.parse_args()
    global SAVE
    SAVE = not args.no_plot
    if args.rho_inf is not None:
        OVERRIDE["rho_inf"] = args.rho_inf
    if args.formulation:
        OVERRIDE["formulation"] = args.formulation
    for p in args.problems:
        if p == "a02":
            a02(args.a02_t_end)
        elif p == "a01":
            a01(args.a01_t_end)
        else:
            {"a03": a03, "a04": a04, "a05": a05}[p]()


if __name__ == "__main__":
    main()
