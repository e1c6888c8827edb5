"""Fingerprints of every kind of run, to show a refactoring changed no number (issue 29).

Prints (or writes with ``--out``) a JSON map run name -> SHA-256 of each channel's bytes and the
solver statistics. Run it before and after a change and compare with ``--compare OLD.json``:
bit-identical results give identical digests. The runs: every model file of ``examples/`` at
its own settings, the Python slider-crank at the README's settings, and the other kinds of run
(index-3, full Newton, adaptive steps, the global-error companion, no condensation, resumed
from a state, statics, kinematics, assembly), so every path of the time loop and of the
analysis is covered.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

import se3dyn as sd
from se3dyn.io.modelfile import load_model

ROOT = Path(__file__).resolve().parents[1]


def _h(a) -> str:
    data = np.ascontiguousarray(np.asarray(a, dtype=float)).tobytes()
    return hashlib.sha256(data).hexdigest()[:16]


def _digest_results(r) -> dict:
    out = {ch: _h(getattr(r, ch)) for ch in
           ("t", "H", "v", "vd", "lam", "kinetic", "potential", "spring", "dissipation")}
    for k, v in sorted(r.stats.items()):
        if isinstance(v, (int, float, str, bool)) and "time" not in k and "seconds" not in k:
            out[k] = v
        elif isinstance(v, np.ndarray):
            out[k] = _h(v)
    state = r.stats.get("final_state")
    if state is not None:
        fields = ("H", "HJ", "v", "vd", "a", "lam", "alpha", "power")
        out["final_state"] = _h(np.concatenate([np.ravel(getattr(state, f)) for f in fields]))
    return out


def runs() -> dict:
    out = {}
    for p in sorted((ROOT / "examples").glob("*.yaml")):
        model, settings = load_model(p)
        out[p.name] = _digest_results(sd.simulate(model, **settings))
    sc = sd.examples.slider_crank()
    out["slider_crank_readme"] = _digest_results(sd.simulate(sc, 5.0, 1e-2, rho_inf=0.9))
    out["slider_crank_index3"] = _digest_results(
        sd.simulate(sc, 1.0, 1e-2, formulation="index3"))
    out["slider_crank_full_newton"] = _digest_results(sd.simulate(sc, 1.0, 1e-2, newton="full"))
    out["slider_crank_adaptive"] = _digest_results(sd.simulate(sc, 1.0, 1e-2, tol=1e-5))
    out["slider_crank_global_error"] = _digest_results(
        sd.simulate(sc, 0.5, 1e-2, tol=1e-5, global_error=True))
    out["slider_crank_uncondensed"] = _digest_results(sd.simulate(sc, 1.0, 1e-2, condense=False))
    out["slider_crank_output_step"] = _digest_results(
        sd.simulate(sc, 1.0, 1e-2, tol=1e-5, output_step=0.05))
    bodies = sd.examples.slider_crank_bodies()
    r = sd.simulate(bodies, 0.5, 1e-2)
    out["bodies"] = _digest_results(r)
    out["bodies_resumed"] = _digest_results(
        sd.simulate(bodies, 1.0, 1e-2, t_start=0.5, initial_state=r.stats["final_state"]))
    mb = sd.ModelBuilder()  # a cantilever beam rolled up by an end moment (tests/test_beam.py)
    mb.node("root", fixed=True)
    mb.node("tip", position=(1.0, 0.0, 0.0))
    mb.beam("b", "root", "tip", elements=8, EA=1e4, GA=1e4, GJ=50.0, EI=100.0)
    mb.load("m", "tip", torque=(0.0, 0.0, 2 * np.pi * 100.0), torque_frame="body")
    st = sd.static_equilibrium(mb.build(), load_steps=4)
    out["statics_rollup"] = {k: _h(v) for k, v in vars(st).items()
                              if isinstance(v, np.ndarray)}
    kin = sd.kinematics(sc, {"1": lambda t: 2.0 * t}, np.linspace(0.0, 1.0, 51))
    out["kinematics"] = {k: _h(v) for k, v in vars(kin).items() if isinstance(v, np.ndarray)}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out")
    ap.add_argument("--compare")
    a = ap.parse_args(argv)
    d = runs()
    text = json.dumps(d, indent=1, sort_keys=True)
    if a.out:
        Path(a.out).write_text(text)
    if a.compare:
        old = json.loads(Path(a.compare).read_text())
        # (an entry the old digests lack is a new output, e.g. a new result field: listed,
        # not a difference of the numbers)
        def same(k):
            o, n = old.get(k), d.get(k)
            if isinstance(o, dict) and isinstance(n, dict):
                for extra in sorted(set(n) - set(o)):
                    print(f"new in {k}: {extra}")
                return all(n.get(x) == v for x, v in o.items())
            return o == n

        bad = [k for k in sorted(set(old) | set(d)) if not same(k)]
        for k in bad:
            print(f"DIFFERS: {k}: {old.get(k)} != {d.get(k)}")
        print(f"{len(d) - len(bad)} of {len(d)} runs bit-identical")
        return 1 if bad else 0
    if not a.out:
        print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
