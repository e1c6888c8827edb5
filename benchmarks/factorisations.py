"""Full factorisations of the linear solver in a run (a refactorisation refused by its pivot
check factorises anew, ~6 refactorisations' time on the chains), Newton iterations and process
CPU time, for the models of docs/performance.md's index-2 section: se3dyn's defaults, h = 1e-3
(slider-crank 1e-2), rho_inf = 0.9.

Run:  python benchmarks/factorisations.py [MODEL ...]
      (models: slider, chain100, chain1000, closed100, nodes300, tree8, fourbar)
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import se3dyn as sd
import se3dyn.engine.system as system
from se3dyn.io.modelfile import load_model

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "cpp"))
import chain_scaling  # noqa: E402
import make_lu_matrices  # noqa: E402  (the spinning chains and the tree of the LU tests)

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
MODELS = {  # name: (model, t_end, h)
    "slider": (sd.examples.slider_crank, 5.0, 1e-2),
    "chain100": (lambda: make_lu_matrices.chain(100), 1.0, 1e-3),  # spinning links
    "chain1000": (lambda: chain_scaling.chain(1000), 1.0, 1e-3),
    "closed100": (lambda: make_lu_matrices.chain_nodes(100, close=True), 1.0, 1e-3),
    "nodes300": (lambda: chain_scaling.chain_nodes(300), 1.0, 1e-3),
    "tree8": (lambda: make_lu_matrices.binary_tree(8), 1.0, 1e-3),
    "fourbar": (lambda: load_model(EXAMPLES / "a02_n_four_bar.yaml")[0], 2.0, 1e-3),
}


def count(name: str) -> str:
    """One run of model `name`: the full factorisations of each of its steppers (matrix rows:
    count; their first, of the model's generic matrix, left out; the index-3 one solves for the
    initial accelerations), Newton iterations, CPU time."""
    made = []
    stepper = system.Workspace.stepper

    def keep(self, index2, dropped, keep=True, split=True):  # the run's steppers, to read
        stp = stepper(self, index2, dropped, keep, split)     # their counters
        if stp not in made:
            made.append(stp)
        return stp

    system.Workspace.stepper = keep
    try:
        make, t_end, h = MODELS[name]
        s = sd.compile_model(make())
        c0 = time.process_time()
        res = sd.simulate(s, t_end, h, rho_inf=0.9)
        cpu = time.process_time() - c0
    finally:
        system.Workspace.stepper = stepper
    full = ", ".join(f"{stp.lu_stats()[0]}: {stp.serials()[0] - 1}" for stp in made)
    return (f"{name:10s} {res.stats['steps']:5d} steps, {res.stats['newton_iterations']:5d} Newton "
            f"iterations, full factorisations ({full}), {cpu:7.2f} s CPU")


if __name__ == "__main__":
    for name in sys.argv[1:] or MODELS:
        print(count(name), flush=True)
