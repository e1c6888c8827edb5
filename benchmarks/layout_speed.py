"""Speed before and after a change of the Python layout (issue 29), paired in one run.

Times, for each given interpreter (each a venv with its own se3dyn build), alternating so that
the machine's drift hits both alike:

* ``import``: ``import se3dyn`` in a fresh process (wall time of the import alone);
* ``first``: a fresh process's import + ``sd.examples.slider_crank()`` + its first
  ``sd.simulate(model, 5.0, 1e-2, rho_inf=0.9)`` (the README's job, every row recorded);
* ``chain``: the 1000-link spherical chain of ``benchmarks/chain_scaling.py`` for 1 s at
  h = 1e-3 with every row recorded (``compare_exudyn.py``'s ``se3_chain_user`` line), in a
  fresh process, compile excluded.

Prints the median of each and the ratio after/before. Usage::

    python benchmarks/layout_speed.py --before /path/old/.venv/bin/python \
        --after .venv/bin/python --repeats 7
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import textwrap

CODE = {
    "import": """
        import time; t0 = time.perf_counter(); import se3dyn
        print(time.perf_counter() - t0)""",
    "first": """
        import time; t0 = time.perf_counter()
        import se3dyn as sd
        r = sd.simulate(sd.examples.slider_crank(), 5.0, 1e-2, rho_inf=0.9)
        print(time.perf_counter() - t0)""",
    "chain": """
        import time
        import se3dyn as sd
        mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81))
        mb.node("ground", fixed=True)
        J = 0.1**2 / 12.0
        prev = "ground"
        for i in range(1000):
            mb.node(f"b{i}", position=(0.1 * i + 0.05, 0.0, 0.0), mass=1.0,
                    inertia=(1e-4 * J, J, J))
            mb.joint(f"s{i}", "spherical", prev, f"b{i}", at=(0.1 * i, 0.0, 0.0))
            prev = f"b{i}"
        s = sd.compile_model(mb.build())
        t0 = time.perf_counter()
        r = sd.simulate(s, 1.0, 1e-3, rho_inf=0.9)
        print(time.perf_counter() - t0)""",
}


def once(python: str, what: str) -> float:
    out = subprocess.run([python, "-c", textwrap.dedent(CODE[what])], capture_output=True,
                         text=True, check=True)
    return float(out.stdout.split()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", required=True)
    ap.add_argument("--after", required=True)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--chain-repeats", type=int, default=3)
    a = ap.parse_args(argv)
    res = {}
    for what in ("import", "first", "chain"):
        n = a.chain_repeats if what == "chain" else a.repeats
        times = {"before": [], "after": []}
        for i in range(n):
            for key in (("before", "after") if i % 2 == 0 else ("after", "before")):
                times[key].append(once(getattr(a, key), what))
        b, f = statistics.median(times["before"]), statistics.median(times["after"])
        res[what] = {"before": times["before"], "after": times["after"], "ratio": f / b}
        print(f"{what:7s} before {b:8.4f} s  after {f:8.4f} s  after/before {f / b:6.3f}  "
              f"(medians of {n}; min {min(times['before']):.4f} / {min(times['after']):.4f})",
              flush=True)
    print(json.dumps(res))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
