"""Recorded sessions and in-process runs as replay tracks for the page.

Reads what ``gcs_scripts/record.py`` writes (``NAME.parquet``, a ``NAME.parts/`` directory),
the Parquet files of in-process runs (``quadsitl run ... --out``, ``out/paper/runs/``) and the
autopilot's flight logs (``.ulg``), through the same readers as the analysis
(:mod:`gcs_scripts.session_log`, :class:`gcs_scripts.analysis.record.FlightRecord`,
:mod:`gcs_scripts.analysis.ulog_reader`). A flight log starts when it started (at arming, by
default): its replay has no ground phase before that.

A track holds the log decimated to ``rate_hz`` samples per second of simulation time (the page
plays them back itself: play, pause, speed and seek need no round trip), the disturbance onsets
found at the full rate, the mode / armed / landed timeline (its changes, from the recorded
HEARTBEAT and EXTENDED_SYS_STATE) and the STATUSTEXT events of the session. Unlike the analysis,
a session is kept from its first truth row, before arming, so a replay shows the ground phase,
the takeoff and the landing too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gcs_scripts.analysis.log_reader import as_array, coalesce_duplicate_times, disturbance_events
from gcs_scripts.analysis.record import FlightRecord
from gcs_scripts.analysis.ulog_reader import is_ulog, read_ulog_columns
from gcs_scripts.session_log import read_session_table, resolve_session_path

from .telemetry import LANDED_STATE_NAMES, mode_name

ALIGNMENTS = ("sim", "start", "armed")

# page column -> (log column, decimal digits kept)
COLUMNS: dict[str, tuple[str, int]] = {
    "x": ("x_m", 6), "y": ("y_m", 6), "z": ("z_m", 6),
    "xr": ("x_ref_m", 6), "yr": ("y_ref_m", 6), "zr": ("z_ref_m", 6),
    "phi": ("phi_rad", 6), "theta": ("theta_rad", 6), "psi": ("psi_rad", 6),
    "phir": ("phi_ref_rad", 6), "thetar": ("theta_ref_rad", 6), "psir": ("psi_ref_rad", 6),
    "u1": ("U1_n", 5),
    "tphi": ("tau_phi_n_m", 6), "ttheta": ("tau_theta_n_m", 6), "tpsi": ("tau_psi_n_m", 6),
    "fx": ("Ax_n", 5), "fy": ("Ay_n", 5), "fz": ("Az_n", 5),
    "mx": ("Ap_n_m", 5), "my": ("Aq_n_m", 5), "mz": ("Ar_n_m", 5),
    # the rotors' health (the simulator's rotor order: 1 front, 2 right, 3 rear, 4 left)
    **{f"e{n}": (f"rotor{n}_effectiveness", 4) for n in (1, 2, 3, 4)},
    **{f"f{n}": (f"rotor{n}_failure", 0) for n in (1, 2, 3, 4)},
}  # fmt: skip
STATUS_COLUMNS = ("mav_custom_mode", "mav_armed", "mav_landed_state")
FALLBACK_STATUS_COLUMNS = ("custom_mode", "armed")  # the controller's own record


@dataclass
class ReplayTrack:
    """One log, ready for the page (times in s after the alignment; paper frames, SI units)."""

    label: str
    source: str
    scenario: str
    controller: str
    columns: dict[str, list[float | None]]  # "t" and COLUMNS' keys
    status: list[list[Any]] = field(default_factory=list)  # [t, mode, armed, landed] at each change
    texts: list[list[Any]] = field(default_factory=list)  # [t, severity, text]
    events: list[float] = field(default_factory=list)  # disturbance onsets
    offset_s: float = 0.0  # simulation time of the track's t = 0

    @property
    def duration_s(self) -> float:
        """The track's length in simulation time (s); 0 when empty."""
        t = self.columns["t"]
        return float(t[-1] - t[0]) if t else 0.0

    def to_json(self) -> dict[str, Any]:
        """The track as the page's JSON: description, columns, status, texts and events."""
        return {
            "label": self.label,
            "source": self.source,
            "scenario": self.scenario,
            "controller": self.controller,
            "offset_s": self.offset_s,
            "cols": self.columns,
            "status": self.status,
            "texts": self.texts,
            "events": self.events,
        }


def decimate_indices(time_s: np.ndarray, rate_hz: float) -> np.ndarray:
    """Indices of the first sample in each 1/rate_hz bin of time, and the last sample."""
    if len(time_s) == 0:
        return np.zeros(0, dtype=int)
    bins = np.floor((time_s - time_s[0]) * rate_hz + 1e-9).astype(np.int64)
    first = np.flatnonzero(np.r_[True, bins[1:] != bins[:-1]])
    if first[-1] != len(time_s) - 1:
        first = np.r_[first, len(time_s) - 1]
    return first


def _rounded(values: np.ndarray, digits: int) -> list[float | None]:
    return [round(float(v), digits) if math.isfinite(v) else None for v in values]


def status_changes(
    time_s: np.ndarray, mode: np.ndarray, armed: np.ndarray, landed: np.ndarray | None
) -> list:
    """[t, mode name, armed, landed name] at the first sample and at every change (full rate)."""
    if len(time_s) == 0:
        return []
    m = np.nan_to_num(np.asarray(mode, dtype=float), nan=-1.0)
    a = np.nan_to_num(np.asarray(armed, dtype=float), nan=-1.0)
    ld = np.full(len(time_s), -1.0) if landed is None else np.nan_to_num(np.asarray(landed, float), nan=-1.0)
    both = np.column_stack([m, a, ld])
    change = np.flatnonzero(np.r_[True, np.any(both[1:] != both[:-1], axis=1)])
    out = []
    for i in change:
        out.append(
            [
                round(float(time_s[i]), 6),
                mode_name(int(m[i])) if m[i] >= 0 else "",
                None if a[i] < 0 else bool(a[i] > 0.5),
                "" if ld[i] < 0 else LANDED_STATE_NAMES.get(int(ld[i]), str(int(ld[i]))),
            ]
        )
    return out


def _alignment_offset(time_s: np.ndarray, armed: np.ndarray | None, align: str, where: Path) -> float:
    if align == "sim":
        return 0.0
    if align == "start":
        return float(time_s[0])
    if armed is None or not np.any(armed > 0.5):
        raise ValueError(f"{where}: --align armed, but the vehicle is never armed in this log")
    return float(time_s[np.argmax(armed > 0.5)])


def _is_flight_record(path: Path) -> bool:
    import pyarrow.parquet as pq

    if path.is_dir() or path.suffix != ".parquet":
        return False
    return b"quadsitl.flight_record" in (pq.read_schema(path).metadata or {})


def load_track(
    path: str | Path, label: str | None = None, rate_hz: float = 30.0, align: str = "sim"
) -> ReplayTrack:
    """A replay track from a session log (file, parts dir, bare NAME) or an in-process run file.

    Raises FileNotFoundError, or ValueError naming the file when it is not a quadsitl log.
    """
    if align not in ALIGNMENTS:
        raise ValueError(f"align must be one of {', '.join(ALIGNMENTS)}, got {align!r}")
    resolved = resolve_session_path(path)
    if _is_flight_record(resolved):
        return _from_flight_record(resolved, label, rate_hz, align)
    if is_ulog(resolved):
        columns, meta = read_ulog_columns(resolved)
    else:
        table, meta = read_session_table(resolved)
        columns = {c: table.column(c) for c in table.column_names}
    names = set(columns)
    if "time_s" not in names or "x_m" not in names:
        raise ValueError(f"{resolved}: not a quadsitl session log (no time_s / x_m columns)")
    wanted = ["time_s", *(c for c, _ in COLUMNS.values() if c in names)]
    wanted += [c for c in (*STATUS_COLUMNS, *FALLBACK_STATUS_COLUMNS) if c in names]
    cols = coalesce_duplicate_times({c: as_array(columns[c]) for c in wanted})
    keep = np.isfinite(cols["x_m"])  # rows with ground truth (the controller's may lag at the edges)
    if keep.sum() < 2:
        raise ValueError(f"{resolved}: fewer than 2 rows with ground truth")
    cols = {k: v[keep] for k, v in cols.items()}
    time_s = cols["time_s"]
    if "mav_custom_mode" in cols and np.any(np.isfinite(cols["mav_custom_mode"])):
        mode, armed = cols["mav_custom_mode"], cols.get("mav_armed")
        landed = cols.get("mav_landed_state")
    elif "custom_mode" in cols:  # the controller's record (a flight log has its landed state too)
        mode, armed, landed = cols["custom_mode"], cols.get("armed"), cols.get("mav_landed_state")
    else:
        mode = armed = landed = None
    offset = _alignment_offset(time_s, armed, align, resolved)
    shifted = time_s - offset
    dist = [c for c in ("Ax_n", "Ay_n", "Az_n", "Ap_n_m", "Aq_n_m", "Ar_n_m") if c in cols]
    events = disturbance_events(shifted, np.column_stack([cols[c] for c in dist])) if len(dist) == 6 else []
    idx = decimate_indices(shifted, rate_hz)
    out: dict[str, list[float | None]] = {"t": _rounded(shifted[idx], 6)}
    nan = np.full(len(idx), np.nan)
    for key, (column, digits) in COLUMNS.items():
        out[key] = _rounded(cols[column][idx] if column in cols else nan, digits)
    status = []
    if mode is not None:
        status = status_changes(
            shifted, mode, armed if armed is not None else np.full(len(mode), np.nan), landed
        )
    texts = [
        [round(float(t) - offset, 6), int(sev), str(text)]
        for t, sev, text in meta.get("statustext", []) or []
    ]
    controller = meta.get("controller", "") or ""
    return ReplayTrack(
        label=label or (f"{controller} ({resolved.stem})" if controller else resolved.stem),
        source=str(resolved),
        scenario=meta.get("scenario", "") or "",
        controller=controller,
        columns=out,
        status=status,
        texts=texts,
        events=[round(t, 6) for t in events],
        offset_s=offset,
    )


def _from_flight_record(path: Path, label: str | None, rate_hz: float, align: str) -> ReplayTrack:
    record = FlightRecord.read_parquet(path)
    cols = record.to_columns()
    time_s = np.asarray(cols["time_s"], dtype=float)
    if len(time_s) < 2:
        raise ValueError(f"{path}: fewer than 2 samples")
    # An in-process run is armed from its first sample: "armed" and "start" both mean t[0].
    offset = 0.0 if align == "sim" else float(time_s[0])
    idx = decimate_indices(time_s - offset, rate_hz)
    out: dict[str, list[float | None]] = {"t": _rounded(time_s[idx] - offset, 6)}
    nan = np.full(len(idx), np.nan)
    for key, (column, digits) in COLUMNS.items():
        values = np.asarray(cols[column], dtype=float)[idx] if column in cols else nan
        out[key] = _rounded(values, digits)
    return ReplayTrack(
        label=label or f"{record.controller or record.label} ({path.stem}, in-process)",
        source=str(path),
        scenario=record.scenario,
        controller=record.controller,
        columns=out,
        status=[[out["t"][0], "in-process run", True, "IN_AIR"]],
        events=[round(t - offset, 6) for t in record.event_times_s],
        offset_s=offset,
    )
