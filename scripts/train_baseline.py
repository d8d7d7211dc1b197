"""From-scratch baselines for EDEN's two result tables: segmentation mIoU and depth errors, per lighting.

    python scripts/train_baseline.py --make-dataset outputs/baseline_ds            # generate, train, table
    python scripts/train_baseline.py --dataset DIR [--train-lighting all,clear]    # an existing dataset
    python scripts/train_baseline.py --dataset DIR --task depth                    # the depth table

Trains a small network (no pretrained weights: nothing is downloaded) on the
``train`` split and prints the test split's mIoU per lighting as a markdown
table: one row per lighting of the test images, one column per training set
(``--train-lighting all,clear`` trains one model on every lighting and one on
clear only, the paper's "train on one lighting, test on all"). mIoU is
``eden_pipe.eval.metrics`` (void ignored, confusion matrices summed over the
images of a lighting).

Models (``--model``): ``small`` (default), a 3-level encoder-decoder of
torchvision ``Conv2dNormActivation`` blocks (~0.57 M parameters, fast on CPU);
``lraspp``, torchvision's ``lraspp_mobilenet_v3_large(weights=None,
weights_backbone=None)``. Uses CUDA when present.

Data: ``eden_pipe.data.EdenDataset`` when the package has it, else a minimal
reader of its own over ``manifest.csv`` (``read_modality``). Images are held in
memory (small datasets only). ``--pred-out DIR`` writes the test predictions
in the ``python -m eden_pipe.eval`` folder convention (palette PNGs at the
manifest's semantic paths), so the CLI can score them.

``--task depth`` trains the same networks with one output channel, the
log-depth, and prints the test split's depth errors per lighting (abs rel,
log10, rms, deltas: ``eden_pipe.eval.metrics.DepthMeter``); the depth pieces
are in ``scripts/baseline_depth.py`` (docs/evaluation.md).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import torch
import torch.nn.functional as F
from torch import nn

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # run as a plain script from a checkout
    sys.path.insert(0, str(REPO))

from eden_pipe import labels  # noqa: E402
from eden_pipe.eval.metrics import NUM_CLASSES, SegmentationMeter  # noqa: E402
from eden_pipe.io.formats import read_modality, write_semantic  # noqa: E402
from eden_pipe.lighting import DEFAULT_SWEEP  # noqa: E402
from scripts import baseline_depth  # noqa: E402

LIGHTINGS = DEFAULT_SWEEP  # the paper's five; night is an extra scenario
IGNORE = 255  # void (class 0) in the training targets


# ------------------------------------------------------------------ dataset
def make_dataset(
    root,
    gardens: int = 5,
    test_gardens: int = 2,
    frames: int = 6,
    width: int = 128,
    height: int = 96,
    lightings=LIGHTINGS,
    stages=None,
    extra=(),
    echo=print,
) -> Path:
    """Generate ``gardens`` small gardens x ``lightings`` with the pipeline (one Hydra multirun).

    Gardens are seeds 0..gardens-1 (ids ``small-s<seed>``); the last ``test_gardens`` are pinned to test,
    the others to train. Only rgb, semantic and depth are rendered. The stage cache defaults to ``<root>.stages``.
    """
    root = Path(root).resolve()
    stages = Path(stages).resolve() if stages else root.with_name(root.name + ".stages")
    seeds = list(range(gardens))
    pinned = ", ".join(f"small-s{s}: test" for s in seeds[gardens - test_gardens :])
    f = width  # 90 degree horizontal field of view, as EDEN's 32 mm lens on a 32 mm sensor
    cmd = [
        sys.executable,
        "-m",
        "eden_pipe",
        "-m",
        "garden=small",
        "garden.seed=" + ",".join(map(str, seeds)),
        "lighting=" + ",".join(lightings),
        f"camera.trajectory.frames=[{frames},{frames}]",
        f"camera.width={width}",
        f"camera.height={height}",
        f"camera.fx={f}",
        f"camera.fy={f}",
        f"camera.cx={width / 2:g}",
        f"camera.cy={height / 2:g}",
        "garden.lawn.triangles_per_m2=1500",
        "render.modalities=[rgb,semantic,depth]",
        "split.train=1.0",
        "split.val=0.0",
        "split.test=0.0",
        f"++split.overrides={{{pinned}}}",
        f"paths.dataset={root}",
        f"paths.stages={stages}",
        "progress=false",
        f"hydra.sweep.dir={stages}/multirun",
        *extra,
    ]
    echo("generating: " + " ".join(cmd[1:]))
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, cwd=REPO, stdout=subprocess.DEVNULL if echo is None else None)
    echo(f"dataset generated in {time.perf_counter() - t0:.0f} s: {root}")
    return root


def _resize(rgb: torch.Tensor, sem: torch.Tensor, size):
    if size is None or tuple(rgb.shape[-2:]) == (size[1], size[0]):
        return rgb, sem
    rgb = F.interpolate(rgb[None], size=(size[1], size[0]), mode="bilinear", align_corners=False, antialias=True)[0]
    sem = F.interpolate(sem[None, None].float(), size=(size[1], size[0]), mode="nearest")[0, 0].long()
    return rgb, sem


def load_split(root, split: str, lightings=None, size=None) -> dict:
    """Every row of ``split`` (and ``lightings``) in memory.

    Returns {"rgb": float32 (N,3,H,W) in [0,1], "semantic": int64 (N,H,W) with void = 255,
    "lighting": [str], "semantic_path": [relative path]}; ``size`` = (W, H) resizes (labels nearest).
    """
    root = Path(root)
    try:
        from eden_pipe.data import EdenDataset  # the project's torch Dataset, when present
    except ImportError:
        EdenDataset = None
    rgbs, sems, lights, paths = [], [], [], []
    if EdenDataset is not None:
        ds = EdenDataset(root, ("rgb", "semantic"), split=split, lighting=lightings, ignore_index=IGNORE)
        for i in range(len(ds)):
            item = ds[i]
            rgb, sem = _resize(item["rgb"], item["semantic"], size)
            rgbs.append(rgb)
            sems.append(sem)
            lights.append(str(item["lighting"]))
            paths.append(str(ds.records[i]["semantic"]))
    else:  # minimal self-contained reader over the manifest
        df = pd.read_csv(root / "manifest.csv", keep_default_na=False)
        df = df[df["split"].astype(str) == split]
        if lightings:
            df = df[df["lighting"].astype(str).isin(set(lightings))]
        for rec in df.to_dict("records"):
            if not rec.get("rgb_left") or not rec.get("semantic"):
                continue
            rgb = torch.from_numpy(read_modality(root / rec["rgb_left"], "rgb_left").astype(np.float32) / 255.0)
            sem = torch.from_numpy(read_modality(root / rec["semantic"], "semantic").astype(np.int64))
            sem[sem == labels.VOID] = IGNORE
            rgb, sem = _resize(rgb.permute(2, 0, 1).contiguous(), sem, size)
            rgbs.append(rgb)
            sems.append(sem)
            lights.append(str(rec["lighting"]))
            paths.append(str(rec["semantic"]))
    if not rgbs:
        raise SystemExit(
            f"no {split} rows with rgb and semantic in {root}"
            + (f" for lighting(s) {', '.join(lightings)}" if lightings else "")
        )
    return {"rgb": torch.stack(rgbs), "semantic": torch.stack(sems), "lighting": lights, "semantic_path": paths}


# ------------------------------------------------------------------ models
class SmallSegNet(nn.Module):
    """3-level encoder-decoder (strides 2, 4, 8, dilated bottleneck) with skip connections."""

    def __init__(self, num_classes: int = NUM_CLASSES, width: int = 32):
        super().__init__()
        from torchvision.ops import Conv2dNormActivation as C

        w = width
        self.enc1 = nn.Sequential(C(3, w, 3, stride=2), C(w, w, 3))
        self.enc2 = nn.Sequential(C(w, 2 * w, 3, stride=2), C(2 * w, 2 * w, 3))
        self.enc3 = nn.Sequential(
            C(2 * w, 4 * w, 3, stride=2), C(4 * w, 4 * w, 3, dilation=2), C(4 * w, 4 * w, 3, dilation=4)
        )
        self.dec2 = C(6 * w, 2 * w, 3)
        self.dec1 = C(3 * w, w, 3)
        self.head = nn.Conv2d(w, num_classes, 1)

    def forward(self, x):
        size = x.shape[-2:]
        e1 = self.enc1(x)
        e2 = self.enc2(e1)
        e3 = self.enc3(e2)
        d2 = self.dec2(torch.cat([F.interpolate(e3, size=e2.shape[-2:], mode="bilinear", align_corners=False), e2], 1))
        d1 = self.dec1(torch.cat([F.interpolate(d2, size=e1.shape[-2:], mode="bilinear", align_corners=False), e1], 1))
        return F.interpolate(self.head(d1), size=size, mode="bilinear", align_corners=False)


class _LRASPP(nn.Module):
    def __init__(self, num_classes: int = NUM_CLASSES):
        super().__init__()
        from torchvision.models.segmentation import lraspp_mobilenet_v3_large

        self.net = lraspp_mobilenet_v3_large(weights=None, weights_backbone=None, num_classes=num_classes)

    def forward(self, x):
        return self.net(x)["out"]


def build_model(name: str = "small", num_classes: int = NUM_CLASSES) -> nn.Module:
    if name == "small":
        return SmallSegNet(num_classes)
    if name == "lraspp":
        return _LRASPP(num_classes)
    raise ValueError(f"unknown model {name!r}; one of small, lraspp")


MEAN, STD = 0.45, 0.25


def _normalise(x: torch.Tensor) -> torch.Tensor:
    return (x - MEAN) / STD


# ------------------------------------------------------------------ train / evaluate
def train(
    model: nn.Module,
    data: dict,
    *,
    epochs: float = 10,
    steps: int | None = None,
    batch_size: int = 16,
    lr: float = 3e-3,
    device="cpu",
    seed: int = 0,
    target: str = "semantic",
    loss_fn=None,
    echo=print,
) -> dict:
    """AdamW + one-cycle schedule, random horizontal flips; fits ``model(rgb)`` to ``data[target]`` by ``loss_fn``
    (default: cross-entropy, void ignored). Returns stats."""
    gen = torch.Generator().manual_seed(seed)
    n = len(data["rgb"])
    per_epoch = max(1, -(-n // batch_size))
    total = int(steps) if steps is not None else max(1, int(round(epochs * per_epoch)))
    model.to(device).train()
    opt = torch.optim.AdamW(model.parameters(), lr=lr, weight_decay=1e-4)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=lr, total_steps=total, pct_start=0.15)
    loss_fn = loss_fn or nn.CrossEntropyLoss(ignore_index=IGNORE)
    t0 = time.perf_counter()
    order = torch.randperm(n, generator=gen)
    pos, losses = 0, []
    for step in range(total):
        if pos + batch_size > n and pos > 0:
            order, pos = torch.randperm(n, generator=gen), 0
        idx = order[pos : pos + batch_size]
        pos += batch_size
        x = data["rgb"][idx]
        y = data[target][idx]
        flip = torch.rand(len(idx), generator=gen) < 0.5
        x = torch.where(flip[:, None, None, None], x.flip(-1), x)
        y = torch.where(flip.view(-1, *[1] * (y.ndim - 1)), y.flip(-1), y)
        x, y = _normalise(x.to(device)), y.to(device)
        loss = loss_fn(model(x), y)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        sched.step()
        losses.append(float(loss.detach()))
        if echo and (step % max(1, total // 10) == 0 or step == total - 1):
            echo(
                f"  step {step + 1}/{total}  loss {np.mean(losses[-per_epoch:]):.3f}  {time.perf_counter() - t0:.0f} s"
            )
    return {
        "steps": total,
        "epochs": total / per_epoch,
        "seconds": time.perf_counter() - t0,
        "final_loss": float(np.mean(losses[-per_epoch:])),
    }


@torch.no_grad()
def _outputs(model: nn.Module, rgb: torch.Tensor, device, batch_size: int):
    """The network's raw outputs, a batch at a time (eval mode, normalised input)."""
    model.to(device).eval()
    for i in range(0, len(rgb), batch_size):
        yield model(_normalise(rgb[i : i + batch_size].to(device)))


def predict(model: nn.Module, rgb: torch.Tensor, device="cpu", batch_size: int = 32) -> torch.Tensor:
    """Class ids (N,H,W) int64 in 1..9: void is never predicted."""
    out = []
    for logits in _outputs(model, rgb, device, batch_size):
        logits[:, labels.VOID] = -torch.inf
        out.append(logits.argmax(1).cpu())
    return torch.cat(out)


def predict_depth(model: nn.Module, rgb: torch.Tensor, device="cpu", batch_size: int = 32) -> torch.Tensor:
    """Depth (N,H,W) float32 in metres from a one-channel log-depth network."""
    return torch.cat([baseline_depth.depth_from_output(o).cpu() for o in _outputs(model, rgb, device, batch_size)])


def score(pred: torch.Tensor, data: dict) -> dict:
    """{lighting: SegmentationMeter result} plus "all"; ground truth void (255) -> 0 (ignored)."""
    gt = data["semantic"].clone()
    gt[gt == IGNORE] = labels.VOID
    meters: dict[str, SegmentationMeter] = {}
    for p, g, light in zip(pred.numpy(), gt.numpy(), data["lighting"], strict=True):  # one of each per image
        meters.setdefault(light, SegmentationMeter()).update(p, g)
    total = SegmentationMeter()
    for m in meters.values():
        total.merge(m)
    out = {k: meters[k].compute() for k in sorted(meters, key=lambda name: (LIGHTINGS + (name,)).index(name))}
    out["all"] = total.compute()
    return out


def write_predictions(pred: torch.Tensor, data: dict, pred_dir) -> None:
    for p, rel in zip(pred.numpy(), data["semantic_path"], strict=True):  # pred: one per image of data
        write_semantic(Path(pred_dir) / rel, p.astype(np.uint8))


def format_table(results: dict, test_counts: dict) -> str:
    """Markdown: rows = test lighting (+ all), columns = training set; mIoU in %."""
    cols = list(results)
    head = ["test lighting", "test images", *(f"train: {c}" for c in cols)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    rows = [x for x in LIGHTINGS if x in test_counts] + [x for x in test_counts if x not in LIGHTINGS] + ["all"]
    for light in rows:
        cells = [
            f"**{light}**" if light == "all" else light,
            str(sum(test_counts.values()) if light == "all" else test_counts[light]),
        ]
        for c in cols:
            v = results[c].get(light, {}).get("miou", float("nan"))
            cells.append("-" if np.isnan(v) else f"{100 * v:.1f}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def format_class_table(result: dict) -> str:
    """Per-class IoU (%) of one model, rows = test lighting."""
    classes = [n for i, n in enumerate(labels.NAMES) if i != labels.VOID]
    lines = ["| test lighting | " + " | ".join(classes) + " |", "|" + "---|" * (len(classes) + 1)]
    for light, r in result.items():
        cells = ["-" if np.isnan(r["iou"][c]) else f"{100 * r['iou'][c]:.1f}" for c in classes]
        lines.append(f"| {'**all**' if light == 'all' else light} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


# ------------------------------------------------------------------ CLI
def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--dataset", help="an existing dataset root")
    src.add_argument("--make-dataset", metavar="DIR", help="generate a small dataset here first (reused if present)")
    p.add_argument("--gardens", type=int, default=5, help="--make-dataset: gardens (seeds 0..N-1)")
    p.add_argument("--test-gardens", type=int, default=2, help="--make-dataset: how many of them are test")
    p.add_argument("--frames", type=int, default=6, help="--make-dataset: trajectory steps per garden and lighting")
    p.add_argument("--resolution", default="128x96", help="--make-dataset: WxH")
    p.add_argument("--size", default=None, help="resize images to WxH for training and testing (default: as stored)")
    p.add_argument("--train-split", default="train")
    p.add_argument("--test-split", default="test")
    p.add_argument(
        "--train-lighting",
        default="all",
        help="comma list of training sets, one model (table column) each: 'all' or a lighting",
    )
    p.add_argument(
        "--task",
        choices=("segmentation", "depth"),
        default="segmentation",
        help="segmentation: the mIoU table; depth: the depth error table (abs rel, log10, rms, deltas)",
    )
    p.add_argument("--model", choices=("small", "lraspp"), default="small")
    p.add_argument("--epochs", type=float, default=10)
    p.add_argument("--steps", type=int, default=None, help="training steps (overrides --epochs)")
    p.add_argument("--batch-size", type=int, default=16)
    p.add_argument("--lr", type=float, default=3e-3)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", default=None, help="default: cuda when available, else cpu")
    p.add_argument(
        "--pred-out",
        default=None,
        help="write the first model's test predictions here (python -m eden_pipe.eval convention; depth as .npy)",
    )
    return p


def _wh(text):
    if text is None:
        return None
    w, h = (int(v) for v in str(text).lower().split("x"))
    return w, h


def main(argv=None, echo=print) -> dict:
    args = build_parser().parse_args(argv)
    device = args.device or ("cuda" if torch.cuda.is_available() else "cpu")
    torch.manual_seed(args.seed)
    t_start = time.perf_counter()
    if args.make_dataset:
        root = Path(args.make_dataset)
        if (root / "manifest.csv").is_file():
            echo(f"reusing {root}/manifest.csv")
        else:
            w, h = _wh(args.resolution)
            make_dataset(root, args.gardens, args.test_gardens, args.frames, w, h, echo=echo)
    else:
        root = Path(args.dataset)
    size = _wh(args.size)
    depth = args.task == "depth"
    load = baseline_depth.load_depth_split if depth else load_split
    t0 = time.perf_counter()
    test = load(root, args.test_split, size=size)
    counts = {light: test["lighting"].count(light) for light in dict.fromkeys(test["lighting"])}
    results, stats = {}, {}
    for name in [s.strip() for s in args.train_lighting.split(",") if s.strip()]:
        data = load(root, args.train_split, None if name == "all" else [name], size=size)
        echo(
            f"train set '{name}': {len(data['rgb'])} images {tuple(data['rgb'].shape[-2:][::-1])} (W, H), "
            f"test: {len(test['rgb'])} images; {'depth ' if depth else ''}model {args.model} on {device} "
            f"(read in {time.perf_counter() - t0:.0f} s)"
        )
        torch.manual_seed(args.seed)
        model = build_model(args.model, 1 if depth else NUM_CLASSES)
        stats[name] = train(
            model,
            data,
            epochs=args.epochs,
            steps=args.steps,
            batch_size=args.batch_size,
            lr=args.lr,
            device=device,
            seed=args.seed,
            target="depth" if depth else "semantic",
            loss_fn=baseline_depth.log_depth_loss if depth else None,
            echo=echo,
        )
        stats[name]["train_images"] = len(data["rgb"])
        if depth:
            pred = predict_depth(model, test["rgb"], device)
            results[name] = baseline_depth.score_depth(pred, test, LIGHTINGS)
        else:
            pred = predict(model, test["rgb"], device)
            results[name] = score(pred, test)
        if args.pred_out and len(results) == 1:
            (baseline_depth.write_depth_predictions if depth else write_predictions)(pred, test, args.pred_out)
            echo(f"test predictions written to {args.pred_out}")
        t0 = time.perf_counter()
    trained = "; ".join(
        f"'{k}': {s['train_images']} train images, {s['steps']} steps ({s['epochs']:.1f} epochs), {s['seconds']:.0f} s"
        for k, s in stats.items()
    )
    echo("")
    if depth:
        echo(
            f"depth errors on the {args.test_split} split by lighting of the test images, model {args.model}, {trained}"
        )
        table = "\n\n".join(baseline_depth.format_depth_table(name, r) for name, r in results.items())
        echo(table)
    else:
        table = format_table(results, counts)
        first = next(iter(results))
        echo(f"mIoU (%) on the {args.test_split} split by lighting of the test images, model {args.model}, {trained}")
        echo(table)
        echo("")
        echo(f"per-class IoU (%), train: {first}")
        echo(format_class_table(results[first]))
    echo(f"\ntotal {time.perf_counter() - t_start:.0f} s")
    return {"results": results, "stats": stats, "table": table, "test_counts": counts}


if __name__ == "__main__":
    main()
