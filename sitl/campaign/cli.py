"""``quadsitl campaign SPEC [--runs N] [--out DIR] [--workers K | --scheduler tcp://HOST:PORT]``.

Kept here (not in ``sitl/cli.py``) so the main command line only registers the subcommand;
nothing heavy (numba, Dask) is imported until the command runs.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def add_campaign_parser(sub) -> None:
    """Register ``campaign`` on the ``quadsitl`` subparsers."""
    p = sub.add_parser(
        "campaign",
        help="Monte Carlo robustness campaign: many randomised runs, indices in Parquet, summary, figures",
        description=(
            "Fly a campaign spec (config/campaigns/NAME.toml or a path) with the batch engine: every run "
            "with every controller, rows appended to Parquet as chunks finish (an interrupted campaign "
            "resumes), then summary.md and figures/ in the output directory."
        ),
    )
    p.add_argument("spec", help="campaign spec: a name in config/campaigns or a path")
    p.add_argument("--runs", type=int, default=None, help="number of runs (default: the spec's)")
    p.add_argument("--out", default=None, help="output directory (default: out/campaigns/<name>)")
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--workers", type=int, default=None, help="local worker processes (default: one per core)"
    )
    where.add_argument(
        "--scheduler",
        default=None,
        metavar="tcp://HOST:PORT",
        help="run on a Dask cluster (dask scheduler + dask worker; needs quadsitl[cluster])",
    )
    p.add_argument(
        "--full-stack",
        type=int,
        default=0,
        metavar="K",
        help="also fly K runs (spread over the campaign) through the whole in-process flight stack and "
        "compare their indices with the batch engine's; exit 1 if any differs",
    )
    p.add_argument("--no-figures", action="store_true", help="write the table and summary only")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run_command)


def run_command(args: argparse.Namespace) -> int:
    """``quadsitl campaign run``: load the spec, fly every run on the batch engine (and
    ``--full-stack`` runs through the whole stack for comparison), write the results, summary, report
    and figures; 2 for a refused option (before flying anything), 1 when a full-stack run differs
    from the batch engine, else 0."""
    try:
        import numba  # noqa: F401
    except ImportError:
        print("quadsitl campaign needs numba for its batch engine (a dependency of quadsitl: reinstall "
              "quadsitl, or pip install numba)", file=sys.stderr)  # fmt: skip
        return 2
    from . import full_stack
    from .report import write_report
    from .runner import run_campaign
    from .spec import load_campaign
    from .summary import summary_markdown

    if args.workers is not None and args.workers < 1:
        print(f"quadsitl campaign: --workers {args.workers} is invalid; allowed: >= 1", file=sys.stderr)
        return 2
    spec = load_campaign(args.spec, runs=args.runs)
    check_runs: list[int] = []
    if args.full_stack:
        try:  # refuse before flying anything, not after
            check_runs = full_stack.pick_runs(spec.runs, args.full_stack)
            why = full_stack.refusal(spec)
            if why:
                raise full_stack.FullStackRefused(why)
        except full_stack.FullStackRefused as exc:
            print(f"quadsitl campaign: {exc}", file=sys.stderr)
            return 2
    for warning in spec.warnings:
        print(f"quadsitl campaign: warning: {warning}", file=sys.stderr)
    out = Path(args.out) if args.out else Path("out") / "campaigns" / spec.name
    where = args.scheduler or f"{args.workers or 'one per core'} local worker(s)"
    print(
        f"campaign {spec.name}: {spec.runs} runs x {len(spec.controllers)} controllers "
        f"({', '.join(spec.controller_names)}), scenario {spec.scenario.name}, seed {spec.seed}, "
        f"wire float32 {'on' if spec.wire_float32 else 'off'}; {where}; results in {out}/",
        flush=True,
    )
    result = run_campaign(
        spec, out, workers=args.workers, scheduler=args.scheduler, progress=not args.no_progress
    )
    flown = f"{result.flown_runs} runs flown" + (
        f", {result.skipped_runs} already done" if result.skipped_runs else ""
    )
    print(f"{flown} in {result.wall_s:.1f} s (kernels ready in {result.warm_up_s:.1f} s; {result.executor})")
    if args.no_figures:
        summary = out / "summary.md"
        summary.write_text(summary_markdown(result.table, spec))
        files = [summary]
    else:
        files = write_report(spec, result.table, out)
    verdict = 0
    if check_runs:
        print(f"flying run(s) {', '.join(map(str, check_runs))} again through the full in-process stack ...",
              flush=True)  # fmt: skip
        results = full_stack.check(
            spec, result.table, check_runs, progress=lambda text: print(text, flush=True)
        )
        with open(files[0], "a") as summary_file:
            summary_file.write("\n" + full_stack.markdown(results, results[0].rel_tol))
        differing = [r for r in results if not r.agrees]
        print(f"full stack: {len(results) - len(differing)} of {len(results)} agree with the batch engine"
              + (f"; {len(differing)} DIFFER (see {files[0]})" if differing else ""))  # fmt: skip
        verdict = 1 if differing else 0
    text = files[0].read_text()
    start = text.index("## Faults" if "## Faults" in text else "## Headline")  # a fault study: ranking too
    end = text.index("\n## ", text.index("## Headline") + 3)
    print(text[start:end].strip())
    print(f"\nresults: {result.results_path}")
    print(f"summary: {files[0]}")
    if len(files) > 1:
        print(f"figures: {out / 'figures'}/ ({len(files) - 1} files)")
    return verdict
