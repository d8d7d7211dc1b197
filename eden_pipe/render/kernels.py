"""Compiled per-pixel kernels of the renderer (numba).

numpy spends most of a view's non-ray time on chains of small steps over (N, 3)
rows: each step writes a temporary, and a row of three is too short for numpy's
inner loops (docs/scale-out.md, Cost estimate: what made the renderer fast).
Each kernel here runs one such chain in a single pass over the pixels. They
compute the same IEEE operations, in the same order and precision, as the numpy
they replaced: numba compiles without fastmath, so LLVM contracts no
multiply-add into an FMA, and the results are bit-identical
(``tests/test_render_kernels.py`` holds the numpy versions and checks every
kernel against them). The glossy lobe, written as a kernel from the start, is
checked against its formulas in float64 instead (float32 rounding). Products
that numpy hands to BLAS (``(N, 3) @ (3, 3)``) stay in numpy: OpenBLAS sums them
with FMAs in a machine-dependent order.

Every kernel is ``nogil``, so frame threads run them at once, and serial: the
parallelism is the frame threads (``stages.render.worker_layout``). The first
call compiles, later processes load the machine code from numba's cache, which
is keyed by each kernel's own source file only: kernels that share helpers live
in this one module (the terrain textures' too), so an edit here recompiles them.
"""

from __future__ import annotations

import numpy as np
from numba import njit

kernel = njit(nogil=True, cache=True)  # no parallel=True: frame threads call these concurrently


# ------------------------------------------------------------------ numpy's comparisons
@njit(inline="always")
def _maximum(a, b):
    """np.maximum: NaN if either is, ``b`` where they are equal (so max(-0.0, 0.0) is 0.0)."""
    return a if (a > b or a != a) else b


@njit(inline="always")
def _minimum(a, b):
    """np.minimum: NaN if either is, ``b`` where they are equal."""
    return a if (a < b or a != a) else b


@njit(inline="always")
def _clip(x, low, high):
    """np.clip: ``x`` itself where it is NaN or equal to a bound (so clip(-0.0, 0.0, 1.0) is -0.0)."""
    return low if x < low else (high if x > high else x)


# ------------------------------------------------------------------ secondary-ray origins
@kernel
def _offset_origins(points, normals, dist, offset, rounding, cap, out):
    for i in range(points.shape[0]):
        # |p|_inf + min(dist, cap): numpy's max over the row, then the sum, in the rows' precision.
        scale = _maximum(_maximum(abs(points[i, 0]), abs(points[i, 1])), abs(points[i, 2])) + _minimum(dist[i], cap)
        step = offset + rounding * scale
        for j in range(3):
            out[i, j] = points[i, j] + normals[i, j] * step
    return out


def offset_origins(points, normals, dist, offset: float, rounding: float) -> np.ndarray:
    """``points + normals * (offset + rounding * (max|p| + min(dist, 1e6)))`` per row, in the
    precision numpy promotes the inputs to (``offsets.leave``; float32 constants)."""
    scale_type = np.result_type(points.dtype, dist.dtype)
    out = np.empty(points.shape, np.result_type(points.dtype, normals.dtype, scale_type))
    return _offset_origins(
        points, normals, dist.astype(scale_type, copy=False), np.float32(offset), np.float32(rounding),
        scale_type.type(1e6), out,
    )  # fmt: skip


# ------------------------------------------------------------------ sun
@kernel
def add_sun_fractions(weight, back_weight, index, cos, fraction):
    """``weight[index] += c * f`` where c > 0, ``back_weight[index] += -c * f`` where c < 0: one
    sun sample's weights (``fraction`` 1 where its ray saw the sun, else 0), or the soft sun's with
    the visible share ``fraction`` of its disc (``shading.direct_sun``; rows of ``index`` are
    distinct). ``fraction`` is float32, so a ray's 1 or 0 adds exactly ``c`` or nothing."""
    for k in range(index.shape[0]):
        c = cos[k] * fraction[k]
        if c > 0:
            weight[index[k]] += c
        elif c < 0:
            back_weight[index[k]] += -c


@kernel
def _sun_light(weight, back_weight, cloud, samples, sun, front, back):
    for i in range(weight.shape[0]):
        scale = np.float32(cloud[i] / samples)
        w = weight[i] * scale
        b = back_weight[i] * scale
        for j in range(3):
            front[i, j] = w * sun[j]
            back[i, j] = b * sun[j]
    return front, back


def sun_light(weight, back_weight, cloud, samples: float, sun) -> tuple[np.ndarray, np.ndarray]:
    """(front, back) (N, 3) float32: the sun's weights (N,) times ``cloud / samples`` (the
    transmittance over pi times the disc samples, in ``cloud``'s precision) times ``sun`` (3,)."""
    n = len(weight)
    front, back = np.empty((n, 3), np.float32), np.empty((n, 3), np.float32)
    return _sun_light(weight, back_weight, cloud, cloud.dtype.type(samples), sun, front, back)


# ------------------------------------------------------------------ flow
@kernel
def flow_relative(points, sky_dirs, hit, centre):
    """(N, 3) float64 what the other camera's rotation turns into its frame: hit points relative to
    its ``centre``, sky directions (misses) as they are."""
    out = np.empty(points.shape, np.float64)
    for i in range(points.shape[0]):
        for j in range(3):
            out[i, j] = points[i, j] - centre[j] if hit[i] else sky_dirs[i, j]
    return out


@kernel
def reproject(cam, fx, fy, cx, cy, width, height):
    """(flow (N, 2) float32, inside (N,) bool) of the row-major pixels of a ``width``-wide image
    whose points are ``cam`` (N, 3) in the other camera's frame (``Intrinsics.project``): zero flow
    where the point is behind that camera or the flow overflows float32."""
    n = cam.shape[0]
    flow = np.empty((n, 2), np.float32)
    inside = np.empty(n, np.bool_)
    right, bottom = width - 0.5, height - 0.5
    for i in range(n):
        z = cam[i, 2]
        safe = z if z > 1e-9 else np.nan
        u = fx * cam[i, 0] / safe + cx
        v = fy * cam[i, 1] / safe + cy
        du = np.float32(u - (i % width))
        dv = np.float32(v - (i // width))
        flow[i, 0] = du if np.isfinite(du) else np.float32(0.0)
        flow[i, 1] = dv if np.isfinite(dv) else np.float32(0.0)
        inside[i] = (z > 1e-9) and (u >= -0.5) and (u < right) and (v >= -0.5) and (v < bottom)
    return flow, inside


@kernel
def occlusion_rays(points, sky_dirs, hit, check, centre, nudge_scale, reach, far):
    """Float32 (origins, directions, tmax) of the occlusion rays of pixels ``check``: from a
    surface point, nudged toward the other camera, to that camera's ``centre`` (a segment); from
    the camera to infinity along a sky pixel's direction (``view.flow_to``)."""
    n = check.shape[0]
    origins = np.empty((n, 3), np.float32)
    dirs = np.empty((n, 3), np.float32)
    tmax = np.empty(n, np.float32)
    c = centre.astype(np.float32)
    for k in range(n):
        i = check[k]
        t0 = c[0] - np.float32(points[i, 0])
        t1 = c[1] - np.float32(points[i, 1])
        t2 = c[2] - np.float32(points[i, 2])
        dist = np.sqrt((t0 * t0 + t1 * t1) + t2 * t2)
        floor = _maximum(dist, np.float32(1e-12))
        nudge = nudge_scale * _maximum(np.float32(1.0), dist)
        if hit[i]:
            u0, u1, u2 = t0 / floor, t1 / floor, t2 / floor
            origins[k, 0] = np.float32(points[i, 0]) + u0 * nudge
            origins[k, 1] = np.float32(points[i, 1]) + u1 * nudge
            origins[k, 2] = np.float32(points[i, 2]) + u2 * nudge
            dirs[k, 0], dirs[k, 1], dirs[k, 2] = u0, u1, u2
            tmax[k] = dist * reach - nudge
        else:
            for j in range(3):
                origins[k, j] = c[j]
                dirs[k, j] = np.float32(sky_dirs[i, j])
            tmax[k] = far
    return origins, dirs, tmax


# ------------------------------------------------------------------ glossy
@njit(inline="always")
def _power(x, exponent):
    """x ** exponent for an integer exponent >= 1 by repeated squaring (six products for 60, where
    ``x ** 60`` is a general power)."""
    if exponent < 1:
        raise ValueError("the exponent must be a positive integer")
    result = x
    first = True
    base = x
    while exponent:
        if exponent & 1:
            if first:
                result, first = base, False
            else:
                result = result * base
        exponent >>= 1
        if exponent:
            base = base * base
    return result


@njit(inline="always")
def _beckmann_lambda(cos, alpha2):
    """Smith's Lambda of the Beckmann distribution for a direction at ``cos`` to the normal: the
    rational approximation of Walter et al. 2007, the one Cycles evaluates (0 where a >= 1.6)."""
    c2 = cos * cos
    s = alpha2 * _maximum((np.float32(1.0) - c2) / c2, np.float32(0.0))  # alpha^2 tan^2
    if s < np.float32(0.39):
        return np.float32(0.0)
    a = np.float32(1.0) / np.sqrt(s)
    return ((np.float32(0.396) * a - np.float32(1.259)) * a + np.float32(1.0)) / (
        (np.float32(2.181) * a + np.float32(3.535)) * a
    )


@kernel
def glossy_lobe(n, d, to_sun, front_sun, alpha2, g_dir, mirror, weight):
    """``shading.glossy_parts`` in one pass over float32 unit normals ``n`` and view directions
    ``d`` (N, 3): the sun's Beckmann microfacet lobe (squared roughness ``alpha2``) times ``front_sun``
    into ``g_dir``, the mirror direction into ``mirror``, the capped Schlick Fresnel ratio into
    ``weight`` (N,). ``front_sun`` is E cos(l) / pi, so the lobe is pi f / cos(l) with the BRDF
    f = D G / (4 cos(l) cos(v)): D Beckmann's, G Smith's height-correlated 1 / (1 + Lambda(v) + Lambda(l))."""
    one, zero = np.float32(1.0), np.float32(0.0)
    for i in range(n.shape[0]):
        h0, h1, h2 = to_sun[0] - d[i, 0], to_sun[1] - d[i, 1], to_sun[2] - d[i, 2]
        length = _maximum(np.sqrt((h0 * h0 + h1 * h1) + h2 * h2), np.float32(1e-30))
        h0, h1, h2 = h0 / length, h1 / length, h2 / length
        cos_h = (n[i, 0] * h0 + n[i, 1] * h1) + n[i, 2] * h2
        cos_l = (n[i, 0] * to_sun[0] + n[i, 1] * to_sun[1]) + n[i, 2] * to_sun[2]
        d_dot_n = (d[i, 0] * n[i, 0] + d[i, 1] * n[i, 1]) + d[i, 2] * n[i, 2]
        cos_v = -d_dot_n
        lobe = zero
        if cos_h > zero and cos_l > zero and cos_v > zero:
            c2 = cos_h * cos_h
            shadowing = one / ((one + _beckmann_lambda(cos_v, alpha2)) + _beckmann_lambda(cos_l, alpha2))
            lobe = (
                (np.exp((one - one / c2) / alpha2) / (alpha2 * (c2 * c2)))
                * shadowing
                / (np.float32(4.0) * cos_v * cos_l)
            )
        for j in range(3):
            g_dir[i, j] = front_sun[i, j] * lobe
        twice = np.float32(2.0) * d_dot_n
        for j in range(3):
            mirror[i, j] = d[i, j] - twice * n[i, j]
        grazing = one - _clip(cos_v, zero, one)
        fresnel = np.float32(0.04) + np.float32(0.96) * _power(grazing, 5)
        weight[i] = _minimum(fresnel / np.float32(0.04), np.float32(2.0))


# ------------------------------------------------------------------ primary hits
@kernel
def primary_hits(index, origins, directions, t, normal):
    """The hit rays ``index``' float32 unit view directions, hit points ``o + d t`` (d as given,
    in float32), geometric normals turned to face the viewer and whether they were turned (the
    viewer is behind the winding's normal) (``shading.primary_surface``)."""
    n = index.shape[0]
    d = np.empty((n, 3), np.float32)
    points = np.empty((n, 3), np.float32)
    facing = np.empty((n, 3), np.float32)
    behind = np.empty(n, np.bool_)
    for k in range(n):
        i = index[k]
        r0, r1, r2 = np.float32(directions[i, 0]), np.float32(directions[i, 1]), np.float32(directions[i, 2])
        length = _maximum(np.sqrt((r0 * r0 + r1 * r1) + r2 * r2), np.float32(1e-30))
        d0, d1, d2 = r0 / length, r1 / length, r2 / length
        d[k, 0], d[k, 1], d[k, 2] = d0, d1, d2
        points[k, 0] = np.float32(origins[i, 0]) + r0 * t[i]
        points[k, 1] = np.float32(origins[i, 1]) + r1 * t[i]
        points[k, 2] = np.float32(origins[i, 2]) + r2 * t[i]
        n0, n1, n2 = normal[i, 0], normal[i, 1], normal[i, 2]
        back = ((n0 * d0 + n1 * d1) + n2 * d2) > 0
        sign = np.float32(-1.0) if back else np.float32(1.0)
        facing[k, 0], facing[k, 1], facing[k, 2] = n0 * sign, n1 * sign, n2 * sign
        behind[k] = back
    return d, points, facing, behind


# ------------------------------------------------------------------ the image formation
COMPOSED_LAYERS = ("albedo", "shading", "glossy", "translucency")  # compose_layers' order of the surface layers


@kernel
def compose_layers(source, albedo, trans, back, spec, gloss, shading, background, layers):
    """``shading.compose`` in one pass: per ray (``source``: its hit row, or -1 on a miss) the
    composite ``albedo * shading + spec * gloss + albedo * trans * back + background``, and the
    surface layers asked for in ``layers`` (albedo, shading, glossy, translucency; zero on misses).
    Returns (linear (N, 3), (4, N, 3) layers, rows of those not asked for left empty)."""
    n = source.shape[0]
    linear = np.empty((n, 3), np.float32)
    out = np.empty((4, n if layers.any() else 0, 3), np.float32)
    for i in range(n):
        h = source[i]
        for j in range(3):
            if h < 0:
                a = s = g = tr = np.float32(0.0)
            else:
                a = albedo[h, j]
                s = shading[h, j]
                g = np.float32(spec[h] * gloss[h, j])  # (float64 terms: rounded once, as numpy's astype)
                tr = np.float32(a * trans[h] * back[h, j])
            linear[i, j] = ((a * s + g) + tr) + background[i, j]
            if layers[0]:
                out[0, i, j] = a
            if layers[1]:
                out[1, i, j] = s
            if layers[2]:
                out[2, i, j] = g
            if layers[3]:
                out[3, i, j] = tr
    return linear, out


# ------------------------------------------------------------------ rows
@kernel
def normalize_rows(a, floor):
    """(N, 3) rows over their length, at least ``floor`` (``vec.normalize``), in ``a``'s precision."""
    out = np.empty(a.shape, a.dtype)
    for i in range(a.shape[0]):
        x, y, z = a[i, 0], a[i, 1], a[i, 2]
        length = _maximum(np.sqrt((x * x + y * y) + z * z), floor)
        out[i, 0], out[i, 1], out[i, 2] = x / length, y / length, z / length
    return out


@kernel
def unit_rows(a):
    """Float32 (N, 3) rows times the reciprocal of their length, at least 1e-30
    (``embree.unit_normals``: Embree's geometric normals), as numpy scales them."""
    out = np.empty(a.shape, np.float32)
    for i in range(a.shape[0]):
        x, y, z = a[i, 0], a[i, 1], a[i, 2]
        scale = np.float32(1.0) / _maximum(np.sqrt((x * x + y * y) + z * z), np.float32(1e-30))
        out[i, 0], out[i, 1], out[i, 2] = x * scale, y * scale, z * scale
    return out


@njit(inline="always")
def _row(j, n):
    """np.take's index rule: a negative ``j`` counts from the end of ``n`` rows; outside them, IndexError."""
    if j < 0:
        j += n
    if j < 0 or j >= n:
        raise IndexError("index out of range for the gathered rows")
    return j


@kernel
def take_rows3(a, index):
    """``np.take(a, index, axis=0)`` for (P, 3) rows: one copy a row, where numpy's take copies
    rows of 12 bytes through its generic chunk loop (about half the time on the render's (N, 3)
    gathers). Negative indices count from the end; any other outside ``a`` raises IndexError."""
    out = np.empty((index.shape[0], 3), a.dtype)
    for i in range(index.shape[0]):
        j = _row(index[i], a.shape[0])
        out[i, 0], out[i, 1], out[i, 2] = a[j, 0], a[j, 1], a[j, 2]
    return out


@kernel
def take_items(a, index):
    """``np.take(a, index)`` for 1-D ``a``, with numpy's index rules as :func:`take_rows3`."""
    out = np.empty(index.shape[0], a.dtype)
    for i in range(index.shape[0]):
        out[i] = a[_row(index[i], a.shape[0])]
    return out


@kernel
def blocked_radiance(bounce, visible, index, floor):
    """``SkyVisibility.blocked_radiance`` of rows ``index``: ``bounce`` (P, 3) float32 over the
    larger of ``floor`` and one less ``visible`` (P,) clipped to [0, 1], as numpy divides them."""
    out = np.empty((index.shape[0], 3), np.float32)
    one, zero = np.float32(1.0), np.float32(0.0)
    for k in range(index.shape[0]):
        i = _row(index[k], min(visible.shape[0], bounce.shape[0]))
        blocked = _maximum(one - _clip(visible[i], zero, one), floor)
        out[k, 0], out[k, 1], out[k, 2] = bounce[i, 0] / blocked, bounce[i, 1] / blocked, bounce[i, 2] / blocked
    return out


@kernel
def hit_points(origins, directions, t, hit):
    """``origins + directions * where(hit, t, 0)`` (N, 3) in the rays' float64, ``t`` (N,) float32."""
    out = np.empty(origins.shape, np.float64)
    for i in range(origins.shape[0]):
        along = np.float64(t[i] if hit[i] else np.float32(0.0))
        for j in range(3):
            out[i, j] = origins[i, j] + directions[i, j] * along
    return out


@kernel
def take_light_rows(tables, visible, index):
    """Rows ``index`` of a frame light's (P, 3) ``tables`` and its (P,) ``visible`` in one pass
    (``ProbeLight.take``): ((len(tables), N, 3), (N,)), the copies :func:`take_rows3` makes term
    by term, the slot read once a row."""
    n, count = index.shape[0], len(tables)
    out = np.empty((count, n, 3), np.float32)
    seen = np.empty(n, np.float32)
    for k in range(n):
        i = _row(index[k], visible.shape[0])
        seen[k] = visible[i]
        for t in range(count):
            table = tables[t]
            out[t, k, 0], out[t, k, 1], out[t, k, 2] = table[i, 0], table[i, 1], table[i, 2]
    return out, seen


# ------------------------------------------------------------------ the bake's light
@kernel
def lightmap_visible(slot, back, points, origin, axis_a, axis_b, steps_a, steps_b, across, first, visible):
    """The visible sky at ``points`` on lightmapped face sides (``Lightmaps.visible_at``): the
    bilinear blend of the four nodes around each point, in float32."""
    n = slot.shape[0]
    out = np.empty(n, np.float32)
    for k in range(n):
        s = slot[k]
        q0 = np.float32(points[k, 0]) - origin[s, 0]
        q1 = np.float32(points[k, 1]) - origin[s, 1]
        q2 = np.float32(points[k, 2]) - origin[s, 2]
        u = _clip((axis_a[s, 0] * q0 + axis_a[s, 1] * q1) + axis_a[s, 2] * q2, np.float32(0.0), steps_a[s])
        v = _clip((axis_b[s, 0] * q0 + axis_b[s, 1] * q1) + axis_b[s, 2] * q2, np.float32(0.0), steps_b[s])
        i = np.int32(_minimum(u, steps_a[s] - np.float32(1.0)))
        j = np.int32(_minimum(v, steps_b[s] - np.float32(1.0)))
        u = np.float32(np.float64(u) - i)  # numpy's float32 - int32: in float64, stored as float32
        v = np.float32(np.float64(v) - j)
        node = (first[s] + j * across[s] + i) * 2 + back[k]  # in the (N, 2) table's flat index
        row = 2 * across[s]
        one = np.float32(1.0)
        light = visible[node] * ((one - u) * (one - v))
        light += visible[node + 2] * (u * (one - v))
        light += visible[node + row] * ((one - u) * v)
        light += visible[node + row + 2] * (u * v)
        out[k] = light
    return out


@kernel
def bounce_light(bounce_sky, bounce_sun, cloud):
    """(N, 3) float32 the bounce of sky light and of sun light times ``cloud`` (N,) (None: no sun),
    at least zero (``SkyVisibility.bounce_light``; float32 terms)."""
    n = bounce_sky.shape[0]
    out = np.empty((n, 3), np.float32)
    for i in range(n):
        for j in range(3):
            b = bounce_sky[i, j] if cloud is None else bounce_sun[i, j] * cloud[i] + bounce_sky[i, j]
            out[i, j] = _maximum(b, np.float32(0.0))
    return out


@kernel
def indirect_light(sky, visible, exposure, ambient, bounce):
    """(N, 3) float32 Dind (``SkyVisibility.irradiance``; float32 terms): the probe's sky term plus
    the open sky at the pixel's normal (``ambient``) times the probe's visible fraction, times the
    side's exposure, at least zero, plus the ``bounce``."""
    n = visible.shape[0]
    out = np.empty((n, 3), np.float32)
    for i in range(n):
        for j in range(3):
            light = (ambient[i, j] * visible[i] + sky[i, j]) * exposure[i]
            out[i, j] = _maximum(light, np.float32(0.0)) + bounce[i, j]
    return out


# ------------------------------------------------------------------ terrain textures (render.textures)
@njit(inline="always")
def _hash2(ix, iy, salt):
    """A deterministic uniform number in [0, 1) from integer cell coordinates."""
    h = (ix * 374761393 + iy * 668265263 + salt * 2147483647) & 0xFFFFFFFF
    h = ((h ^ (h >> 13)) * 1274126177) & 0xFFFFFFFF
    h = h ^ (h >> 16)
    return np.float64(h & 0xFFFFFF) / float(1 << 24)


@njit(inline="always")
def _value(x, y, scale, salt):
    """Smooth value noise (bilinear over hashed lattice) in [0, 1) at float32 ``x``, ``y``."""
    gx, gy = x / np.float32(scale), y / np.float32(scale)
    ix, iy = np.int64(np.floor(gx)), np.int64(np.floor(gy))
    fx, fy = np.float64(gx) - ix, np.float64(gy) - iy
    fx, fy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)
    a, b = _hash2(ix, iy, salt), _hash2(ix + 1, iy, salt)
    c, d = _hash2(ix, iy + 1, salt), _hash2(ix + 1, iy + 1, salt)
    return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy


@njit(inline="always")
def _bump(normal, k, sx, sy):
    """The unit normal of row ``k`` of ``normal`` tilted by the slope (``sx``, ``sy``), in place."""
    n0 = np.float32(normal[k, 0] - sx)
    n1 = np.float32(normal[k, 1] - sy)
    n2 = normal[k, 2]
    length = _maximum(np.sqrt((n0 * n0 + n1 * n1) + n2 * n2), np.float32(1e-30))
    normal[k, 0], normal[k, 1], normal[k, 2] = n0 / length, n1 / length, n2 / length


@njit(inline="always")
def _stone(k, x, y, normal, albedo, cell, palette, salt, gap_dark, dome, roundness):
    """Stones around Worley feature points: per-stone colour and tone, dark gaps, domed normals.
    ``roundness`` > 0 makes stones round (radius ``roundness`` cells, varying per stone) with
    soil between them, as loose pebbles; 0 packs them edge to edge, as gravel."""
    gx, gy = x / np.float32(cell), y / np.float32(cell)
    cx, cy = np.int64(np.floor(gx)), np.int64(np.floor(gy))
    f1 = f2 = np.inf
    bx = by = 0
    off_x = off_y = 0.0
    for dx in (-1, 0, 1):  # the nearest and second nearest feature points of the 3 x 3 cells
        for dy in (-1, 0, 1):
            nx, ny = cx + dx, cy + dy
            ddx = np.float64(gx) - (nx + _hash2(nx, ny, salt))
            ddy = np.float64(gy) - (ny + _hash2(nx, ny, salt + 1))
            d = np.sqrt(ddx * ddx + ddy * ddy)
            if d < f1:
                f2, f1, bx, by, off_x, off_y = f1, d, nx, ny, ddx, ddy
            else:
                f2 = _minimum(f2, d)
    count = palette.shape[0]
    pick = min(np.int64(_hash2(bx, by, salt + 7) * count), count - 1)
    shade = 0.75 + 0.5 * _hash2(bx, by, salt + 9)
    edge = _clip((f2 - f1) / 0.12, 0.0, 1.0)  # 0 in the gaps between stones
    if roundness > 0:
        radius = roundness * (0.8 + 0.4 * _hash2(bx, by, salt + 5))
        edge = _minimum(edge, _clip((radius - f1) / 0.06, 0.0, 1.0))
        reach = _maximum(radius, 1e-6)
        slope_x, slope_y = dome * off_x / reach * edge, dome * off_y / reach * edge
    else:
        slope_x, slope_y = dome * off_x * edge, dome * off_y * edge  # the normal tilts away from the stone centre
    tone = (gap_dark + (1.0 - gap_dark) * edge) * shade
    # Keep the patch's tint (albedo relative to its mean) and take the stone's colour and tone.
    mean = _maximum((albedo[k, 0] + albedo[k, 1] + albedo[k, 2]) / np.float32(3), np.float32(1e-6))
    for j in range(3):
        albedo[k, j] = albedo[k, j] / mean * palette[pick, j] * tone
    _bump(normal, k, -slope_x, -slope_y)


@njit(inline="always")
def _paving(k, x, y, normal, albedo):
    """Running-bond tiles (every other row shifted by half a tile) with dark, bevelled joints."""
    tile = np.float32(0.5)
    row = np.floor(y / tile)
    x_shift = x + np.float32(0.5 * 0.5) * (row % np.float32(2))
    col = np.floor(x_shift / tile)
    ux, uy = x_shift / tile - col, y / tile - row
    across_x, across_y = _minimum(ux, np.float32(1.0) - ux), _minimum(uy, np.float32(1.0) - uy)
    joint = _minimum(across_x, across_y) * tile
    if joint < np.float32(0.006):
        factor = 0.45
    else:
        factor = (0.88 + 0.24 * _hash2(np.int64(col), np.int64(row), 31)) * (0.9 + 0.2 * _value(x, y, 0.03, 37))
    for j in range(3):
        albedo[k, j] = albedo[k, j] * factor
    bevel = _clip(np.float32(1.0) - joint / np.float32(0.012), np.float32(0.0), np.float32(1.0))
    gx = (1.0 if ux < np.float32(0.5) else -1.0) * (across_x < across_y)
    gy = (1.0 if uy < np.float32(0.5) else -1.0) * (across_y <= across_x)
    lean = np.float32(-0.5) * bevel
    _bump(normal, k, lean * gx, lean * gy)


@njit(inline="always")
def _soil(k, x, y, normal, albedo, scale, amp):
    """Dirt and the soil under the lawn: two octaves of value noise and clumps, gently bumped."""
    v = 0.6 * _value(x, y, scale, 41) + 0.4 * _value(x, y, scale / 4.0, 43)
    clumps = _value(x, y, 0.012, 47)
    factor = (1.0 - amp + 2.0 * amp * v) * (0.85 + 0.3 * clumps)
    for j in range(3):
        albedo[k, j] = albedo[k, j] * factor
    eps = scale / 4.0
    step = np.float32(eps)
    gx = (_value(x + step, y, scale / 4.0, 43) - _value(x - step, y, scale / 4.0, 43)) / (2 * eps)
    gy = (_value(x, y + step, scale / 4.0, 43) - _value(x, y - step, scale / 4.0, 43)) / (2 * eps)
    _bump(normal, k, 0.01 * gx, 0.01 * gy)


@kernel
def terrain_textures(material, points, albedo, normal, codes, pebbles, gravel, soils):
    """``textures.apply_terrain_textures`` in place on float32 ``albedo`` and ``normal`` (N, 3): each hit's
    pattern by its material (``codes``: pebbles, gravel, pavement; ``soils``: (code, scale, amplitude)),
    every albedo clipped to [0, 1]."""
    for k in range(material.shape[0]):
        m = material[k]
        x, y = points[k, 0], points[k, 1]
        if m == codes[0]:
            _stone(k, x, y, normal, albedo, pebbles[0], pebbles[1], pebbles[2], pebbles[3], pebbles[4], pebbles[5])
        elif m == codes[1]:
            _stone(k, x, y, normal, albedo, gravel[0], gravel[1], gravel[2], gravel[3], gravel[4], gravel[5])
        elif m == codes[2]:
            _paving(k, x, y, normal, albedo)
        else:
            for code, scale, amp in soils:
                if m == code:
                    _soil(k, x, y, normal, albedo, scale, amp)
        for j in range(3):
            albedo[k, j] = _clip(albedo[k, j], np.float32(0.0), np.float32(1.0))
