"""Compiled ray loops that call Embree 4 directly (the native tracer, :mod:`embree_native`).

Each kernel fills Embree's ray structures for a range of work, calls one of
``rtcIntersect1/16`` or ``rtcOccluded1/16`` and reads the results back, all in
compiled code without the GIL, so the tracer's thread pool runs chunks in
parallel. Embree's functions arrive as plain addresses (integers) and are
called through :func:`call3`/:func:`call4`: nothing in a kernel refers to a
process-specific object, so numba caches the kernels on disk (``cache=True``)
and a new process starts without compiling them.

Packets (docs/design.md, "Ray tracing"): an image's pixel-centre rays go out as
packets of ``lanes`` rays (16 over 4x4 pixel tiles, or 8 over 4x2: the widest
Embree traverses natively on the CPU, ``embree_native.packet_lanes``) with
Embree's COHERENT query flag; a subset of an image's pixels (shadow and
occlusion rays from hit pixels) goes out in the same tiles, a packet per tile
with the other lanes masked off. Incoherent rays (bounces) go one at a time,
as embreex traces them.

Struct layouts are those of Embree 4's ``rtcore_ray.h`` and ``rtcore_scene.h``
built with its defaults (one instance level, instance arrays on, no min-width):
:mod:`embree_native` checks them against embreex's results before use.
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import cfunc, njit, types
from numba.extending import intrinsic

INVALID_ID = 0xFFFFFFFF  # RTC_INVALID_GEOMETRY_ID
QUERY_COHERENT = 1 << 16  # RTC_RAY_QUERY_FLAG_COHERENT
FEATURE_ALL = 0xFFFFFFFF  # RTC_FEATURE_FLAG_ALL
TILE = 4  # packets cover TILE pixels across and lanes // TILE down
LANES = TILE * TILE  # the widest packet (RTCRayHit16); 8-lane packets use the first half of each buffer
PACKET_WIDTHS = (8, 16)  # rtcIntersect8/16, rtcOccluded8/16

# RTCRayN as float32 words: 12 fields of N lanes each (field k of lane i at k * N + i); RTCHitN
# follows it. Embree's build options move only the hit part (RTC_MAX_INSTANCE_LEVEL_COUNT, instance
# arrays), so where the hit starts is a run-time ``layout`` entry (for N = 16; N lanes: its N/16),
# which the start-up check can get wrong on purpose.
P_ORG_X, P_ORG_Y, P_ORG_Z, P_TNEAR = 0, 1, 2, 3
P_DIR_X, P_DIR_Y, P_DIR_Z, P_TIME = 4, 5, 6, 7
P_TFAR, P_MASK, P_ID, P_FLAGS = 8, 9, 10, 11
# RTCHitN fields (N-lane rows from its start): Ng_x, Ng_y, Ng_z, u, v, primID, geomID, instID, instPrimID.
H_NG, H_PRIM, H_GEOM, H_INST, H_INST_PRIM = 0, 5, 6, 7, 8
# RTCRay (12 words), then RTCHit: Ng (3), u, v, primID, geomID, instID, instPrimID.
S_TFAR, S_MASK = 8, 9
H1_NG, H1_PRIM, H1_GEOM, H1_INST, H1_INST_PRIM = 0, 5, 6, 7, 8
# Where the hit starts (words) in RTCRayHit16 and RTCRayHit of Embree's default build.
LAYOUT = (192, 12)
PACKET_WORDS = 336  # sizeof(RTCRayHit16) / 4
SINGLE_WORDS = 24  # sizeof(RTCRayHit) / 4, 16-byte aligned
SLACK_WORDS = 256  # spare room after each structure: a build with more instance levels writes past it
# RTCIntersectArguments / RTCOccludedArguments: flags, feature_mask, three pointers (and a float in
# min-width builds): 64 zeroed bytes hold either.
ARGS_WORDS = 16

QUERY_INVOKE_ARGUMENT_FILTER = 1 << 1  # RTC_RAY_QUERY_FLAG_INVOKE_ARGUMENT_FILTER
ARGS_FILTER = 2  # RTCIntersectArguments.filter, in 64-bit words
# RTCFilterFunctionNArguments: int* valid, void* geometryUserPtr, context, RTCRayN* ray, RTCHitN* hit,
# unsigned int N (bytes); RTCRayN/RTCHitN hold N lanes of each field: id is the ray's 11th field,
# primID the hit's 6th.
FILTER_VALID, FILTER_RAY, FILTER_HIT, FILTER_N = 0, 24, 32, 40
RAY_ID_FIELD, HIT_PRIM_FIELD = 10, 5

# The function table (embree_native.EmbreeLibrary.functions): Embree's queries, then the tie filter.
FN_INTERSECT1, FN_INTERSECT16, FN_OCCLUDED1, FN_OCCLUDED16, FN_INTERSECT8, FN_OCCLUDED8 = 0, 1, 2, 3, 4, 5
FN_OTHER_PRIMITIVE = 6


def _call_codegen(arity: int):
    def codegen(context, builder, signature, llargs):
        voidp = ir.IntType(8).as_pointer()
        fnty = ir.FunctionType(ir.VoidType(), [voidp] * arity)
        target = builder.inttoptr(llargs[0], fnty.as_pointer())
        builder.call(target, [builder.inttoptr(x, voidp) for x in llargs[1:]])
        return context.get_dummy_value()

    return codegen


@intrinsic
def call3(typingctx, fn, a, b, c):
    """``fn(a, b, c)`` for a C function at address ``fn`` taking three pointers (given as integers):
    rtcIntersect1 / rtcOccluded1 (scene, ray, arguments)."""
    return types.void(fn, a, b, c), _call_codegen(3)


@intrinsic
def call4(typingctx, fn, a, b, c, d):
    """As :func:`call3` with four pointers: rtcIntersect16 / rtcOccluded16 (valid, scene, ray, arguments)."""
    return types.void(fn, a, b, c, d), _call_codegen(4)


@intrinsic
def fused_multiply_subtract(typingctx, a, b, c):
    """``a * b - c`` with one rounding (float32), as Embree's ``msub`` on FMA machines."""

    def codegen(context, builder, signature, llargs):
        x, y, z = llargs
        return builder.fma(x, y, builder.fneg(z))

    return types.float32(types.float32, types.float32, types.float32), codegen


def _memory_codegen(bits: int, store: bool):
    def codegen(context, builder, signature, llargs):
        pointer = builder.inttoptr(llargs[0], ir.IntType(bits).as_pointer())
        if store:
            builder.store(llargs[1], pointer)
            return context.get_dummy_value()
        return builder.load(pointer)

    return codegen


@intrinsic
def load_u32(typingctx, address):
    """The 32-bit word at ``address`` (an integer), as the filter below reads Embree's structures."""
    return types.uint32(address), _memory_codegen(32, False)


@intrinsic
def load_u64(typingctx, address):
    return types.uint64(address), _memory_codegen(64, False)


@intrinsic
def store_i32(typingctx, address, value):
    if not isinstance(value, types.Integer) or value.bitwidth != 32:
        return None
    return types.void(address, value), _memory_codegen(32, True)


@cfunc(types.void(types.uint64), cache=True)
def other_primitive(args):
    """An Embree argument filter (RTCFilterFunctionN) that rejects each lane's hit on the primitive
    whose id the ray carries in its ``id`` field: an occlusion query from the closest hit's distance
    to itself then finds whether another primitive lies at exactly that distance (a tie)."""
    valid = load_u64(args + FILTER_VALID)
    ray = load_u64(args + FILTER_RAY)
    hit = load_u64(args + FILTER_HIT)
    n = load_u32(args + FILTER_N)
    for i in range(n):
        own = load_u32(ray + 4 * (RAY_ID_FIELD * n + i))
        if load_u32(valid + 4 * i) != 0 and load_u32(hit + 4 * (HIT_PRIM_FIELD * n + i)) == own:
            store_i32(valid + 4 * i, np.int32(0))


@njit(nogil=True, cache=True)
def _aligned(words: int, align: int) -> np.ndarray:
    """A zeroed float32 buffer of ``words`` whose first element lies on an ``align``-byte boundary."""
    raw = np.zeros(words + align // 4, np.float32)
    skip = ((-raw.ctypes.data) % align) // 4
    return raw[skip : skip + words]


@njit(nogil=True, cache=True)
def _query_args(flags: int) -> np.ndarray:
    """rtcInitIntersectArguments / rtcInitOccludedArguments (inline in the headers), with ``flags``."""
    args = _aligned(ARGS_WORDS, 16).view(np.uint32)
    args[0] = flags
    args[1] = FEATURE_ALL
    return args


@njit(nogil=True, cache=True, inline="always")  # per ray: no call, no reference counting
def _fill_lane(buf, hit, n, lane, origins, dirs, dir_step, tfar, tfar_step, ray):
    """Lane ``lane`` of an ``n``-lane packet (hit part at word ``hit``) <- ray ``ray``."""
    ints = buf.view(np.uint32)
    buf[P_ORG_X * n + lane] = origins[ray, 0]
    buf[P_ORG_Y * n + lane] = origins[ray, 1]
    buf[P_ORG_Z * n + lane] = origins[ray, 2]
    buf[P_TNEAR * n + lane] = 0.0
    d = ray * dir_step
    buf[P_DIR_X * n + lane] = dirs[d, 0]
    buf[P_DIR_Y * n + lane] = dirs[d, 1]
    buf[P_DIR_Z * n + lane] = dirs[d, 2]
    buf[P_TIME * n + lane] = 0.0
    buf[P_TFAR * n + lane] = tfar[ray * tfar_step]
    ints[P_MASK * n + lane] = INVALID_ID  # every mask bit
    ints[P_ID * n + lane] = 0
    ints[P_FLAGS * n + lane] = 0
    for field in (H_PRIM, H_GEOM, H_INST, H_INST_PRIM):
        ints[hit + field * n + lane] = INVALID_ID


@njit(nogil=True, cache=True, inline="always")
def _packet(fns, scene, query, layout, work, lanes, rays, count, origins, dirs, dir_step, tfar, tfar_step, out, ties):
    """Trace one packet of ``count`` rays (indices ``rays``; the other of its ``lanes`` lanes masked
    off) and store its results: ``query`` 0, closest hits into ``out`` = (t, prim, ng) (misses
    untouched); else occlusion into ``out[3]``. ``work``: :func:`_buffers`. ``ties`` (closest hits):
    1 settles ties as single rays do, 0 keeps the packet's own pick."""
    buf, valid, args, tie_args, single = work
    single_ints = single.view(np.uint32)
    n = lanes
    hit = layout[0] // LANES * n  # the hit follows the ray's 12 fields of n lanes
    for lane in range(n):
        valid[lane] = -1 if lane < count else 0
        if lane < count:
            _fill_lane(buf, hit, n, lane, origins, dirs, dir_step, tfar, tfar_step, rays[lane])
    if n == LANES:
        fn, occluded = (fns[FN_INTERSECT16] if query == 0 else fns[FN_OCCLUDED16]), fns[FN_OCCLUDED16]
    else:
        fn, occluded = (fns[FN_INTERSECT8] if query == 0 else fns[FN_OCCLUDED8]), fns[FN_OCCLUDED8]
    call4(fn, valid.ctypes.data, scene, buf.ctypes.data, args.ctypes.data)
    t, prim, ng, occ = out
    ints = buf.view(np.uint32)
    hits = 0
    for lane in range(count):
        ray = rays[lane]
        valid[lane] = 0
        if query != 0:
            occ[ray] = buf[P_TFAR * n + lane] < 0.0  # Embree sets tfar to -inf on a hit
        elif ints[hit + H_GEOM * n + lane] != INVALID_ID:
            t[ray] = buf[P_TFAR * n + lane]
            prim[ray] = ints[hit + H_PRIM * n + lane]
            for k in range(3):
                ng[ray, k] = buf[hit + (H_NG + k) * n + lane]
            # Ready the lane for the tie test: the segment [t, t], carrying its primitive's id.
            buf[P_TNEAR * n + lane] = buf[P_TFAR * n + lane]
            ints[P_ID * n + lane] = ints[hit + H_PRIM * n + lane]
            valid[lane] = -1
            hits += 1
    if hits == 0 or ties == 0:
        return
    # Where two primitives lie at the closest distance (duplicated or coincident faces), which one
    # Embree reports depends on the order it visits them, which packets and single rays do not
    # share: 43 of 9.2 M primary rays of the default garden differed. Such rays go again alone,
    # as embreex traces them, so every hit is the single-ray one.
    call4(occluded, valid.ctypes.data, scene, buf.ctypes.data, tie_args.ctypes.data)
    for lane in range(count):
        if valid[lane] != 0 and buf[P_TFAR * n + lane] < 0.0:
            ray = rays[lane]
            _fill_single(single, single_ints, layout[1], origins, dirs, dir_step, tfar, tfar_step, ray)
            call3(fns[FN_INTERSECT1], scene, single.ctypes.data, 0)
            _read_single(single, single_ints, layout[1], ray, t, prim, ng)


@njit(nogil=True, cache=True)
def _buffers(fns):
    """(ray packet, valid mask, coherent query arguments, the tie test's arguments, a single ray),
    aligned as Embree requires."""
    buf = _aligned(PACKET_WORDS + SLACK_WORDS, 64)
    valid = _aligned(LANES, 64).view(np.int32)
    tie_args = _query_args(QUERY_COHERENT | QUERY_INVOKE_ARGUMENT_FILTER)
    tie_args.view(np.uint64)[ARGS_FILTER] = fns[FN_OTHER_PRIMITIVE]
    single = _aligned(SINGLE_WORDS + SLACK_WORDS, 16)
    return buf, valid, _query_args(QUERY_COHERENT), tie_args, single


@njit(nogil=True, cache=True)
def image_tiles(
    fns, scene, query, layout, lanes, origins, dirs, dir_step, tfar, tfar_step, height, width, lo, hi, out, ties
):
    """Rays of a row-major ``height`` x ``width`` image, one per pixel, in ``lanes``-ray packets over
    the tiles ``lo:hi`` (``TILE`` pixels wide, ``lanes // TILE`` high; row-major over the grid of
    tiles). ``dir_step``/``tfar_step`` 0: one direction / distance for all rays; ``out``, ``ties``:
    as :func:`_packet`."""
    work = _buffers(fns)
    rays = np.empty(LANES, np.int64)
    tall = lanes // TILE
    tiles_x = (width + TILE - 1) // TILE
    for k in range(lo, hi):
        y0 = (k // tiles_x) * tall
        x0 = (k % tiles_x) * TILE
        count = 0
        for y in range(y0, min(y0 + tall, height)):
            for x in range(x0, min(x0 + TILE, width)):
                rays[count] = y * width + x
                count += 1
        _packet(
            fns, scene, query, layout, work, lanes, rays, count, origins, dirs, dir_step, tfar, tfar_step, out, ties
        )


@njit(nogil=True, cache=True)
def grouped(
    fns, scene, query, layout, lanes, origins, dirs, dir_step, tfar, tfar_step, order, starts, lo, hi, out, ties
):
    """Rays in groups ``lo:hi``, group g being rays ``order[starts[g]:starts[g + 1]]`` (one tile's
    pixels, :func:`tile_groups`), in packets of up to ``lanes``; arguments as :func:`image_tiles`."""
    work = _buffers(fns)
    for g in range(lo, hi):
        for s in range(starts[g], starts[g + 1], lanes):
            count = min(lanes, starts[g + 1] - s)
            _packet(
                fns,
                scene,
                query,
                layout,
                work,
                lanes,
                order[s : s + count],
                count,
                origins,
                dirs,
                dir_step,
                tfar,
                tfar_step,
                out,
                ties,
            )


@njit(nogil=True, cache=True, inline="always")  # per ray: no call, no reference counting
def _fill_single(buf, ints, hit, origins, dirs, dir_step, tfar, tfar_step, ray):
    d = ray * dir_step
    for k in range(3):
        buf[k] = origins[ray, k]
        buf[4 + k] = dirs[d, k]
    buf[3] = 0.0  # tnear
    buf[7] = 0.0  # time
    buf[S_TFAR] = tfar[ray * tfar_step]
    ints[S_MASK] = INVALID_ID
    ints[S_MASK + 1] = 0  # id
    ints[S_MASK + 2] = 0  # flags
    for field in (H1_PRIM, H1_GEOM, H1_INST, H1_INST_PRIM):
        ints[hit + field] = INVALID_ID


@njit(nogil=True, cache=True, inline="always")
def _read_single(buf, ints, hit, ray, t, prim, ng):
    if ints[hit + H1_GEOM] != INVALID_ID:
        t[ray] = buf[S_TFAR]
        prim[ray] = ints[hit + H1_PRIM]
        for k in range(3):
            ng[ray, k] = buf[hit + H1_NG + k]


@njit(nogil=True, cache=True)
def single_rays(fns, scene, query, layout, origins, dirs, dir_step, tfar, tfar_step, lo, hi, out):
    """Rays ``lo:hi`` one at a time (incoherent: Embree's default query arguments, as embreex);
    arguments as :func:`image_tiles`."""
    buf = _aligned(SINGLE_WORDS + SLACK_WORDS, 16)
    ints = buf.view(np.uint32)
    address = buf.ctypes.data
    hit = layout[1]
    t, prim, ng, occ = out
    if query == 0:
        for ray in range(lo, hi):
            _fill_single(buf, ints, hit, origins, dirs, dir_step, tfar, tfar_step, ray)
            call3(fns[FN_INTERSECT1], scene, address, 0)
            _read_single(buf, ints, hit, ray, t, prim, ng)
    else:
        for ray in range(lo, hi):
            _fill_single(buf, ints, hit, origins, dirs, dir_step, tfar, tfar_step, ray)
            call3(fns[FN_OCCLUDED1], scene, address, 0)
            occ[ray] = buf[S_TFAR] < 0.0  # Embree sets tfar to -inf on a hit


@njit(nogil=True, cache=True)
def tile_groups(pixels, width, tall=TILE):
    """(order, starts) for the rays of an image's pixels ``pixels`` (one ray each, any order): ray
    indices grouped by tile (``TILE`` pixels wide, ``tall`` high), tiles in row-major order and rays
    in their given order within a tile (a counting sort), and where each non-empty tile's group
    starts (plus the end)."""
    tiles_x = (width + TILE - 1) // TILE
    n = len(pixels)
    tile = np.empty(n, np.int64)
    top = 0
    # The pixel's row follows the previous pixel's where they come in order (np.flatnonzero's, the
    # callers' usual), stepping a row at a time: no integer division per pixel (a third of the time).
    y, row_start, first_tile = 0, 0, 0
    for i in range(n):
        p = pixels[i]
        if p < row_start:
            y = p // width
            row_start = y * width
            first_tile = (y // tall) * tiles_x
        while p - row_start >= width:
            y += 1
            row_start += width
            first_tile = (y // tall) * tiles_x
        tile[i] = first_tile + (p - row_start) // TILE
        top = max(top, tile[i] + 1)
    counts = np.zeros(top + 1, np.int64)
    for i in range(n):
        counts[tile[i] + 1] += 1
    groups = 0
    for k in range(1, top + 1):
        groups += counts[k] > 0
        counts[k] += counts[k - 1]
    starts = np.empty(groups + 1, np.int64)
    g = 0
    for k in range(top):
        if counts[k + 1] > counts[k]:
            starts[g] = counts[k]
            g += 1
    starts[groups] = n
    order = np.empty(n, np.int64)
    for i in range(n):
        order[counts[tile[i]]] = i
        counts[tile[i]] += 1
    return order, starts


PLANE_BITS = 11  # plane_order: 2048 steps a side (2.4 cm over a 50 m garden), one radix pass an axis
PLANE_STEPS = 1 << PLANE_BITS


@njit(nogil=True, cache=True, inline="always")
def _spread_bits(x):
    """The low 16 bits of ``x`` moved to the even bit positions (a Morton code's half)."""
    x = (x | (x << 8)) & 0x00FF00FF
    x = (x | (x << 4)) & 0x0F0F0F0F
    x = (x | (x << 2)) & 0x33333333
    return (x | (x << 1)) & 0x55555555


@njit(nogil=True, cache=True)
def plane_order(origins, direction):
    """Indices of parallel rays (one ``direction``, as sun shadows) along a Z-order curve over the
    plane across that direction: rays whose lines lie close together come one after another,
    however far apart their starts lie along the direction, so each packet of consecutive rays
    crosses the same boxes of the BVH (docs/design.md, Ray tracing). The plane's extent is cut into
    ``PLANE_STEPS`` a side (finer cells gave no faster packets); the order is a stable radix sort of
    the codes, in two passes."""
    n = len(origins)
    dx, dy, dz = float(direction[0]), float(direction[1]), float(direction[2])
    # Two axes across the direction: crossed with the coordinate axis least along it.
    ax, ay, az = (
        (1.0, 0.0, 0.0)
        if abs(dx) <= min(abs(dy), abs(dz))
        else ((0.0, 1.0, 0.0) if abs(dy) <= abs(dz) else (0.0, 0.0, 1.0))
    )
    ux, uy, uz = dy * az - dz * ay, dz * ax - dx * az, dx * ay - dy * ax
    vx, vy, vz = dy * uz - dz * uy, dz * ux - dx * uz, dx * uy - dy * ux
    u = np.empty(n)
    v = np.empty(n)
    for i in range(n):
        x, y, z = float(origins[i, 0]), float(origins[i, 1]), float(origins[i, 2])
        u[i] = ux * x + uy * y + uz * z
        v[i] = vx * x + vy * y + vz * z
    order = np.arange(n)
    if n < 2:
        return order
    u0, v0 = u.min(), v.min()
    extent = max(u.max() - u0, v.max() - v0)
    scale = (PLANE_STEPS - 1) / extent if extent > 0.0 else 0.0
    code = np.empty(n, np.uint32)
    for i in range(n):
        code[i] = _spread_bits(np.uint32((u[i] - u0) * scale)) | (_spread_bits(np.uint32((v[i] - v0) * scale)) << 1)
    spare, spare_code = np.empty(n, np.int64), np.empty(n, np.uint32)
    counts = np.empty(PLANE_STEPS + 1, np.int64)
    for shift in (0, PLANE_BITS):  # the codes travel with the indices: every pass reads in order
        counts[:] = 0
        for i in range(n):
            counts[((code[i] >> shift) & (PLANE_STEPS - 1)) + 1] += 1
        for k in range(PLANE_STEPS):
            counts[k + 1] += counts[k]
        for i in range(n):
            key = (code[i] >> shift) & (PLANE_STEPS - 1)
            spare[counts[key]] = order[i]
            spare_code[counts[key]] = code[i]
            counts[key] += 1
        order, spare = spare, order
        code, spare_code = spare_code, code
    return order


@njit(nogil=True, cache=True)
def face_normals(vertices, faces):
    """(F, 3) float32 geometric normals (not unit), each face's as Embree's robust (Pluecker)
    intersector computes a hit's Ng (kernels/geometry/triangle_intersector_pluecker.h,
    ``stable_triangle_normal`` in common/math/vec3.h) for a ray from the origin: edges
    e0 = v2 - v0, e1 = v0 - v1, e2 = v1 - v2, each component of cross(e0, e1) or cross(e1, e2),
    whichever has the larger cancelling product, with fused multiply-subtracts."""
    out = np.empty((len(faces), 3), np.float32)
    for f in range(len(faces)):
        p, q, r = vertices[faces[f, 0]], vertices[faces[f, 1]], vertices[faces[f, 2]]
        ax, ay, az = r[0] - p[0], r[1] - p[1], r[2] - p[2]  # e0
        bx, by, bz = p[0] - q[0], p[1] - q[1], p[2] - q[2]  # e1
        cx, cy, cz = q[0] - r[0], q[1] - r[1], q[2] - r[2]  # e2
        ab_x, ab_y, ab_z = az * by, ax * bz, ay * bx
        bc_x, bc_y, bc_z = bz * cy, bx * cz, by * cx
        ab = abs(ab_x) < abs(bc_x)
        out[f, 0] = fused_multiply_subtract(ay, bz, ab_x) if ab else fused_multiply_subtract(by, cz, bc_x)
        ab = abs(ab_y) < abs(bc_y)
        out[f, 1] = fused_multiply_subtract(az, bx, ab_y) if ab else fused_multiply_subtract(bz, cx, bc_y)
        ab = abs(ab_z) < abs(bc_z)
        out[f, 2] = fused_multiply_subtract(ax, by, ab_z) if ab else fused_multiply_subtract(bx, cy, bc_z)
    return out
