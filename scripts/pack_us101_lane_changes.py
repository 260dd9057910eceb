"""Pack the US-101 lane-change tables into ``avrisk/data/ngsim/``.

Command (from the repository root)::

    .venv/bin/python scripts/pack_us101_lane_changes.py --source /work/shared/data/ngsim

reads the original ``us101_vehicle_subset.csv.gz`` (provenance in the source
folder's ``SOURCE.md``), draws the held-out third of its vehicles, detects
their lane changes (:func:`avrisk.learning.ngsim.us101_lane_changes.lane_change_tables`)
and writes the two tables into ``--out`` (default the package's folder). It
then reads them back, stops with an error unless they equal what it made,
and prints each split's statistics and the files' sha256 (for ``SOURCE.md``).
"""

from __future__ import annotations

import argparse
import hashlib
from pathlib import Path

from avrisk.learning.ngsim.files import US101_FILE, default_ngsim_dir
from avrisk.learning.ngsim.loaders import load_us101
from avrisk.learning.ngsim.us101_lane_changes import (
    EVENTS_FILE,
    VEHICLES_FILE,
    lane_change_tables,
    load_lane_change_tables,
    split_statistics,
    write_lane_change_tables,
)


def sha256(path: Path) -> str:
    """Hex sha256 of a file."""
    return hashlib.sha256(path.read_bytes()).hexdigest()


def main() -> None:
    """Pack, check and report (see the module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--source", required=True, help="folder of the originals")
    parser.add_argument("--out", default=str(default_ngsim_dir()))
    args = parser.parse_args()
    source, out = Path(args.source) / US101_FILE, Path(args.out)
    tables = lane_change_tables(load_us101(source))
    write_lane_change_tables(tables, out)
    if not load_lane_change_tables(out).equals(tables):
        raise SystemExit("the written tables differ from the computed ones")
    print(f"source {source.name}: {source.stat().st_size:,} bytes, {sha256(source)}")
    for name in (VEHICLES_FILE, EVENTS_FILE):
        path = out / name
        rows = load_lane_change_tables(out)
        n = (rows.vehicles if name == VEHICLES_FILE else rows.events).num_rows
        print(f"{name}: {n} rows, {path.stat().st_size:,} bytes, {sha256(path)}")
    print(f"lane-keeping noise speed (train): {tables.noise_speed:.4f} m/s")
    for split in ("train", "test"):
        s = split_statistics(tables, split)
        print(
            f"{split}: {s.vehicles} vehicles, {s.hours:.3f} veh-h, {s.changes} "
            f"changes, {s.rate:.1f} [{s.rate_low:.1f}, {s.rate_high:.1f}] /veh-h, "
            f"left {s.left_fraction:.2f}, duration p10/50/90 {s.duration_q10:.1f}/"
            f"{s.duration_q50:.1f}/{s.duration_q90:.1f} s, peak |vy| p10/50/90 "
            f"{s.peak_q10:.2f}/{s.peak_q50:.2f}/{s.peak_q90:.2f} m/s"
        )


if __name__ == "__main__":
    main()
