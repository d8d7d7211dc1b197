"""Hash every file two reference jobs write, to prove a refactor changes no byte.

    python scripts/dataset_fingerprint.py --out before.json        # record
    python scripts/dataset_fingerprint.py --compare before.json    # after a change: exit 1 on any difference
    python scripts/dataset_fingerprint.py --against 420c25b        # both at once: REV (a git worktree) vs this tree
    python scripts/dataset_fingerprint.py --against 420c25b --pixels   # a change of encoder settings: the images'
                                                                       # decoded arrays must match, their bytes may not

The two jobs are the small garden and the default garden cut to 4 trajectory
steps (so the check takes about a minute), each in a fresh empty folder. Every
file under the dataset root is hashed (images, layers, manifest, metadata);
files that record wall-clock time or the host are listed in VOLATILE and skipped.
With ``--pixels`` a PNG or OpenEXR file is compared by its decoded array (and a
palette PNG's palette) instead of its bytes, and the files whose bytes alone
differ are counted apart. Without it the bytes decide, and each image that
differs says whether its decoded array is the same: ISA-L's deflate, from the
writer threads, now and then gives another valid stream of the same rows
(docs/design.md, File formats), which is not a change of the dataset.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

JOBS = {
    "small": ["garden=small", "camera.trajectory.min_steps=4"],
    "default": ["garden=default", "camera.trajectory.min_steps=4"],
}
# Files whose content is legitimately run-dependent (timings, git commit, host).
VOLATILE = {"dataset.json"}


IMAGES = (".png", ".exr")
PIXELS_SUFFIX = " pixels"  # the digests of a job's images by their decoded arrays


def pixel_digest(path: Path) -> str:
    """A digest of an image file's decoded content: its array as stored (any PNG or EXR encoding of
    the same pixels gives the same digest), with a palette PNG's indices and palette."""
    import cv2
    import numpy as np
    from PIL import Image

    from eden_pipe.io.exr import read_exr

    digest = hashlib.sha256()
    if path.suffix == ".exr":
        array = read_exr(path)
    else:
        array = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        with Image.open(path) as img:
            if img.mode == "P":
                array = np.asarray(img)
                digest.update(bytes(img.getpalette()))
    digest.update(f"{array.dtype} {array.shape}".encode())
    digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()


def run_jobs(extra: list[str], jobs: list[str], code_root: Path = ROOT) -> dict[str, dict[str, str]]:
    """Each job's digests of every file's bytes (``name``) and of its images' decoded arrays
    (``name pixels``)."""
    digests: dict[str, dict[str, str]] = {}
    for name in jobs:
        with tempfile.TemporaryDirectory(prefix=f"fingerprint-{name}-") as tmp:
            cmd = [
                sys.executable,
                "-m",
                "eden_pipe",
                *JOBS[name],
                *extra,
                "progress=false",
                f"paths.stages={tmp}/stages",
                f"paths.dataset={tmp}/dataset",
                f"hydra.run.dir={tmp}/run",
            ]
            env = dict(os.environ, PYTHONPATH=str(code_root))
            subprocess.run(cmd, check=True, cwd=tmp, env=env, stdout=subprocess.DEVNULL)
            root = Path(tmp) / "dataset"
            digests[name] = {
                str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
                for p in sorted(root.rglob("*"))
                if p.is_file() and p.name not in VOLATILE
            }
            # Both, always: a byte comparison tells an image's new pixels from a new stream of the same.
            digests[f"{name}{PIXELS_SUFFIX}"] = {
                str(p.relative_to(root)): pixel_digest(p)
                for p in sorted(root.rglob("*"))
                if p.is_file() and p.suffix in IMAGES
            }
            print(f"{name}: {len(digests[name])} files hashed", file=sys.stderr)
    return digests


def content_digest(path: Path) -> str:
    """What two jobs' files are compared by where only their content matters: an image's
    :func:`pixel_digest` (its PNG or EXR bytes can differ for the same pixels: ISA-L's deflate,
    docs/design.md, File formats), sha256 of another file's bytes."""
    return pixel_digest(path) if path.suffix in IMAGES else hashlib.sha256(path.read_bytes()).hexdigest()


def compare(before: dict, after: dict, allow_new: bool = False) -> list[str]:
    """Differences; files only ``after`` has are listed too, and count unless ``allow_new``
    (a deliberate change that adds files, e.g. new metadata, must leave every old file as it was)."""
    problems = []
    for job in before:
        b, a = before[job], after.get(job, {})
        problems += [f"{job}: missing {p}" for p in sorted(set(b) - set(a))]
        new = [f"{job}: new file {p}" for p in sorted(set(a) - set(b))]
        if allow_new:
            for line in new:
                print(line + " (allowed)")
        else:
            problems += new
        problems += [f"{job}: differs {p}" for p in sorted(set(a) & set(b)) if a[p] != b[p]]
    return problems


def annotate(line: str, decoded: dict) -> str:
    """A byte comparison's line about a differing image, with whether its decoded array differs too."""
    job, _, rest = line.partition(": differs ")
    if not rest.endswith(IMAGES):
        return line
    was, now = decoded.get(job, (None, None))
    if not was or not now or rest not in was or rest not in now:
        return line
    return line + (" (its pixels the same: another deflate stream)" if was[rest] == now[rest] else " (its pixels too)")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, help="write the digests here")
    ap.add_argument("--compare", type=Path, help="compare against digests recorded earlier")
    ap.add_argument(
        "--against", metavar="REV", help="record REV's digests first (checked out in a temporary git worktree)"
    )
    ap.add_argument("--allow-new", action="store_true", help="list files REV lacks without counting them")
    ap.add_argument("--jobs", nargs="+", default=list(JOBS), choices=list(JOBS))
    ap.add_argument(
        "--pixels", action="store_true", help="compare PNG and EXR files by their decoded arrays, not their bytes"
    )
    ap.add_argument("overrides", nargs="*", help="extra overrides for both jobs")
    args = ap.parse_args(argv)
    before = None
    if args.against:
        with tempfile.TemporaryDirectory(prefix="fingerprint-rev-") as tmp:
            tree = Path(tmp) / "tree"
            subprocess.run(
                ["git", "-C", str(ROOT), "worktree", "add", "--detach", "-q", str(tree), args.against], check=True
            )
            try:
                before = run_jobs(args.overrides, args.jobs, tree)
            finally:
                subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], check=True)
    elif args.compare:
        before = json.loads(args.compare.read_text())
    digests = run_jobs(args.overrides, args.jobs)
    if args.out:
        args.out.write_text(json.dumps(digests, indent=1, sort_keys=True))
    if before is not None:
        if not args.pixels:  # bytes decide; the pixel digests only annotate (older records lack them)
            decoded = {job: (before.get(job + PIXELS_SUFFIX), digests.get(job + PIXELS_SUFFIX)) for job in before}
            before = {job: d for job, d in before.items() if not job.endswith(PIXELS_SUFFIX)}
            problems = [annotate(line, decoded) for line in compare(before, digests, args.allow_new)]
        else:  # an image whose decoded array is the same may differ in its bytes
            problems = compare(before, digests, args.allow_new)
            encoded = [p for p in problems if " pixels: " not in p and p.endswith(IMAGES) and "differs" in p]
            kinds: dict[str, int] = {}
            for line in encoded:
                folder = line.split()[-1].split("/")[-2]
                kinds[folder] = kinds.get(folder, 0) + 1
            print(f"{len(encoded)} images differ in their bytes alone: {kinds}")
            problems = [p for p in problems if p not in encoded]
        for p in problems:
            print(p)
        total = sum(len(digests.get(job, {})) for job in before)
        print(f"{total} files compared, {len(problems)} differences")
        return 1 if problems else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
