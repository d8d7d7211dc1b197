"""Blender Cycles, the EDEN paper's renderer, as a backend (``render=cycles``, ``render.backend=cycles``).

Cycles renders the light: rgb and the image-formation layers (albedo, shading, glossy,
translucency, background) of the same garden, camera, sky and sun. Every label-like pass (semantic,
instance, depth, normal, flow and its occlusion) comes from the Embree backend, so the ground truth
is identical across backends. Cycles runs in a worker process
(:mod:`eden_pipe.render.backends.cycles_worker`) started with ``render.cycles.python`` (empty: this
interpreter): ``bpy`` 5.0 pins numpy < 2, so it may live in an environment of its own
(docs/realism.md, Cycles).

Passes, per view (two renders that share Cycles' BVH; the camera's rays see the diffuse closure and
a mirror in the first, the translucent closure and the sun's glossy lobe in the second, all other rays
diffuse and translucent; the renderer's two glossy terms, the light along the mirror times a Fresnel
weight and the sun's lobe, each in its own render lit only by its own light):

- albedo = DiffCol, shading = DiffDir + DiffInd of the first render (Cycles divides its light
  passes by their colour pass, which is the albedo there);
- glossy = GlossCol * (GlossDir + GlossInd) of the first plus GlossCol * GlossDir of the second;
- translucency = DiffCol * (DiffDir + DiffInd) of the second (Translucent BSDF light is filed under
  Cycles' diffuse passes, hence the second render);
- background = Env of the first (the camera's map: sky, distant scenery, the sun's disc);
- linear = albedo * shading + glossy + translucency + background, the image formation
  (docs/design.md), so the identity holds to float32 rounding.

The world: the sky at the frame's time baked to two equirectangular maps (``map_width``): what
lights the garden (the sky's radiance, as the Embree renders integrate it) and what a camera ray
sees (plus distant scenery and the sun's disc); the sun as a sun lamp with the sampled direction,
irradiance, colour and angular size. Not modelled in Cycles: cloud shadows (the sun lamp is
unshadowed by clouds) and the terrain's procedural textures and bump (faces carry their mean
albedo).
"""

from __future__ import annotations

import logging
import os
import secrets
import subprocess
import sys
import tempfile
import threading
from dataclasses import dataclass
from multiprocessing.connection import Listener
from pathlib import Path

import numpy as np

from eden_pipe.modalities import MODALITIES
from eden_pipe.render.backends import Backend

log = logging.getLogger("eden_pipe")
WORKER = Path(__file__).with_name("cycles_worker.py")
START_TIMEOUT_S = 120.0  # importing bpy and connecting back
LIGHT_LAYERS = frozenset({"rgb", "albedo", "shading", "glossy", "translucency", "background"})
GLOSSY_DISTRIBUTION = "BECKMANN"  # the renderers' sun lobe (shading.glossy_parts)
# Cycles' pixel filter: a Gaussian 0.01 px wide, the narrowest Blender allows (its box filter is always 1 px
# wide). Cycles samples it over 3 widths with sigma = width / 4, so a pixel's rays reach 1.5 widths from its
# centre: on faces smaller than that footprint's reach, a pixel can see two faces (docs/realism.md, Cycles).
PIXEL_FILTER_WIDTH = 0.01
FOOTPRINT_REACH_PX = 1.5 * PIXEL_FILTER_WIDTH  # how far from its centre a Cycles pixel's rays reach


def glossy_roughness(alpha: float) -> float:
    """Blender's roughness ``r`` of a Beckmann lobe of roughness ``alpha`` (Blender squares its roughness:
    alpha = r^2); the renderers' glossy sun lobe is ``shading.GLOSS_ALPHA``'s (docs/realism.md, Cycles)."""
    return float(alpha**0.5)


class CyclesError(RuntimeError):
    """Cycles could not start or render (the worker's message and log tail included)."""


def interpreter(python: str) -> str:
    return python or sys.executable


def check_available(python: str) -> str | None:
    """None when ``python`` (``render.cycles.python``; empty: this interpreter) imports bpy, else why not."""
    exe = interpreter(python)
    try:
        res = subprocess.run(
            [exe, "-c", "import bpy, sys; sys.stdout.write(bpy.app.version_string)"],
            capture_output=True,
            text=True,
            timeout=START_TIMEOUT_S,
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"{exe}: {exc}"
    if res.returncode != 0:
        tail = (res.stderr or res.stdout).strip().splitlines()[-1:] or ["no output"]
        return (
            f"{exe} cannot import bpy ({tail[0]}); install it with pip install -e '.[cycles]' or point "
            "render.cycles.python at an interpreter that has bpy==5.0.*"
        )
    return None


def equirect_directions(width: int, height: int) -> np.ndarray:
    """(height, width, 3) unit directions at the texel centres of an equirectangular map in Blender's
    convention, rows top-down: u = 0.5 - azimuth / 2 pi (azimuth from +X toward +Y), v = 0.5 +
    elevation / pi (v = 1 the zenith)."""
    u = (np.arange(width) + 0.5) / width
    v = 1.0 - (np.arange(height) + 0.5) / height
    azimuth = (0.5 - u) * 2.0 * np.pi
    elevation = (v - 0.5) * np.pi
    el, az = np.meshgrid(elevation, azimuth, indexing="ij")
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1)


def world_maps(sky, settings, time: float, width: int) -> dict:
    """The worker's ``world`` message for the sky at ``time`` (module doc)."""
    from eden_pipe.render.shading import sky_and_background

    d = equirect_directions(width, width // 2).reshape(-1, 3)
    light = np.asarray(settings.sky_radiance(sky, d.astype(np.float32)), np.float32)
    seen = np.asarray(sky_and_background(sky, d, time), np.float32)
    shape = (width // 2, width, 3)
    return {
        "light_map": light.reshape(shape),
        "camera_map": seen.reshape(shape),
        "sun_direction": np.asarray(sky.sun_direction, np.float64),
        "sun_irradiance": np.asarray(sky.sun_irradiance, np.float64),
        "sun_angular_radius": float(sky.sun_angular_radius),
    }


class CyclesProcess:
    """The worker: one Blender scene in a child process (module doc), spoken to over a local socket."""

    def __init__(self, python: str = ""):
        self.folder = tempfile.TemporaryDirectory(prefix="eden-cycles-")
        address = os.path.join(self.folder.name, "socket")
        key = secrets.token_bytes(16)
        self.log_path = Path(self.folder.name) / "blender.log"
        self.listener = Listener(address, family="AF_UNIX", authkey=key)
        env = dict(os.environ, EDEN_CYCLES_AUTHKEY=key.hex())
        with open(self.log_path, "wb") as log:
            self.proc = subprocess.Popen(
                # -P: the script's folder is not put on sys.path (its cycles.py would shadow Blender's add-on)
                [interpreter(python), "-P", str(WORKER), address],
                stdout=log,
                stderr=subprocess.STDOUT,
                env=env,
            )
        self.conn = self._accept()
        _, self.facts = self.conn.recv()  # ('ready', Blender's and numpy's versions)
        self.renders = 0

    def _accept(self):
        got: dict = {}
        thread = threading.Thread(target=lambda: got.setdefault("conn", self.listener.accept()), daemon=True)
        thread.start()
        waited = 0.0
        while thread.is_alive() and waited < START_TIMEOUT_S:
            thread.join(0.2)
            waited += 0.2
            if self.proc.poll() is not None and thread.is_alive():
                log = self.log()
                self.close()
                raise CyclesError(f"the Cycles worker exited ({self.proc.returncode}) before connecting:\n{log}")
        if "conn" not in got:
            log = self.log()
            self.close()
            raise CyclesError(f"the Cycles worker did not connect within {START_TIMEOUT_S:.0f} s:\n{log}")
        return got["conn"]

    def log(self, lines: int = 20) -> str:
        try:
            return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-lines:])
        except OSError:
            return ""

    def call(self, kind: str, payload=None):
        try:
            self.conn.send((kind, plain(payload)))
            status, result = self.conn.recv()
        except (EOFError, OSError) as exc:
            raise CyclesError(f"the Cycles worker stopped during {kind!r} ({exc}):\n{self.log()}") from exc
        if status == "error":
            raise CyclesError(f"Cycles {kind!r} failed: {result}\n{self.log()}")
        return result

    def render(self, intr, pose: np.ndarray) -> tuple[dict[str, np.ndarray], dict]:
        """The two renders of one view (module doc) as {pass name: (H, W, 3) float32}, prefixed 1/ and 2/."""
        paths = [os.path.join(self.folder.name, f"view{self.renders}_{i}.exr") for i in (1, 2)]
        self.renders += 1
        view = {k: getattr(intr, k) for k in ("width", "height", "fx", "fy", "cx", "cy")}
        facts = self.call("view", dict(view, pose=np.asarray(pose, np.float64), paths=paths))
        passes = {}
        for i, path in enumerate(paths, 1):
            for name, value in read_passes(path).items():
                passes[f"{i}/{name}"] = value
            os.remove(path)
        return passes, facts

    def close(self) -> None:
        conn = getattr(self, "conn", None)
        if conn is not None and self.proc.poll() is None:
            try:
                self.call("close")
            except CyclesError:
                pass
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
        self.listener.close()
        self.folder.cleanup()


def plain(value):
    """``value`` with every numpy array as ("ndarray", dtype, shape, bytes): the worker's numpy may be
    another major version (bpy 5.0 pins numpy < 2), whose unpickler cannot read numpy 2's arrays."""
    if isinstance(value, np.ndarray):
        a = np.ascontiguousarray(value)
        return ("ndarray", a.dtype.str, a.shape, a.tobytes())
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, np.generic):
        return value.item()
    return value


def device_message(facts: dict) -> str:
    """A line on the device the worker's ``settings`` answer names (``device``, ``names``)."""
    if facts["device"] == "CPU":
        return "Cycles renders on the CPU"
    return (
        f"Cycles renders on {facts['device']} ({', '.join(facts['names'])}); its first render on a machine "
        "compiles the GPU kernels where bpy ships none for this GPU (minutes; cached by the driver; "
        "docs/realism.md, Cycles)"
    )


def worker_settings(cycles_cfg, threads: int = 0) -> dict:
    """The worker's ``settings`` message from ``render.cycles`` (a ``config.schema.CyclesConfig``)."""
    from eden_pipe.render.shading import GLOSS_ALPHA

    c = cycles_cfg
    return {
        "samples": int(c.samples),
        "seed": int(c.seed),
        "max_bounces": int(c.max_bounces),
        "diffuse_bounces": int(c.diffuse_bounces),
        "glossy_bounces": int(c.glossy_bounces),
        "transmission_bounces": int(c.transmission_bounces),
        "clamp_direct": float(c.clamp_direct),
        "clamp_indirect": float(c.clamp_indirect),
        "threads": int(threads),
        "device": str(c.device),
        "glossy_distribution": GLOSSY_DISTRIBUTION,
        "glossy_roughness": glossy_roughness(GLOSS_ALPHA),
        "filter_width": PIXEL_FILTER_WIDTH,
    }


def read_passes(path: str) -> dict[str, np.ndarray]:
    """{pass: (H, W, 3) float32} of a Blender multilayer EXR (channels ``<layer>.<pass>.<R|G|B>``, one
    part per pass since Blender 4)."""
    import OpenEXR

    groups: dict[str, dict[str, np.ndarray]] = {}
    with OpenEXR.File(path, separate_channels=True) as f:
        for part in f.parts:
            for name, ch in part.channels.items():
                pass_name, _, channel = name.rpartition(".")
                groups.setdefault(pass_name.partition(".")[2], {})[channel] = ch.pixels
    return {
        name: np.stack([chans[c] for c in "RGB"], axis=-1).astype(np.float32)
        for name, chans in groups.items()
        if all(c in chans for c in "RGB")
    }


def layers_from_passes(passes: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The image-formation layers (module doc) from the two renders' passes."""
    albedo = passes["1/Diffuse Color"]
    shading = passes["1/Diffuse Direct"] + passes["1/Diffuse Indirect"]
    # The second render's lobe holds the sun alone, its direct light (what its rays meet in the garden is
    # the first render's mirror's).
    glossy = passes["1/Glossy Color"] * (passes["1/Glossy Direct"] + passes["1/Glossy Indirect"])
    glossy = glossy + passes["2/Glossy Color"] * passes["2/Glossy Direct"]
    translucency = passes["2/Diffuse Color"] * (passes["2/Diffuse Direct"] + passes["2/Diffuse Indirect"])
    background = passes["1/Environment"]
    linear = albedo * shading + glossy + translucency + background
    return {
        "albedo": albedo,
        "shading": shading,
        "glossy": glossy,
        "translucency": translucency,
        "background": background,
        "linear": linear,
    }


@dataclass
class CyclesFrame:
    """A frame's state: the Embree frame's settings (for the label passes) and its sky's time."""

    embree: object
    time: float


class CyclesBackend(Backend):
    """Cycles for the light, the Embree backend for every label-like pass (module doc). One frame at a
    time: the worker holds one Blender scene."""

    name = "cycles"
    capabilities = frozenset(MODALITIES)
    max_frame_threads = 1

    @classmethod
    def unavailable(cls, render_cfg) -> str | None:
        why = check_available(str(render_cfg.cycles.python))
        if why is None:
            return None
        return f"render.cycles.python={str(render_cfg.cycles.python)!r}: {why} (render.backend=cycles needs bpy)"

    def __init__(self, scene, sky, render_cfg, *, modalities: set[str], threads: int = 0):
        from eden_pipe.render.backends.raytrace import RaytraceBackend

        self.scene, self.sky, self.cfg = scene, sky, render_cfg.cycles
        self.embree = RaytraceBackend(scene, sky, render_cfg, modalities=modalities, threads=threads)
        self.process = CyclesProcess(str(self.cfg.python))
        mesh = scene.mesh
        self.process.call(
            "scene",
            {
                "vertices": mesh.vertices,
                "faces": mesh.faces,
                "albedo": mesh.albedo,
                "translucency": mesh.translucency,
                "specular": mesh.specular,
            },
        )
        log.info(device_message(self.process.call("settings", worker_settings(self.cfg, threads))))
        self.world_time: float | None = None
        self.seconds: list[float] = []

    def frame(self, time: float, prev_time: float | None = None, next_time: float | None = None) -> CyclesFrame:
        return CyclesFrame(self.embree.frame(time), time)

    def render_view(
        self, state, intr, pose, *, want, pose_next=None, pose_prev=None, rng=None, rgb_spp=1, partner=None
    ):
        labels_wanted = (set(want) - LIGHT_LAYERS) | {"depth"}
        out = self.embree.render_view(
            state.embree, intr, pose, want=labels_wanted, pose_next=pose_next, pose_prev=pose_prev, rng=rng
        )
        if set(want) & LIGHT_LAYERS:
            if self.world_time != state.time:
                self.process.call("world", world_maps(self.sky, state.embree, state.time, int(self.cfg.map_width)))
                self.world_time = state.time
            passes, facts = self.process.render(intr, pose)
            self.seconds.append(sum(facts["seconds"]))
            layers = layers_from_passes(passes)
            for key in set(want) & (LIGHT_LAYERS - {"rgb"}):
                out[key] = layers[key]
            out["linear"] = layers["linear"]
            if "rgb" in want:
                out["rgb_linear"] = layers["linear"]
        return out

    def close(self) -> None:
        self.process.close()
        self.embree.close()
