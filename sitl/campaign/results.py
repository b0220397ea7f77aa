"""The campaign's table on disk: appended as runs finish, resumable, one row per run x controller.

Layout of an output directory::

    manifest.json          the spec's fingerprint, name, seed (a resume refuses a different spec)
    spec.toml              the spec as it was read
    parts/*.parquet        one file per finished chunk, written whole then renamed into place
    results.parquet        all rows, sorted by (run, controller), written at the end

A chunk's rows reach ``parts/`` only complete (write to a temporary name, then ``os.replace``),
so an interrupted campaign leaves whole chunks and nothing half-written; on resume the runs that
have a row for every controller are skipped and the rest are flown again.
"""

from __future__ import annotations

import json
import os
import uuid
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from quadcommon.schema import ConfigError

from .spec import CampaignSpec

RESULTS_FILE = "results.parquet"


class ResultStore:
    """The output directory of one campaign."""

    def __init__(self, out_dir: str | Path, spec: CampaignSpec) -> None:
        self.dir = Path(out_dir)
        self.parts = self.dir / "parts"
        self.spec = spec
        self.parts.mkdir(parents=True, exist_ok=True)
        manifest = self.dir / "manifest.json"
        fingerprint = spec.fingerprint()
        if manifest.exists():
            old = json.loads(manifest.read_text())
            if old.get("fingerprint") != fingerprint:
                raise ConfigError(
                    f"{self.dir}: holds results of a different campaign ({old.get('name')!r}, "
                    f"fingerprint {old.get('fingerprint')}; this spec {spec.path} has {fingerprint}); "
                    "choose another --out, or delete the directory to start again"
                )
        else:
            manifest.write_text(
                json.dumps(
                    {
                        "name": spec.name,
                        "spec": spec.path,
                        "seed": spec.seed,
                        "fingerprint": fingerprint,
                        "controllers": list(spec.controller_names),
                        "wire_float32": spec.wire_float32,
                    },
                    indent=2,
                )
                + "\n"
            )
            (self.dir / "spec.toml").write_text(spec.text)

    def _part_files(self) -> list[Path]:
        return sorted(self.parts.glob("*.parquet"))

    def done_runs(self) -> set[int]:
        """Runs that already have a row for every controller of the spec."""
        seen: dict[int, set[str]] = {}
        for path in self._part_files():
            t = pq.read_table(path, columns=["run", "controller"])
            for run, controller in zip(
                t.column("run").to_pylist(), t.column("controller").to_pylist(), strict=True
            ):
                seen.setdefault(run, set()).add(controller)
        wanted = set(self.spec.controller_names)
        return {run for run, names in seen.items() if wanted <= names}

    def append(self, rows: Sequence[dict[str, Any]]) -> Path | None:
        """Persist one finished chunk (atomically)."""
        if not rows:
            return None
        runs = [r["run"] for r in rows]
        name = f"runs-{min(runs):07d}-{max(runs):07d}-{uuid.uuid4().hex[:8]}.parquet"
        final = self.parts / name
        tmp = self.parts / f".{name}.tmp"
        pq.write_table(pa.Table.from_pylist(list(rows)), tmp)
        os.replace(tmp, final)
        return final

    def table(self, runs: int | None = None) -> pa.Table:
        """Every row of runs ``< runs`` (default: the spec's), one per (run, controller), sorted."""
        limit = self.spec.runs if runs is None else runs
        tables = [pq.read_table(p) for p in self._part_files()]
        if not tables:
            return pa.Table.from_pylist([])
        table = pa.concat_tables(tables, promote_options="default")
        rows = table.to_pylist()
        unique: dict[tuple[int, str], dict[str, Any]] = {}
        for row in rows:
            key = (row["run"], row["controller"])
            if row["run"] < limit and key not in unique:
                unique[key] = row
        ordered = [unique[k] for k in sorted(unique)]
        return pa.Table.from_pylist(ordered, schema=table.schema)

    def write_results(self) -> Path:
        """Write the results table to ``results.parquet`` in the campaign directory, atomically (a temporary
        file renamed); return its path."""
        path = self.dir / RESULTS_FILE
        tmp = self.dir / f".{RESULTS_FILE}.tmp"
        pq.write_table(self.table(), tmp)
        os.replace(tmp, path)
        return path


def tables_equal(a: pa.Table, b: pa.Table) -> bool:
    """Same columns, same order, same values (NaN equal to NaN): the determinism check."""
    if a.column_names != b.column_names or a.num_rows != b.num_rows:
        return False
    for name in a.column_names:
        x, y = a.column(name).to_pylist(), b.column(name).to_pylist()
        if a.schema.field(name).type in (pa.float64(), pa.float32()):
            if not np.array_equal(np.array(x, dtype=float), np.array(y, dtype=float), equal_nan=True):
                return False
        elif x != y:
            return False
    return True
