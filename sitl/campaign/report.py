"""After a campaign: the Markdown summary and the figures, next to the results table."""

from __future__ import annotations

from pathlib import Path

import pyarrow as pa

from .batch import fly_recorded
from .figures import campaign_figures, worst_run_figures
from .spec import CampaignSpec
from .summary import summary_markdown, title, worst_runs


def write_report(spec: CampaignSpec, table: pa.Table, out_dir: str | Path, worst: bool = True) -> list[Path]:
    """``summary.md`` and ``figures/`` in ``out_dir``; returns the files written.

    Each controller's worst run is flown again by every controller with its time series
    recorded (same plant, same disturbances), so its figures compare the cascades on it.
    """
    out = Path(out_dir)
    figures = out / "figures"
    controllers = list(spec.controller_names)
    paths = campaign_figures(table, controllers, figures)
    notes = []
    if worst and table.num_rows:
        for controller, run in worst_runs(table, controllers).items():
            records = [fly_recorded(spec, run, c)[0] for c in controllers]
            files = worst_run_figures(records, figures, controller, run)
            paths += files
            notes.append(
                f"- worst run of {title(controller)}: run {run} (`figures/worst_{controller}_run{run}_*.png`)"
            )
    extra = "## Figures\n\n" + "\n".join(
        [
            "- `figures/distributions.png`: per-index box plots, `figures/ecdf.png`: empirical CDFs",
            "- `figures/ise_vs_mass.png`: position ISE against the mass scale",
            *(["- `figures/faults.png`: survival and excursion under the faults drawn"]
              if "survived" in table.column_names else []),  # fmt: skip
            *notes,
        ]
    )
    summary = out / "summary.md"
    summary.write_text(summary_markdown(table, spec, controllers, extra=extra))
    return [summary, *paths]
