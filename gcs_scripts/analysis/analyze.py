"""``quadsitl analyze``: the paper's indices and figures for recorded runs, from logs only.

For each log (a recorder session ``NAME.parquet``, a ``NAME.parts/`` directory left by a
recorder that died, an in-process run's Parquet file, or the autopilot's flight log ``.ulg``)
this builds a FlightRecord
(:func:`~gcs_scripts.analysis.log_reader.read_session`) and writes to ``--out``:

* ``comparison.md``: the runs (source, scenario, controller, window, samples) and one table of
  final errors, ISE and IADU with a column per run (:func:`tables.comparison_markdown`);
* ``comparison_{path3d,position,position_error,orientation,controls}.png``: the paper's figures
  with the runs overlaid (:func:`figures.paper_figures`; the first run's reference is drawn);
* for runs flown on the EKF (estimator columns in the log): a table of estimation RMS errors in
  ``comparison.md`` and ``comparison_estimate_{position_error,attitude_error,test_ratios}.png``
  (estimate − truth with the filter's ±3σ; :mod:`~gcs_scripts.analysis.estimation`).

``--t0 S [S ...]`` and ``--duration S`` select a window of simulation time (one t0 for every
log, or one per log) and shift it to start at 0, so a trajectory flown through the SITL from
t0 (``fly_trajectory.py`` prints it) compares with the in-process run of the same scenario.
In-process files start at 0; a t0 given for them trims their start in the same way (e.g.
``--t0 T0+4 4 --duration 36`` compares both runs after a 4 s start-up transient).

Usage: ``quadsitl analyze LOG... [--out DIR] [--t0 S ...] [--duration S] [--labels NAME ...]``
(also ``python -m gcs_scripts.analysis.analyze``).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from quadcommon.cli_help import HelpFormatter

from .estimation import estimation_markdown, estimation_stats
from .figures import estimation_figures, paper_figures
from .log_reader import Window, read_session
from .metrics import indices
from .record import FlightRecord
from .tables import comparison_markdown

FIGURE_PREFIX = "comparison"

WindowSpec = Window | Sequence[Window | None] | None


def _windows(window: WindowSpec, count: int) -> list[Window | None]:
    """One window for every log, or one per log."""
    if window is None:
        return [None] * count
    if len(window) == 2 and all(v is None or isinstance(v, int | float) for v in window):
        return [window] * count  # type: ignore[list-item]
    windows = list(window)  # type: ignore[arg-type]
    if len(windows) != count:
        raise ValueError(f"{len(windows)} windows for {count} logs: give one, or one per log")
    return windows  # type: ignore[return-value]


def _unique_labels(records: Sequence[FlightRecord], paths: Sequence[Path]) -> None:
    """Make labels unique (the table has a column per label): add the file name where needed."""
    seen: dict[str, int] = {}
    for rec in records:
        seen[rec.label] = seen.get(rec.label, 0) + 1
    for rec, path in zip(records, paths, strict=True):
        if seen[rec.label] > 1:
            rec.label = f"{rec.label} ({Path(path).name})"
    counts: dict[str, int] = {}
    for rec in records:  # still equal (same file name twice): number them
        counts[rec.label] = counts.get(rec.label, 0) + 1
        if counts[rec.label] > 1:
            rec.label = f"{rec.label} #{counts[rec.label]}"


def load_runs(
    paths: Sequence[str | Path],
    labels: Sequence[str] | None = None,
    window: WindowSpec = None,
) -> list[FlightRecord]:
    """FlightRecords of ``paths`` (see :func:`analyze` for ``labels`` and ``window``)."""
    if not paths:
        raise ValueError("no logs given")
    if labels is not None and len(labels) != len(paths):
        raise ValueError(f"{len(labels)} labels for {len(paths)} logs")
    windows = _windows(window, len(paths))
    records = [
        read_session(p, windows[i], labels[i] if labels is not None else None) for i, p in enumerate(paths)
    ]
    if labels is None:
        _unique_labels(records, [Path(p) for p in paths])
    return records


def _runs_markdown(records: Sequence[FlightRecord], windows: Sequence[Window | None]) -> str:
    lines = [
        "| Run | Source | Scenario | Controller | Window | Samples | Span (s) |",
        "|---|---|---|---|---|---:|---:|",
    ]
    for rec, w in zip(records, windows, strict=True):
        if w is None:
            win = "whole log"
        elif not rec.source.startswith(("sitl", "flight log")):  # in-process runs start at 0: duration only
            win = "whole run" if w[1] is None else f"first {w[1]:g} s"
        else:
            t0 = "start" if w[0] is None else f"t0={w[0]:g} s"
            win = f"{t0}, {'to the end' if w[1] is None else f'{w[1]:g} s'}"
        span = f"{rec.time_s[0]:.3f}..{rec.time_s[-1]:.3f}"
        lines.append(
            f"| {rec.label} | {rec.source} | {rec.scenario} | {rec.controller} | {win} | "
            f"{len(rec.time_s)} | {span} |"
        )
    return "\n".join(lines) + "\n"


def analyze(
    paths: Sequence[str | Path],
    out_dir: str | Path,
    labels: Sequence[str] | None = None,
    window: WindowSpec = None,
) -> list[Path]:
    """Indices (``comparison.md``) and overlaid figures of the runs in ``paths``; returns the files.

    ``labels``: one per path (default: the controller name, made unique with the file name).
    ``window``: ``(t0, duration)`` in simulation seconds for every log, or a list with one
    ``(t0, duration)`` (or None) per log; the window is shifted to start at 0.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    windows = _windows(window, len(paths))
    records = load_runs(paths, labels, windows)
    table = comparison_markdown({rec.label: indices(rec) for rec in records})
    text = [
        "# Run comparison",
        "",
        "Errors are actual − desired (ground truth vs the controller's reference). "
        "ISE = ∫e² dt (m²s, rad²s); IADU = ∫|du/dt| dt (total variation of U1, τ at the control rate).",
        "",
        _runs_markdown(records, windows),
        table,
    ]
    stats = {rec.label: s for rec in records if (s := estimation_stats(rec)) is not None}
    if stats:
        text += ["", estimation_markdown(stats)]
    md_path = out / "comparison.md"
    md_path.write_text("\n".join(text))
    figures = paper_figures(records, out, FIGURE_PREFIX) + estimation_figures(records, out, FIGURE_PREFIX)
    return [md_path, *figures]


def build_parser(prog: str = "quadsitl analyze") -> argparse.ArgumentParser:
    """The ``quadsitl analyze`` command line (logs, output directory, time windows, figures)."""
    parser = argparse.ArgumentParser(
        prog=prog, description=__doc__, formatter_class=HelpFormatter
    )
    parser.add_argument(
        "logs", nargs="+",
        help="session .parquet, NAME.parts/ directory, in-process .parquet, or flight log .ulg",
    )
    parser.add_argument("--out", default="out/analysis", help="output directory (default out/analysis)")
    parser.add_argument(
        "--t0", type=float, nargs="+", default=None, help="window start, sim s (one, or one per log)"
    )
    parser.add_argument("--duration", type=float, default=None, help="window length, s (default: to the end)")
    parser.add_argument("--labels", nargs="+", default=None, help="one label per log")
    return parser


def main(argv: list[str] | None = None, prog: str = "quadsitl analyze") -> int:
    """Command line: parse ``argv``, run :func:`analyze`, print the files written."""
    parser = build_parser(prog)
    args = parser.parse_args(argv)
    if args.duration is not None and not args.duration > 0.0:
        parser.error(f"--duration must be > 0 s, got {args.duration}")
    window: WindowSpec = None
    if args.t0 is not None:
        if len(args.t0) not in (1, len(args.logs)):
            parser.error(f"--t0: give one value or one per log ({len(args.logs)}), got {len(args.t0)}")
        t0s = args.t0 * len(args.logs) if len(args.t0) == 1 else args.t0
        window = [(t0, args.duration) for t0 in t0s]
    elif args.duration is not None:
        window = (None, args.duration)
    try:
        paths = analyze(args.logs, args.out, args.labels, window)
    except (FileNotFoundError, ValueError) as exc:
        print(f"analyze: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {len(paths)} files to {args.out}/:")
    for p in paths:
        print(f"  {p}")
    return 0


if __name__ == "__main__":
    sys.exit(main(prog="python -m gcs_scripts.analysis.analyze"))
