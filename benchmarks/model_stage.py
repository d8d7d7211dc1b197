"""Time of the whole model stage (terrain, lawn, every tree, bush, flower and asset model) per garden.

Runs ``run_model_stage`` on a fresh cache for each garden seed, exactly as a job does, and prints
wall and CPU seconds (CPU time is steadier on a shared machine), the lawn's share, triangles
built per pool and what the bushes drew. Configs are composed from the ``conf/`` of the
``eden_pipe`` that is imported, so two code versions compare in one command:

    for root in /path/to/baseline .; do PYTHONPATH=$root python benchmarks/model_stage.py --seeds 0,1,2; done

    python benchmarks/model_stage.py [--seeds 0,1,2] [overrides ...]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra

import eden_pipe
from eden_pipe.config import register_schemas, to_config
from eden_pipe.models.species import CONF_DIR
from eden_pipe.stages.cache import Artifact, StageCache
from eden_pipe.stages.model import load_model_keys, run_model_stage


def garden_config(overrides: list[str]):
    register_schemas()
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return to_config(compose("config", overrides=overrides)).garden


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="0,1,2", help="comma-separated garden seeds")
    ap.add_argument("overrides", nargs="*", help="Hydra overrides, e.g. garden=small")
    args = ap.parse_args()
    print(f"eden_pipe from {Path(eden_pipe.__file__).parent}")
    print(f"{'seed':>4} {'wall s':>7} {'cpu s':>7} {'lawn s':>7} {'models':>6}  triangles per pool")
    wall_total = cpu_total = 0.0
    for seed in (int(s) for s in args.seeds.split(",")):
        garden = garden_config([f"garden.seed={seed}", *args.overrides])
        with tempfile.TemporaryDirectory() as root:
            cache = StageCache(root)
            w0, c0 = time.perf_counter(), time.process_time()
            art = run_model_stage(garden, cache)
            wall, cpu = time.perf_counter() - w0, time.process_time() - c0
            marker = art.marker()
            tris: dict[str, int] = {}
            looks = []
            models = load_model_keys(art)
            for name, key in models.items():
                facts = Artifact("model", key, cache.path("model", key), True, 0.0).marker()
                pool = name.split("/")[0]
                tris[pool] = tris.get(pool, 0) + int(facts["faces"])
                if "leaf_type" in facts:
                    looks.append(facts["leaf_type"])
        wall_total, cpu_total = wall_total + wall, cpu_total + cpu
        pools = ", ".join(f"{p} {n:,}" for p, n in tris.items())
        print(
            f"{seed:>4} {wall:7.2f} {cpu:7.2f} {marker.get('lawn_seconds', 0):7.2f} {len(models):>6}  "
            f"lawn {marker.get('lawn_faces', 0):,}, {pools}" + (f"; bush leaves: {', '.join(looks)}" if looks else "")
        )
    print(f"total wall {wall_total:.2f} s, cpu {cpu_total:.2f} s")


if __name__ == "__main__":
    main()
