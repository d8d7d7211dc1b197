"""Encode CPU time and bytes of each manifest column under candidate lossless settings.

Reads the arrays the writers encode from a rendered dataset (every format is lossless, so the
decoded files are the encoders' inputs), and encodes each file with every candidate:

- PNG columns: OpenCV (libpng + zlib, as the writers before ``io.encoders``) at zlib levels 0-9
  with the row filters none / sub / up, zlib's Huffman-only and RLE strategies at level 1, and
  ``io.encoders.png_encode`` (ISA-L levels 1-3, the same filters); the semantic map also with
  Pillow (its writer before);
- EXR columns: the OpenEXR library's lossless NONE, RLE, ZIPS, ZIP, PIZ (and ZSTD, which only
  OpenEXR 3.4+ reads) and ``io.encoders.exr_encode`` (ZIP and ZIPS at ISA-L levels 1-3).

Repetitions are interleaved (every candidate once per round) and the least CPU time
(``time.process_time``: every thread of this process) of each file is kept. Rows are split by
camera and frame: ``--choose`` cameras at ``--choose-frames`` frames to pick settings on, the others
held out to report on.

    python benchmarks/encode_settings.py --dataset /work/cache/bench/dataset [--repeats 3] [--json out.json]
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import cv2
import numpy as np
import OpenEXR
from PIL import Image

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from eden_pipe.io import encoders, formats  # noqa: E402
from eden_pipe.io.exr import read_exr  # noqa: E402
from eden_pipe.io.half_float import half_planes  # noqa: E402

NONE, SUB, UP = cv2.IMWRITE_PNG_FILTER_NONE, cv2.IMWRITE_PNG_FILTER_SUB, cv2.IMWRITE_PNG_FILTER_UP
OURS_FILTER = {NONE: encoders.FILTER_NONE, SUB: encoders.FILTER_SUB, UP: encoders.FILTER_UP}
FILTER_NAME = {NONE: "none", SUB: "sub", UP: "up"}
# The settings of e69f90d's writers (io.formats, io.kitti, io.exr at render.png_compression=1).
BASELINE = {
    "rgb": "cv2 L1 none",
    "semantic": "pillow L1",
    "instance": "cv2 L1 none",
    "depth": "cv2 L1 sub",
    "normal": "cv2 L1 none",
    "flow": "cv2 L1 sub",
    "occ": "cv2 L1 none",
    "exr": "openexr ZIP",
}
# What the writers use now: the table in io.formats (PNGs at render.png_compression=1).
FILTER_OF = {"flow": "kitti_flow", "occ": "mask"}
CHOSEN = {
    kind: f"isal L1 {('none', 'sub', 'up')[formats.ROW_FILTERS[FILTER_OF.get(kind, kind)]]}"
    for kind in BASELINE
    if kind != "exr"
}
CHOSEN["exr"] = f"isal ZIP L{formats.EXR_DEFLATE_LEVEL}"
KIND = {
    "rgb_left": "rgb",
    "rgb_right": "rgb",
    "semantic": "semantic",
    "instance": "instance",
    "depth": "depth",
    "depth_right": "depth",
    "normal": "normal",
    "flow_fwd": "flow",
    "flow_bwd": "flow",
    "occ_fwd": "occ",
    "occ_bwd": "occ",
    "albedo": "exr",
    "shading": "exr",
    "translucency": "exr",
}


def load_input(path: Path, kind: str):
    """(OpenCV's array, the file-order array, the palette) the writer encodes for this file."""
    if kind == "exr":
        return None, half_planes(read_exr(path)), None
    if kind == "semantic":
        with Image.open(path) as img:
            return None, np.asarray(img, np.uint8), np.asarray(img.getpalette(), np.uint8).reshape(-1, 3)
    raw = formats.read_raw(path)  # exactly the array OpenCV was given (BGR order)
    return raw, (raw[..., ::-1] if raw.ndim == 3 else raw), None


def png_candidates(kind: str) -> dict:
    out = {}
    for level in range(10):
        for f in (NONE, SUB, UP):
            params = [cv2.IMWRITE_PNG_COMPRESSION, level, cv2.IMWRITE_PNG_FILTER, f]
            out[f"cv2 L{level} {FILTER_NAME[f]}"] = ("cv2", params)
    for f in (NONE, SUB):
        for strategy, name in (
            (cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY, "huffman"),
            (cv2.IMWRITE_PNG_STRATEGY_RLE, "rle"),
        ):
            params = [cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_FILTER, f, cv2.IMWRITE_PNG_STRATEGY, strategy]
            out[f"cv2 L1 {FILTER_NAME[f]} {name}"] = ("cv2", params)
    for level in (1, 2, 3):
        for f in (NONE, SUB, UP):
            out[f"isal L{level} {FILTER_NAME[f]}"] = ("ours", (level, OURS_FILTER[f]))
    if kind == "semantic":  # a palette PNG: OpenCV cannot write one
        out = {k: v for k, v in out.items() if v[0] == "ours"}
        out["pillow L1"] = ("pillow", 1)
    return out


EXR_LIBRARY = {
    "NONE": OpenEXR.NO_COMPRESSION,
    "RLE": OpenEXR.RLE_COMPRESSION,
    "ZIPS": OpenEXR.ZIPS_COMPRESSION,
    "ZIP": OpenEXR.ZIP_COMPRESSION,
    "PIZ": OpenEXR.PIZ_COMPRESSION,
    "ZSTD": OpenEXR.ZSTD_COMPRESSION,
}


def exr_candidates() -> dict:
    out = {f"openexr {name}": ("openexr", c) for name, c in EXR_LIBRARY.items()}
    for level in (1, 2, 3):
        out[f"isal ZIP L{level}"] = ("exr", (encoders.EXR_ZIP, level))
        out[f"isal ZIPS L{level}"] = ("exr", (encoders.EXR_ZIPS, level))
    return out


def encode(how, setting, cv_array, array, palette, scratch: str) -> int:
    """Encode once; the encoded size in bytes."""
    if how == "cv2":
        _, buf = cv2.imencode(".png", cv_array, setting)
        return len(buf)
    if how == "ours":
        level, f = setting
        return len(encoders.png_encode(array, level, f, palette=palette))
    if how == "pillow":
        img = Image.fromarray(array, mode="P")
        img.putpalette(palette.ravel().tolist())
        buf = io.BytesIO()
        img.save(buf, format="PNG", compress_level=setting)
        return len(buf.getvalue())
    if how == "exr":
        compression, level = setting
        return len(encoders.exr_encode(array, ("R", "G", "B"), compression, level))
    pixels = {n: np.ascontiguousarray(array[i]) for i, n in enumerate("RGB")}
    with OpenEXR.File({"compression": setting, "type": OpenEXR.scanlineimage}, pixels) as exr:
        exr.write(scratch)  # the library writes files only (a tmpfs path where there is one)
    return os.path.getsize(scratch)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--dataset", type=Path, default=Path("/work/cache/bench/dataset"))
    parser.add_argument("--choose", default="0,1", help="cameras to choose settings on (the rest are held out)")
    parser.add_argument("--choose-frames", default="0,1", help="... at these frames (other frames are held out)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument(
        "--only",
        default="",
        help="comma-separated candidates to time besides the baselines (chosen: the table's; default: all)",
    )
    parser.add_argument("--part", choices=("choose", "held_out", "all"), default="all", help="rows to encode")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    cv2.setNumThreads(1)
    cameras = {int(c) for c in args.choose.split(",")}
    frames = {int(f) for f in args.choose_frames.split(",")}

    def chosen(row) -> bool:
        return int(row["camera"]) in cameras and int(row["frame"]) in frames

    only = {s.strip() for s in args.only.split(",") if s.strip()}
    with open(args.dataset / "manifest.csv") as fh:
        rows = list(csv.DictReader(fh))
    files = []  # (row index, column, kind, inputs)
    for i, row in enumerate(rows):
        if args.part != "all" and chosen(row) != (args.part == "choose"):
            continue
        for column, kind in KIND.items():
            if row.get(column):
                files.append((i, column, kind, load_input(args.dataset / row[column], kind)))
    candidates = {"exr": exr_candidates(), **{k: png_candidates(k) for k in set(KIND.values()) - {"exr"}}}
    if only:
        if "chosen" in only:
            only |= set(CHOSEN.values())
        keep = set(BASELINE.values()) | only
        candidates = {k: {n: c for n, c in v.items() if n in keep} for k, v in candidates.items()}
    scratch_dir = "/dev/shm" if os.path.isdir("/dev/shm") else None
    best: dict[tuple[int, str, str], float] = {}
    size: dict[tuple[int, str, str], int] = {}
    with tempfile.TemporaryDirectory(dir=scratch_dir) as tmp:
        scratch = os.path.join(tmp, "x.exr")
        for _ in range(args.repeats):
            for i, column, kind, (cv_array, array, palette) in files:
                for name, (how, setting) in candidates[kind].items():
                    start = time.process_time()
                    n = encode(how, setting, cv_array, array, palette, scratch)
                    spent = time.process_time() - start
                    key = (i, column, name)
                    best[key] = min(best.get(key, np.inf), spent)
                    size[key] = n
    report = {}
    for part, wanted in (("choose", True), ("held_out", False)):
        picked = [i for i, row in enumerate(rows) if chosen(row) == wanted]
        n_rows = len(picked)
        if args.part not in ("all", part):
            continue
        table = defaultdict(dict)
        for (i, column, name), seconds in best.items():
            if i in picked:
                cell = table[column].setdefault(name, [0.0, 0])
                cell[0] += seconds * 1e3 / n_rows
                cell[1] += size[(i, column, name)] / n_rows
        report[part] = {"rows": n_rows, "columns": table}
        print(f"== {part}: {n_rows} rows (ms and kB per row, mean)")
        for column, cells in table.items():
            base = BASELINE[KIND[column]]
            print(f"-- {column} (baseline {base}: {cells[base][0]:.2f} ms, {cells[base][1] / 1e3:.0f} kB)")
            for name, (ms, nbytes) in sorted(cells.items(), key=lambda kv: kv[1][0]):
                print(f"   {name:24s} {ms:7.2f} ms {nbytes / 1e3:8.0f} kB")
        total = {"before": [0.0, 0.0], "now": [0.0, 0.0]}
        print(f"== {part}: the e69f90d writers' settings against the table's (ms, kB per row)")
        for column, cells in table.items():
            before, now = cells[BASELINE[KIND[column]]], cells.get(CHOSEN[KIND[column]], [np.nan, np.nan])
            for key, cell in (("before", before), ("now", now)):
                total[key][0] += cell[0]
                total[key][1] += cell[1]
            print(
                f"   {column:14s} {BASELINE[KIND[column]]:12s} {before[0]:6.2f} ms {before[1] / 1e3:6.0f} kB"
                f"   {CHOSEN[KIND[column]]:12s} {now[0]:6.2f} ms {now[1] / 1e3:6.0f} kB"
            )
        print(
            f"   total: {total['before'][0]:.1f} ms {total['before'][1] / 1e6:.3f} MB per row before, "
            f"{total['now'][0]:.1f} ms {total['now'][1] / 1e6:.3f} MB now"
        )
    if args.json:
        args.json.write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
