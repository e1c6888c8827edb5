"""The layers of the package are checked, not hoped for (issue 29, docs/design.md).

* the import-linter contracts of pyproject.toml hold (a lower layer never imports a higher one;
  nothing inside the package imports its face or the old-path aliases);
* there is no import cycle between modules, function-level imports included (imports under
  ``if TYPE_CHECKING:`` are annotations only and never run);
* the contract catches an upward import: a copy of the package with one added fails it, naming
  the import;
* ``import se3dyn`` loads nothing heavy and changes no process state; the old import paths of
  the flat layout keep working (or, where the old module name is a function of the face, fail
  naming the new module);
* no function of the package is longer than 120 lines of code (docstring aside) without its
  reason written beside it (``# long: ...`` on the line of the ``def``).
"""

from __future__ import annotations

import ast
import os
import re
import shutil
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "se3dyn"
LINT = shutil.which("lint-imports", path=os.path.dirname(sys.executable)) or \
    shutil.which("lint-imports")

needs_linter = pytest.mark.skipif(LINT is None, reason="import-linter is not installed "
                                  "(pip install -e '.[test]')")


def _lint(cwd: Path, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([LINT, "--no-cache"], cwd=cwd, capture_output=True, text=True,
                          env=env, timeout=300)


@needs_linter
def test_the_layer_contracts_of_pyproject_hold():
    out = _lint(ROOT)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "2 kept, 0 broken" in out.stdout


def _graph(package: str = "se3dyn"):
    grimp = pytest.importorskip("grimp")
    return grimp.build_graph(package, exclude_type_checking_imports=True, cache_dir=None)


def _cycles(adj: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index, low, on, stack, out, counter = {}, {}, set(), [], [], [0]
    for root in sorted(adj):
        if root in index:
            continue
        work = [(root, iter(sorted(adj[root])))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(adj[w]))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    x = stack.pop()
                    on.discard(x)
                    comp.append(x)
                    if x == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def test_the_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycle_between_modules_function_level_imports_included():
    g = _graph()
    adj = {m: set(g.find_modules_directly_imported_by(m)) for m in g.modules}
    cycles = _cycles(adj)
    assert not cycles, "import cycles: " + "; ".join(" <-> ".join(c) for c in cycles)


@needs_linter
def test_an_upward_import_breaks_the_contract(tmp_path):
    """A copy of the package under another name, with the engine importing the time loop (a
    lower layer importing a higher one): the contract fails and names the import."""
    name = "se3dyncopy"
    dst = tmp_path / "src" / name
    shutil.copytree(SRC, dst, ignore=shutil.ignore_patterns("__pycache__", "*.so", "*.hpp",
                                                            "*.cpp", "static"))
    for p in dst.rglob("*.py*"):
        p.write_text(re.sub(r"\bse3dyn\b", name, p.read_text()))
    target = dst / "engine" / "system.py"
    target.write_text(target.read_text() + f"\n\ndef _upward():\n    from {name}.dynamics "
                      "import run  # an upward import\n\n    return run\n")
    (tmp_path / "pyproject.toml").write_text(
        re.sub(r"\bse3dyn\b", name, (ROOT / "pyproject.toml").read_text()))
    env = dict(os.environ, PYTHONPATH=str(tmp_path / "src"))
    out = _lint(tmp_path, env)
    assert out.returncode != 0, out.stdout
    assert f"{name}.engine is not allowed to import {name}.dynamics" in out.stdout, out.stdout
    assert f"{name}.engine.system -> {name}.dynamics.run" in out.stdout, out.stdout


def _fresh(code: str) -> str:
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_THREAD_TIMEOUT"}
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True,
                          text=True, check=True, env=env, timeout=120).stdout


def test_import_se3dyn_loads_nothing_heavy_and_changes_no_process_state():
    out = _fresh("""
        import gc, os, signal, sys
        before = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
        import se3dyn as sd
        heavy = [m for m in ("numpy", "scipy", "h5py", "yaml", "se3dyn._core._engine")
                 if m in sys.modules]
        print(heavy, gc.isenabled(), os.environ.get("OPENBLAS_THREAD_TIMEOUT"),
              (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == before)
        print(type(sd.simulate).__name__, sd.ModelBuilder.__module__, sd.__version__)
    """).splitlines()
    assert out[0] == "[] True None True"
    assert out[1].split()[:2] == ["function", "se3dyn.model.builder"]


def test_every_public_name_of_the_face_loads_and_dir_lists_it():
    import se3dyn as sd

    for name in sd.__all__:
        assert getattr(sd, name) is not None, name
        assert name in dir(sd)
    with pytest.raises(AttributeError, match="no attribute 'simulat'"):
        sd.simulat  # noqa: B018


def test_the_old_paths_keep_working_and_say_where_the_modules_went():
    out = _fresh("""
        import warnings
        warnings.simplefilter("error", DeprecationWarning)
        try:
            import se3dyn.modelfile
        except DeprecationWarning as w:
            print(w)
        warnings.simplefilter("ignore", DeprecationWarning)
        import se3dyn.h5, se3dyn.modelfile, se3dyn.io.h5, se3dyn.io.modelfile
        from se3dyn.system import evaluate, LinearSolver, Workspace
        from se3dyn.integrator import State, SolverMemory
        import se3dyn.engine.evaluate as ev, se3dyn.engine.linsolve as ls
        print(se3dyn.h5.read_results is se3dyn.io.h5.read_results,
              se3dyn.modelfile.load_model is se3dyn.io.modelfile.load_model,
              evaluate is ev.evaluate, LinearSolver is ls.LinearSolver)
        import se3dyn as sd
        try:
            import se3dyn.simulate
        except ImportError as e:
            print(e)
        print(type(sd.simulate).__name__, type(sd.kinematics).__name__)
    """).splitlines()
    assert "se3dyn.modelfile moved to se3dyn.io.modelfile" in out[0]
    assert out[1] == "True True True True"
    assert "se3dyn.simulate is now se3dyn.dynamics.run" in out[2]
    assert out[3] == "function function"


def test_results_show_names_its_new_place():
    import numpy as np

    from se3dyn.results.results import Results

    res = Results.__new__(Results)
    with pytest.raises(AttributeError, match=r"se3dyn.show\(result\)"):
        res.show()
    assert np is not None


LIMIT = 120


def _long_functions():
    for p in sorted(SRC.rglob("*.py")):
        lines = p.read_text().splitlines()
        for node in ast.walk(ast.parse("\n".join(lines))):
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            body = node.body
            first = body[0]
            doc = (isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant)
                   and isinstance(first.value.value, str))
            start = (body[1].lineno if len(body) > 1 else first.end_lineno) if doc else \
                first.lineno
            n = node.end_lineno - start + 1
            if n > LIMIT:
                yield p.relative_to(SRC.parent), node, n, lines[node.lineno - 1]


def test_no_function_over_120_lines_of_code_without_its_reason_beside_it():
    bare = [f"{p}:{node.lineno} {node.name} ({n} lines)"
            for p, node, n, line in _long_functions() if "# long:" not in line]
    assert not bare, ("functions over 120 lines of code with no '# long: <reason>' on their "
                      "def line: " + "; ".join(bare))


def test_the_function_length_rule_sees_a_long_function(tmp_path, monkeypatch):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        body = "\n".join(f"    x{i} = {i}" for i in range(LIMIT + 1))
    (tmp_path / "se3dyn").mkdir()
    (tmp_path / "se3dyn" / "m.py").write_text(f'def f():\n    """doc"""\n{body}\n')
    monkeypatch.setattr(sys.modules[__name__], "SRC", tmp_path / "se3dyn")
    found = list(_long_functions())
    assert [(node.name, n) for _, node, n, _ in found] == [("f", LIMIT + 1)]
