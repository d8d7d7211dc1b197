"""Bytes per manifest row, compact against exact storage, and the error compact storage costs.

    python benchmarks/dataset_size.py                  # default garden, 10 frames (about 3 minutes)
    python benchmarks/dataset_size.py --steps 100 garden=small

Both jobs render the same garden, trajectory and lighting (one shared stage cache): the pixels
are identical, only the files differ. Prints bytes per row per column for both, the ratio, the
worst relative error of the half-float layers and the worst KITTI flow error against the
float32 originals.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from eden_pipe.config import make_cfg
from eden_pipe.io.formats import read_modality
from eden_pipe.modalities import PATH_COLUMNS


def column_bytes(root: Path) -> tuple[pd.DataFrame, dict[str, float], float]:
    rows = pd.read_csv(root / "manifest.csv", keep_default_na=False, dtype=dict.fromkeys(PATH_COLUMNS, str))
    per_column = {c: sum((root / p).stat().st_size for p in rows[c] if p) / len(rows) for c in PATH_COLUMNS}
    total = sum(p.stat().st_size for p in root.rglob("*") if p.is_file())
    return rows, per_column, total / len(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("overrides", nargs="*")
    args = ap.parse_args(argv)
    from eden_pipe.pipeline import run_job

    with tempfile.TemporaryDirectory(prefix="dataset-size-") as tmp:
        base = [
            f"camera.trajectory.frames=[{args.steps},{args.steps}]",
            "progress=false",
            f"paths.stages={tmp}/stages",
            *args.overrides,
        ]
        results = {}
        for storage in ("exact", "compact"):
            cfg = make_cfg(Path(tmp), base + [f"render.storage={storage}", f"paths.dataset={tmp}/{storage}"])
            run_job(cfg, echo=lambda *_: None)
            results[storage] = column_bytes(Path(tmp) / storage)
        (rows_e, col_e, total_e), (rows_c, col_c, total_c) = results["exact"], results["compact"]
        print(f"{'column':<14} {'exact B/row':>12} {'compact B/row':>14} {'ratio':>6}")
        for c in PATH_COLUMNS:
            if col_e[c]:
                print(f"{c:<14} {col_e[c]:12.0f} {col_c[c]:14.0f} {col_e[c] / max(col_c[c], 1):6.2f}")
        print(f"{'all files':<14} {total_e:12.0f} {total_c:14.0f} {total_e / total_c:6.2f}")

        worst_rel, worst_flow = 0.0, 0.0
        # The same job in two storage modes: the same rows in the same order.
        for (_, re), (_, rc) in zip(rows_e.iterrows(), rows_c.iterrows(), strict=True):
            for c in ("albedo", "shading", "translucency", "glossy", "background", "rgb_linear"):
                if re[c]:
                    a = read_modality(Path(tmp) / "exact" / re[c], c)
                    b = read_modality(Path(tmp) / "compact" / rc[c], c)
                    big = np.abs(a) > 1e-4  # half floats are relative below that only to their subnormal step
                    worst_rel = max(worst_rel, float(np.max(np.abs(b - a)[big] / np.abs(a)[big], initial=0.0)))
            for c in ("flow_fwd", "flow_bwd"):
                if re[c]:
                    a = read_modality(Path(tmp) / "exact" / re[c], c)
                    b = read_modality(Path(tmp) / "compact" / rc[c], c)
                    ok = np.isfinite(b).all(axis=-1)
                    worst_flow = max(worst_flow, float(np.abs(b - a)[ok].max(initial=0.0)))
        print(
            f"rows: {len(rows_e)}; half-float layers: worst relative error {worst_rel:.2e}; "
            f"KITTI flow: worst error {worst_flow:.4f} px"
        )
        print(
            f"bytes per row: exact {total_e / 1e6:.2f} MB, compact {total_c / 1e6:.2f} MB "
            f"({total_e / total_c:.2f}x smaller)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
