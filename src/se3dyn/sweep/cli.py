"""``se3dyn sweep``: the command-line side of :func:`se3dyn.sweep.run_sweep`.

:func:`add_arguments` declares the sweep's own options (the run-time overrides ``--t-end``,
``--step``, ... are declared by :mod:`se3dyn.cli.commands`, shared with ``se3dyn run``);
:func:`main`
runs it. Exit codes: 0 every run ok, 1 some runs failed (the summary is complete), 2 bad input
(one line, before any run starts), 130 interrupted (the summary holds the finished runs;
``--resume`` completes it).
"""

from __future__ import annotations

import argparse
import sys

__all__ = ["add_arguments", "main"]


def _count(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return n


def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``se3dyn sweep`` (besides the run-time overrides)."""
    p.add_argument("model", help="model file (YAML)")
    p.add_argument("--vary", action="append", required=True, metavar="PATH=SPEC",
                   help="a model-file field and its values: V1,V2,... | START:STOP:N | "
                        "uniform(A,B) | loguniform(A,B) | normal(MEAN,SD), e.g. "
                        "joints.8.damping.0=0.5,1,2; repeat --vary for more paths (grid: "
                        "every combination)")
    p.add_argument("--method", choices=("grid", "random", "lhs"), default="grid",
                   help="full grid of the lists/ranges (default), or --samples random or "
                        "Latin-hypercube points")
    p.add_argument("--samples", type=_count, metavar="N", help="runs of a random/lhs sweep")
    p.add_argument("--seed", type=_int, help="seed of random/lhs sampling (default: drawn, "
                                             "stored in DIR/sweep.json)")
    p.add_argument("--metric", action="append", default=[], metavar="NAME=FUNC(EXPR)",
                   help="a summary column: FUNC in max|min|final|mean|rms of a channel or "
                        "abs(channel), e.g. peak=max(abs(joint/1/multiplier/3))")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output folder: summary.csv, runs/*.h5, sweep.json, journal.jsonl")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="a running dask scheduler (tcp://host:port); default: a local cluster")
    p.add_argument("--workers", type=_count, metavar="N",
                   help="worker processes of the local cluster (default: one per core)")
    p.add_argument("--resume", action="store_true",
                   help="complete the sweep in DIR: run only what is missing")
    p.add_argument("--retry-failed", action="store_true",
                   help="with --resume: run the failed runs again too")
    p.add_argument("--h5", choices=("shared", "client", "none"), default="shared",
                   help="results files: written by the workers into DIR/runs (shared folder, "
                        "default), sent back to this client, or none (summary only)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def main(args: argparse.Namespace, overrides: dict) -> int:
    """Run ``se3dyn sweep`` for parsed ``args``; returns the exit code (bad input raises
    :class:`~se3dyn.errors.ModelError` or ImportError, turned into exit 2 by the caller)."""
    from se3dyn._version import __version__
    from se3dyn.sweep.runner import SweepInterrupted, execute_plan, prepare

    plan = prepare(args.model, args.vary, method=args.method, samples=args.samples,
                   seed=args.seed, metrics=args.metric, overrides=overrides, out=args.out,
                   h5=args.h5)
    paths = ", ".join(v.path for v in plan.variables)
    print(f"se3dyn {__version__} sweep: {args.model}, {len(plan.runs)} runs "
          f"({args.method} over {paths}) -> {plan.out}")
    try:
        rows = execute_plan(plan, workers=args.workers, scheduler=args.scheduler,
                            resume=args.resume, retry_failed=args.retry_failed,
                            progress=False if args.quiet else None, as_frame=False, log=print)
    except SweepInterrupted as exc:
        print(f"se3dyn: error: {exc}", file=sys.stderr)
        return 130
    print(f"  summary: {plan.out / 'summary.csv'}")
    failed = [r for r in rows if r["status"] != "ok"]
    if failed:
        r = failed[0]
        print(f"se3dyn: {len(failed)} of {len(rows)} runs failed; run {r['run']}: "
              f"{r['message']}", file=sys.stderr)
        return 1
    return 0
