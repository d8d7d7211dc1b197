"""Embree 4 without embreex's per-ray wrapper: the native tracer's library, scene and start-up check.

embreex ships Embree 4 as a shared library beside its extension modules
(``site-packages/embreex.libs/libembree4-*.so.4``); this module opens that same
library with cffi (ABI mode: no compiler) and declares the few calls the
tracer needs. The scene reads the mesh's index array in place and one padded
float32 copy of its vertices (shared buffers), with the flags embreex uses
(robust, default build quality), so every hit is the one embreex returns
(docs/design.md, "Ray tracing"). The ray loops are compiled (:mod:`embree_kernels`).

:func:`check_against_embreex` traces a small scene both ways and raises
:class:`NativeTracerError` naming what differs: a library that is not the one
the declarations describe, or a struct layout that is not the one the kernels
assume.
"""

from __future__ import annotations

import glob
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from eden_pipe.render import embree_kernels as kern

CDEF = """
typedef struct RTCDeviceTy* RTCDevice;
typedef struct RTCSceneTy* RTCScene;
typedef struct RTCGeometryTy* RTCGeometry;
RTCDevice rtcNewDevice(const char* config);
void rtcReleaseDevice(RTCDevice device);
int rtcGetDeviceError(RTCDevice device);
const char* rtcGetDeviceLastErrorMessage(RTCDevice device);
ssize_t rtcGetDeviceProperty(RTCDevice device, int prop);
RTCScene rtcNewScene(RTCDevice device);
void rtcSetSceneFlags(RTCScene scene, int flags);
void rtcSetSceneBuildQuality(RTCScene scene, int quality);
void rtcCommitScene(RTCScene scene);
void rtcReleaseScene(RTCScene scene);
RTCGeometry rtcNewGeometry(RTCDevice device, int type);
void rtcSetSharedGeometryBuffer(RTCGeometry geometry, int type, unsigned int slot, int format,
                                const void* ptr, size_t byteOffset, size_t byteStride, size_t itemCount);
void rtcCommitGeometry(RTCGeometry geometry);
void rtcSetGeometryBuildQuality(RTCGeometry geometry, int quality);
void rtcUpdateGeometryBuffer(RTCGeometry geometry, int type, unsigned int slot);
unsigned int rtcAttachGeometry(RTCScene scene, RTCGeometry geometry);
void rtcReleaseGeometry(RTCGeometry geometry);
void rtcIntersect1(RTCScene scene, void* rayhit, void* args);
void rtcIntersect8(const int* valid, RTCScene scene, void* rayhit, void* args);
void rtcIntersect16(const int* valid, RTCScene scene, void* rayhit, void* args);
void rtcOccluded1(RTCScene scene, void* ray, void* args);
void rtcOccluded8(const int* valid, RTCScene scene, void* ray, void* args);
void rtcOccluded16(const int* valid, RTCScene scene, void* ray, void* args);
"""
# Enum values of embree4/rtcore_*.h (4.4).
DEVICE_PROPERTY_VERSION_MAJOR = 1
# Whether the library traverses 16-ray packets as packets on this CPU (AVX-512); where not,
# rtcIntersect16 traces its lanes one by one (rtcore_ray.cpp), so a packet only adds its copies.
DEVICE_PROPERTY_NATIVE_RAY16 = 34
DEVICE_PROPERTY_FILTER_FUNCTION_SUPPORTED = 66  # the packets' tie test is an argument filter
GEOMETRY_TYPE_TRIANGLE = 0
BUFFER_TYPE_INDEX, BUFFER_TYPE_VERTEX = 0, 1
FORMAT_UINT3, FORMAT_FLOAT3 = 0x5003, 0x9003
SCENE_FLAG_DYNAMIC, SCENE_FLAG_ROBUST = 1 << 0, 1 << 2
BUILD_QUALITY = {"low": 0, "medium": 1, "high": 2}
BUILD_QUALITY_REFIT = 3  # a geometry's BVH refitted to moved vertices (honoured under a "low" scene)
DEFAULT_BUILD_QUALITY = "medium"  # Embree's (and so embreex's) default
FUNCTIONS = (  # embree_kernels.FN_* order
    "rtcIntersect1",
    "rtcIntersect16",
    "rtcOccluded1",
    "rtcOccluded16",
    "rtcIntersect8",
    "rtcOccluded8",
)
ERRORS = {1: "unknown", 2: "invalid argument", 3: "invalid operation", 4: "out of memory", 5: "unsupported CPU"}


class NativeTracerError(RuntimeError):
    """The native path cannot be used: the library is missing or disagrees with embreex."""


def library_path() -> str:
    """embreex's bundled libembree4 (the wheel's ``embreex.libs`` folder)."""
    import embreex

    site = os.path.dirname(os.path.dirname(os.path.abspath(embreex.__file__)))
    found = sorted(glob.glob(os.path.join(site, "embreex.libs", "libembree4*.so*")))
    if not found:
        raise NativeTracerError(f"no libembree4 in {os.path.join(site, 'embreex.libs')}")
    return found[0]


@dataclass
class EmbreeLibrary:
    ffi: Any  # cffi.FFI
    lib: Any  # the opened library
    functions: np.ndarray  # (7,) uint64 addresses, embree_kernels.FN_* order
    layout: np.ndarray  # (2,) int64 word offsets of the hit in RTCRayHit16 and RTCRayHit

    def address(self, pointer) -> int:
        return int(self.ffi.cast("uintptr_t", pointer))


def load_library(path: str | None = None, layout=kern.LAYOUT) -> EmbreeLibrary:
    """Open libembree4 (embreex's unless ``path``); ``layout`` overrides the kernels' struct layout
    (only for the start-up check's own test)."""
    try:
        import cffi

        ffi = cffi.FFI()  # imports cffi's C parser (pycparser), which a partial install can lack
        ffi.cdef(CDEF)
    except ImportError as exc:  # a dependency; kept for a clear message and auto's fallback
        raise NativeTracerError(f"cffi cannot be used: {exc}") from exc
    try:
        lib = ffi.dlopen(path or library_path())
    except OSError as exc:
        raise NativeTracerError(f"cannot open libembree4: {exc}") from exc
    addresses = [int(ffi.cast("uintptr_t", getattr(lib, name))) for name in FUNCTIONS]
    functions = np.array([*addresses, kern.other_primitive.address], np.uint64)
    return EmbreeLibrary(ffi, lib, functions, np.asarray(layout, np.int64))


def packet_lanes(lib, device) -> int:
    """The packet width to trace coherent rays with: 16 where the library traverses 16-ray packets
    natively (AVX-512), else 8. Embree's AVX2 builds (embreex's wheels) take a 16-ray packet one ray
    at a time, where an 8-ray packet is a real packet: on the 2-core AVX2 machine of docs/scale-out.md
    an image's rays took 0.55-0.66 of the time in 8-ray packets over 4x2 tiles, as single rays or
    16-ray packets took the same (docs/design.md, Ray tracing)."""
    return 16 if lib.rtcGetDeviceProperty(device, DEVICE_PROPERTY_NATIVE_RAY16) else 8


class NativeScene:
    """One committed Embree scene over a triangle mesh whose arrays it shares (not copies).

    ``vertices`` (V, 3) and ``faces`` (F, 3): a float32 copy of the vertices is made only if they
    are not float32 already, always with the 4 bytes of padding Embree's vector loads read past
    the last vertex (rtcSetSharedGeometryBuffer); int32 C-contiguous faces are used as they are.

    ``movable``: the scene's vertices may move (wind, docs/design.md "Wind"): a dynamic scene whose
    BVH :meth:`refit` adapts to the moved vertices instead of rebuilding it (Embree refits a
    geometry's BVH only in its two-level "low" scene build, so ``quality`` is then ignored).

    ``robust``: Embree's robust flag, watertight on shared edges (the render's ground truth); without
    it a ray may slip between two faces at their edge, and traversal is cheaper (the bake's rays,
    docs/scale-out.md).

    ``lanes``: the width of the coherent packets :func:`trace` sends (8 or 16); None: the widest the
    library traverses natively on this CPU (:func:`packet_lanes`). Every width gives the same hits
    but where two faces tie and :func:`trace` is told not to settle ties.
    """

    def __init__(
        self,
        library: EmbreeLibrary,
        vertices: np.ndarray,
        faces: np.ndarray,
        quality: str = "medium",
        movable: bool = False,
        robust: bool = True,
        lanes: int | None = None,
    ):
        if lanes is not None and lanes not in kern.PACKET_WIDTHS:
            raise ValueError(f"lanes must be one of {kern.PACKET_WIDTHS}, not {lanes!r}")
        self.library = library
        lib, ffi = library.lib, library.ffi
        n_vertices = len(vertices)
        padded = np.empty(n_vertices * 3 + 1, np.float32)
        padded[-1] = 0.0
        self.vertices = padded[:-1].reshape(n_vertices, 3)
        self.vertices[:] = vertices
        self.faces = np.ascontiguousarray(faces, np.int32)
        self._device = lib.rtcNewDevice(ffi.NULL)
        if self._device == ffi.NULL:
            raise NativeTracerError("rtcNewDevice failed")
        self._scene = ffi.NULL
        self._geometry = ffi.NULL
        try:
            major = lib.rtcGetDeviceProperty(self._device, DEVICE_PROPERTY_VERSION_MAJOR)
            if major != 4:
                raise NativeTracerError(f"libembree4 reports Embree version {major}, not 4")
            if not lib.rtcGetDeviceProperty(self._device, DEVICE_PROPERTY_FILTER_FUNCTION_SUPPORTED):
                raise NativeTracerError("libembree4 was built without filter functions")
            self.lanes = lanes or packet_lanes(lib, self._device)
            self._scene = lib.rtcNewScene(self._device)
            flags = (SCENE_FLAG_ROBUST if robust else 0) | (SCENE_FLAG_DYNAMIC if movable else 0)
            lib.rtcSetSceneFlags(self._scene, flags)
            lib.rtcSetSceneBuildQuality(self._scene, BUILD_QUALITY["low" if movable else quality])
            geometry = lib.rtcNewGeometry(self._device, GEOMETRY_TYPE_TRIANGLE)
            if movable:
                lib.rtcSetGeometryBuildQuality(geometry, BUILD_QUALITY_REFIT)
            lib.rtcSetSharedGeometryBuffer(
                geometry, BUFFER_TYPE_VERTEX, 0, FORMAT_FLOAT3, ffi.cast("void*", padded.ctypes.data), 0, 12, n_vertices
            )
            lib.rtcSetSharedGeometryBuffer(
                geometry,
                BUFFER_TYPE_INDEX,
                0,
                FORMAT_UINT3,
                ffi.cast("void*", self.faces.ctypes.data),
                0,
                12,
                len(self.faces),
            )
            lib.rtcCommitGeometry(geometry)
            lib.rtcAttachGeometry(self._scene, geometry)
            self._geometry = geometry if movable else ffi.NULL  # the scene holds a reference too
            if not movable:
                lib.rtcReleaseGeometry(geometry)
            lib.rtcCommitScene(self._scene)  # builds the BVH
            self._raise_device_error("building the scene")
        except BaseException:
            self.close()
            raise
        self._padded = padded  # Embree reads it until the scene is released
        self.handle = library.address(self._scene)

    def refit(self) -> None:
        """Adapt the BVH to the vertices written into :attr:`vertices` since the last commit (a
        ``movable`` scene only). Not thread-safe against queries on this scene."""
        lib, ffi = self.library.lib, self.library.ffi
        if self._geometry == ffi.NULL:
            raise NativeTracerError("refit needs a scene made with movable=True")
        lib.rtcUpdateGeometryBuffer(self._geometry, BUFFER_TYPE_VERTEX, 0)
        lib.rtcCommitGeometry(self._geometry)
        lib.rtcCommitScene(self._scene)
        self._raise_device_error("refitting the scene")

    def _raise_device_error(self, doing: str) -> None:
        lib, ffi = self.library.lib, self.library.ffi
        code = lib.rtcGetDeviceError(self._device)
        if code:
            message = lib.rtcGetDeviceLastErrorMessage(self._device)
            text = ffi.string(message).decode() if message != ffi.NULL else ""
            raise NativeTracerError(f"Embree error while {doing}: {ERRORS.get(code, code)} {text}".rstrip())

    def close(self) -> None:
        lib, ffi = self.library.lib, self.library.ffi
        if getattr(self, "_geometry", ffi.NULL) != ffi.NULL:
            lib.rtcReleaseGeometry(self._geometry)
            self._geometry = ffi.NULL
        if self._scene != ffi.NULL:
            lib.rtcReleaseScene(self._scene)
            self._scene = ffi.NULL
            self.handle = 0
        if self._device != ffi.NULL:
            lib.rtcReleaseDevice(self._device)
            self._device = ffi.NULL


def check_scene(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A small scene for the start-up check: 400 random triangles in a unit box (vertices, faces)."""
    n = 400
    centres = rng.uniform(-1, 1, (n, 1, 3))
    vertices = (centres + rng.normal(0, 0.15, (n, 3, 3))).reshape(-1, 3).astype(np.float32)
    return vertices, np.arange(3 * n, dtype=np.int32).reshape(n, 3)


def trace(
    scene: NativeScene,
    query: int,
    origins,
    dirs,
    tfar,
    map_chunks,
    image=None,
    pixels=None,
    settle_ties=True,
    along=None,
):
    """Trace ``origins``/``dirs`` (N, 3) float32 C-contiguous (``dirs`` may be (1, 3): one for all)
    with ``tfar`` (N,) or (1,) float32 through ``scene``. ``query`` 0: closest hits, returns
    (t, prim, Ng) with inf, -1, 0 on misses; else (occluded,). ``image`` (h, w): the rays are that
    image's pixels, row-major, or with ``pixels`` (N,) those pixels (sorted or not): traced as
    coherent packets of ``scene.lanes`` rays over tiles of 4 x lanes/4 pixels; else one ray at a
    time. Rays with one direction (occlusion rays, or closest hits whose ties need not be
    settled) go as packets of neighbours across it (:func:`embree_kernels.plane_order`), with or
    without ``image``; so do rays with directions of their own that nearly share ``along`` (3,)
    (the sun's disc), in the order of where they cross the plane across it. ``map_chunks(fn, n)`` runs
    ``fn(start, stop)`` over chunks of ``n`` rays (RayTracer.map_chunks). ``settle_ties``: packets'
    closest hits tied with another face at the same distance are traced again alone, so they are
    the single ray's; False keeps the packet's own pick (RayTracer.intersect)."""
    n = len(origins)
    t = np.full(n if query == 0 else 0, np.inf, np.float32)
    prim = np.full(n if query == 0 else 0, -1, np.int64)
    ng = np.zeros((n if query == 0 else 0, 3), np.float32)
    occ = np.zeros(n if query != 0 else 0, np.bool_)
    out = (t, prim, ng, occ)
    if n == 0:
        return (t, prim, ng) if query == 0 else (occ,)
    if len(dirs) not in (1, n) or len(tfar) not in (1, n) or origins.shape != (n, 3) or dirs.shape[1:] != (3,):
        raise ValueError(f"{n} origins need (1 or {n}, 3) directions and 1 or {n} distances")
    library, lanes = scene.library, scene.lanes
    common = (library.functions, scene.handle, query, library.layout)
    steps = (int(len(dirs) > 1), tfar, int(len(tfar) > 1))
    ties = int(settle_ties)
    tall = lanes // kern.TILE  # tiles are TILE pixels wide
    if along is None and len(dirs) == 1 and (query != 0 or not settle_ties):
        along = dirs[0]
    if along is not None:
        # Parallel rays (sun shadows): packets of rays whose lines lie close together
        # across the direction, wherever they start (an image's tile can hold a leaf and the lawn
        # behind it): 1.22-1.27x the image tiles' speed with the same answers (docs/scale-out.md).
        order = kern.plane_order(origins, np.asarray(along, np.float32))
        starts = np.minimum(np.arange(0, n + lanes, lanes), n)
        groups = len(starts) - 1

        def run(a: int, b: int) -> None:
            kern.grouped(
                *common, lanes, origins, dirs, *steps, order, starts, a * groups // n, b * groups // n, out, ties
            )

    elif image is not None and pixels is None:
        height, width = image
        if height * width != n:
            raise ValueError(f"{n} rays are not an image of {height} x {width} pixels")
        tiles = -(-height // tall) * -(-width // kern.TILE)

        def run(a: int, b: int) -> None:
            kern.image_tiles(
                *common, lanes, origins, dirs, *steps, height, width, a * tiles // n, b * tiles // n, out, ties
            )

    elif image is not None:
        order, starts = kern.tile_groups(np.ascontiguousarray(pixels, np.int64), int(image[1]), tall)
        groups = len(starts) - 1

        def run(a: int, b: int) -> None:
            kern.grouped(
                *common, lanes, origins, dirs, *steps, order, starts, a * groups // n, b * groups // n, out, ties
            )

    else:

        def run(a: int, b: int) -> None:
            kern.single_rays(*common, origins, dirs, *steps, a, b, out)

    map_chunks(run, n)
    return (t, prim, ng) if query == 0 else (occ,)


def _serial(fn, n):
    return [fn(0, n)]


def check_against_embreex(library: EmbreeLibrary) -> None:
    """Trace a small scene through the native kernels and through embreex; raise
    :class:`NativeTracerError` naming each query whose hits (prim, t, Ng) or occlusion differ."""
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    rng = np.random.default_rng(7)
    vertices, faces = check_scene(rng)
    reference = rtcs.EmbreeScene()
    TriangleMesh(reference, vertices, faces)
    height, width = 18, 23  # not a multiple of the tile: partial tiles too
    # A pinhole camera outside the box: most rays hit, the corners miss.
    v, u = np.meshgrid(np.linspace(-0.9, 0.9, height), np.linspace(-0.9, 0.9, width), indexing="ij")
    cam_dirs = np.stack([u.ravel(), v.ravel(), np.ones(u.size)], 1).astype(np.float32)
    cam_origins = np.broadcast_to(np.array([0.05, -0.02, -2.5], np.float32), cam_dirs.shape).copy()
    rand_origins = rng.uniform(-1.2, 1.2, (500, 3)).astype(np.float32)
    rand_dirs = rng.normal(size=(500, 3)).astype(np.float32)
    pixels = np.sort(rng.choice(height * width, 150, replace=False))
    limit = rng.uniform(0.2, 3.0, height * width).astype(np.float32)
    # (name, origins, directions, tmax, image, pixels, lanes)
    cases: list[tuple[str, np.ndarray, np.ndarray, Any, Any, Any, int]] = [
        ("rtcIntersect1", rand_origins, rand_dirs, None, None, None, kern.PACKET_WIDTHS[0])
    ]
    for lanes in kern.PACKET_WIDTHS:  # both widths, whichever this CPU's scenes will use
        cases += [
            (f"rtcIntersect{lanes} image packets", cam_origins, cam_dirs, None, (height, width), None, lanes),
            (
                f"rtcIntersect{lanes} masked packets",
                cam_origins[pixels],
                cam_dirs[pixels],
                None,
                (height, width),
                pixels,
                lanes,
            ),
            (f"rtcIntersect{lanes} with tmax", cam_origins, cam_dirs, limit, (height, width), None, lanes),
        ]
    problems = []
    scenes = {lanes: NativeScene(library, vertices, faces, lanes=lanes) for lanes in kern.PACKET_WIDTHS}
    try:
        for name, o, d, tmax, image, px, lanes in cases:
            scene = scenes[lanes]
            dists = np.full(len(o), 1e37, np.float32) if tmax is None else tmax
            res = reference.run(o, d, dists=dists.copy(), output=1)
            hit = res["geomID"] >= 0
            want_prim = np.where(hit, res["primID"], -1)
            want_t = np.where(hit, res["tfar"], np.inf).astype(np.float32)
            want_ng = np.where(hit[:, None], res["Ng"], 0).astype(np.float32)
            t, prim, ng = trace(scene, 0, o, d, dists, _serial, image, px)
            for field, got, want in (("prim", prim, want_prim), ("t", t, want_t), ("normal", ng, want_ng)):
                bad = ~np.all((got == want).reshape(len(o), -1), axis=1)
                if bad.any():
                    problems.append(f"{name}: {field} differs on {int(bad.sum())} of {len(o)} rays")
            if not hit.any() or hit.all():
                problems.append(f"{name}: the check's rays should both hit and miss")
            occluded_name = name.replace("Intersect", "Occluded")
            want_occ = np.asarray(reference.run(o, d, dists=dists.copy(), query="OCCLUDED")) >= 0
            (occ,) = trace(scene, 1, o, d, dists, _serial, image, px)
            if np.any(occ != want_occ):
                problems.append(
                    f"{occluded_name}: occlusion differs on {int((occ != want_occ).sum())} of {len(o)} rays"
                )
    finally:
        for scene in scenes.values():
            scene.close()
    if problems:
        raise NativeTracerError(
            "the native Embree path disagrees with embreex on a test scene (library or struct layout): "
            + "; ".join(problems)
        )
