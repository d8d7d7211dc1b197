"""Each pixel's own visible sky, from a few rays and its face's neighbours (``render.pixel_sky_rays``).

The bake gives every point of a probe (a 10 x 10 x 3 cm cell) its probe's visible sky, scaled by
its face side's exposure. Inside a hedge or a topiary the sky a point sees changes from leaf to leaf
and within a leaf, and that is most of the plants' per-pixel error (docs/realism.md, Where the
plants' error comes from): no per-face or per-vertex table holds it.

Here each pixel lit through a probe traces ``k`` cosine-weighted any-hit rays over its viewer side,
the directions stratified over each 4 x 4 block of pixels, and pools them with the rays of the
pixels within ``render.pixel_sky_radius`` that see the same face (a leaf's edge is where its sky
changes most; pooling across faces blurred it: docs/realism.md, Each pixel's own sky). The pooled
rays' escaping fraction over the bake's fraction at the same pixels (a ratio of sums, so the bake's
own variation from pixel to pixel is kept), with the bake itself counted as ``PRIOR_RAYS`` rays of
the pixel's own, scales the pixel's exposure: where few pixels share a face, a few rays alone
would be noisier than the bake. Pixels whose face has a lightmap or lies on the ground map keep
their exposure: those already carry their point's sky.

The factor is the sky of a point of a face side, not of a view: the right camera of a pair takes
the left camera's factor (:class:`SkyShare`) where its hit point projects to a left pixel that saw
the same face side, and traces its own rays only elsewhere (docs/realism.md, Each pixel's own sky).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from eden_pipe.camera.rig import Intrinsics
from eden_pipe.render import vec
from eden_pipe.render.offsets import leave
from eden_pipe.render.vec import orthonormal_basis

kernel = njit(nogil=True, cache=True)  # serial, nogil: frame threads call it concurrently

BLOCK = 4  # directions are stratified over BLOCK x BLOCK pixels: BLOCK**2 strata of the hemisphere
PRIOR_RAYS = 12.0  # the bake's fraction counts as this many of the pixel's own rays
MIN_POOLED = 1e-6  # below this pooled bake fraction the window says nothing: exposure kept


@kernel
def _cosine_directions(normals, pixels, width, k, jitter, out):
    """Per hit i and ray j: a cosine-weighted direction about ``normals[i]`` in the stratum of the
    hemisphere its pixel's place in a BLOCK x BLOCK block and ``j`` give, jittered within it."""
    strata = BLOCK * BLOCK
    for i in range(normals.shape[0]):
        x = pixels[i] % width
        y = pixels[i] // width
        base = (x % BLOCK) + BLOCK * (y % BLOCK)
        nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
        # An orthonormal frame about n (Duff et al. 2017, "Building an orthonormal basis, revisited").
        sign = 1.0 if nz >= 0.0 else -1.0
        a = -1.0 / (sign + nz)
        b = nx * ny * a
        t0, t1, t2 = 1.0 + sign * nx * nx * a, sign * b, -sign * nx
        b0, b1, b2 = b, sign + ny * ny * a, -ny
        for j in range(k):
            s = (base * 7 + j * strata // k) % strata  # 7 is coprime to 16: neighbours' strata spread
            u1 = ((s % BLOCK) + jitter[i, j, 0]) / BLOCK
            u2 = ((s // BLOCK) + jitter[i, j, 1]) / BLOCK
            r = np.sqrt(u1)
            phi = 2.0 * np.pi * u2
            lx, ly, lz = r * np.cos(phi), r * np.sin(phi), np.sqrt(max(0.0, 1.0 - u1))
            row = i * k + j
            out[row, 0] = lx * t0 + ly * b0 + lz * nx
            out[row, 1] = lx * t1 + ly * b1 + lz * ny
            out[row, 2] = lx * t2 + ly * b2 + lz * nz
    return out


@kernel
def _pooled_ratio(slot, width, height, pixels, seen, bake, face, radius, prior, out):
    """Per hit i: (its window's escaping fraction + prior * bake[i]) over (its window's bake fraction
    + prior * bake[i]), the window being the pixels within ``radius`` that see ``face[i]``; 1 where
    that bake sum is under MIN_POOLED. ``slot`` (height * width,): each pixel's hit row, -1 where it
    has none or is not estimated."""
    for i in range(pixels.shape[0]):
        x0 = pixels[i] % width
        y0 = pixels[i] // width
        sum_seen = prior * bake[i]
        sum_bake = prior * bake[i]
        for y in range(max(0, y0 - radius), min(height, y0 + radius + 1)):
            for x in range(max(0, x0 - radius), min(width, x0 + radius + 1)):
                q = slot[y * width + x]
                if q >= 0 and face[q] == face[i]:
                    sum_seen += seen[q]
                    sum_bake += bake[q]
        out[i] = sum_seen / sum_bake if sum_bake >= MIN_POOLED else 1.0
    return out


def pixel_exposure_scale(
    tracer,
    pixels: np.ndarray,
    image: tuple[int, int],
    points: np.ndarray,
    normals: np.ndarray,
    faces: np.ndarray,
    bake_visible: np.ndarray,
    rays: int,
    radius: int,
    rng: np.random.Generator,
    known: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """(N,) float32 factors for the exposure of N hits of an image: each pixel's pooled traced
    cosine-weighted visible sky over the bake's (``bake_visible`` (N,): the bake's cosine-weighted
    visible fraction there). ``pixels`` (N,): their row-major pixels in an ``image`` (height, width);
    ``points``, ``normals`` (N, 3): their hit points and viewer-side geometric normals; ``faces``
    (N,): their face ids; ``rays`` a pixel, pooled over ``radius`` pixels around it. ``known``:
    other pixels of the image whose visible sky is known without rays (their pixels, faces, visible
    fractions and the bake's there), pooled as a pixel's own rays are."""
    n = len(pixels)
    if n == 0 or rays <= 0:
        return np.ones(n, np.float32)
    width = image[1]
    pixels = pixels.astype(np.int64)
    normals64 = np.ascontiguousarray(normals, np.float64)
    jitter = rng.random((n, rays, 2))
    dirs = _cosine_directions(normals64, pixels, width, rays, jitter, np.empty((n * rays, 3)))
    origins = leave(
        np.repeat(np.asarray(points, np.float32), rays, axis=0),
        np.repeat(np.asarray(normals, np.float32), rays, axis=0),
        np.zeros(n * rays, np.float32),
    )
    blocked = tracer.occluded(origins, dirs.astype(np.float32)).reshape(n, rays)
    seen = (rays - blocked.sum(axis=1)) / np.float64(rays)
    return pooled_scale(pixels, image, faces, seen, bake_visible, radius, PRIOR_RAYS / rays, known)


def pooled_scale(
    pixels: np.ndarray,
    image: tuple[int, int],
    faces: np.ndarray,
    seen: np.ndarray,
    bake_visible: np.ndarray,
    radius: int,
    prior: float,
    known: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """(N,) float32 exposure factors of N hits of an ``image`` (their row-major ``pixels``, ``faces``):
    their estimated visible sky ``seen`` pooled over the pixels within ``radius`` on the same face,
    over the bake's (``bake_visible``) pooled alike, the bake counted ``prior`` times at the pixel
    itself; ``known`` as :func:`pixel_exposure_scale`."""
    n = len(pixels)
    height, width = image
    pixels = pixels.astype(np.int64)
    seen = np.asarray(seen, np.float64)
    bake = np.asarray(bake_visible, np.float64)
    faces = faces.astype(np.int64)
    pooled = pixels
    if known is not None and len(known[0]):
        # The estimated hits first (the kernel's rows 0..n-1), then the known ones, in one window map.
        pooled = np.concatenate([pixels, known[0].astype(np.int64)])
        faces = np.concatenate([faces, known[1].astype(np.int64)])
        seen = np.concatenate([seen, np.asarray(known[2], np.float64)])
        bake = np.concatenate([bake, np.asarray(known[3], np.float64)])
    slot = np.full(height * width, -1, np.int64)
    slot[pooled] = np.arange(len(pooled))
    ratio = _pooled_ratio(slot, width, height, pixels, seen, bake, faces, radius, prior, np.empty(n))
    return ratio.astype(np.float32)


SUN_BLOCK = 4  # the sun's disc in SUN_BLOCK**2 strata, one for each pixel of a SUN_BLOCK x SUN_BLOCK block
DISC_CENTRE = SUN_BLOCK * SUN_BLOCK  # sun_disc_rays' index for the ray to the disc's centre, after the strata


def sun_disc_directions(axis: np.ndarray, angular_radius: float) -> np.ndarray:
    """(SUN_BLOCK**2, 3) float64 unit directions toward the sun's disc (centre ``axis``, radius
    ``angular_radius`` radians), the centres of SUN_BLOCK**2 strata of equal area (SUN_BLOCK rings
    by SUN_BLOCK sectors, each ring turned by half a sector from the last): stratum ``ring *
    SUN_BLOCK + sector``. Fixed, not drawn: a view renders the same every time, and the pooled
    window, not a jitter, averages the disc."""
    axis = np.asarray(axis, np.float64)
    t, b = (v[0] for v in orthonormal_basis(axis[None]))
    k = np.arange(SUN_BLOCK * SUN_BLOCK)
    ring, sector = k // SUN_BLOCK, k % SUN_BLOCK
    r = np.tan(angular_radius) * np.sqrt((ring + 0.5) / SUN_BLOCK)
    phi = 2.0 * np.pi * (sector + 0.5 * (ring % 2) + 0.25) / SUN_BLOCK
    d = axis[None] + t[None] * (r * np.cos(phi))[:, None] + b[None] * (r * np.sin(phi))[:, None]
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def sun_disc_stratum(pixels: np.ndarray, width: int) -> np.ndarray:
    """(N,) int64: the disc stratum (:func:`sun_disc_directions`) whose shadow ray the row-major
    ``pixels`` of a ``width``-wide image trace: every stratum once in each SUN_BLOCK x SUN_BLOCK
    block, neighbours in strata far apart on the disc (7 is coprime to 16)."""
    pixels = np.asarray(pixels, np.int64)
    x, y = pixels % width, pixels // width
    return ((x % SUN_BLOCK) + SUN_BLOCK * (y % SUN_BLOCK)) * 7 % (SUN_BLOCK * SUN_BLOCK)


@kernel
def _alone(width, height, pixels, keys, key_at, radius, out):
    """Per pixel i: whether no other pixel within ``radius`` holds its key (``key_at``: each
    pixel's key, -1 where no hit); the scan stops at the first other one."""
    for i in range(pixels.shape[0]):
        x0 = pixels[i] % width
        y0 = pixels[i] // width
        alone = True
        for y in range(max(0, y0 - radius), min(height, y0 + radius + 1)):
            row = y * width
            for x in range(max(0, x0 - radius), min(width, x0 + radius + 1)):
                if key_at[row + x] == keys[i] and (x != x0 or y != y0):
                    alone = False
                    break
            if not alone:
                break
        out[i] = alone
    return out


def sun_disc_rays(pixels: np.ndarray, image: tuple[int, int], keys: np.ndarray, radius: int) -> np.ndarray:
    """(N,) int64: the disc stratum (:func:`sun_disc_directions`) each of the row-major ``pixels``
    traces (:func:`sun_disc_stratum`), or DISC_CENTRE for the disc's centre where no other pixel within
    ``radius`` holds its key (face side): no window averages its ray, and alone the centre's
    answer is the best one ray gives (1 exactly where more than half the disc shows across a
    straight edge), where a stratum's is right only on average."""
    height, width = image
    pixels, keys = np.asarray(pixels, np.int64), np.asarray(keys, np.int64)
    key_at = _per_pixel(pixels, image, keys, -1)
    alone = _alone(width, height, pixels, keys, key_at, int(radius), np.empty(len(pixels), np.bool_))
    return np.where(alone, DISC_CENTRE, sun_disc_stratum(pixels, width))


@kernel
def _mixed_windows(width, height, pixels, keys, seen, code_at, radius, mixed, far_at):
    """Per hit i: whether the pixels of its key within ``radius`` hold rays of both answers
    (``mixed``); where they do, each of their blocked pixels is marked in ``far_at`` (per pixel).
    ``code_at``: each pixel's key * 2 + answer (1 where its ray saw the sun), -1 where no hit. A
    window holds both answers where it holds a pixel of the hit's key with the other answer (the
    hit itself holds its own): one comparison a pixel, without a branch, twice as fast as
    counting each answer."""
    for i in range(pixels.shape[0]):
        x0 = pixels[i] % width
        y0 = pixels[i] // width
        other = keys[i] * 2 + (0 if seen[i] else 1)
        x_lo, x_hi = max(0, x0 - radius), min(width, x0 + radius + 1)
        y_lo, y_hi = max(0, y0 - radius), min(height, y0 + radius + 1)
        found = False
        for y in range(y_lo, y_hi):
            row = y * width
            for x in range(x_lo, x_hi):
                found |= code_at[row + x] == other
        if not found:
            continue
        mixed[i] = True
        blocked = keys[i] * 2
        for y in range(y_lo, y_hi):
            row = y * width
            for x in range(x_lo, x_hi):
                if code_at[row + x] == blocked:
                    far_at[row + x] = True
    return mixed


@kernel
def _penumbra_mean(width, height, pixels, seen, mixed, keys, code_at, blocker_at, footprint, spread, radius, out):
    """Per hit i: the mean of ``seen`` over the pixels of its key within its penumbra's half-width
    (the mean distance to the blockers that its window's blocked rays met, times ``spread``, over
    its ``footprint``, in pixels, at most ``radius``): percentage-closer soft shadows (Fernando
    2005), the window's rays standing for the disc's samples. A window whose rays all agree
    (not ``mixed``) gives its own ray's answer, whatever the reach; a mixed one whose penumbra is
    under a pixel gives NaN: the disc's centre answers there (``Penumbrae.fraction``)."""
    for i in range(pixels.shape[0]):
        if not mixed[i]:
            out[i] = 1.0 if seen[i] else 0.0
            continue
        x0 = pixels[i] % width
        y0 = pixels[i] // width
        sum_t = 0.0
        blocked = 0
        code_blocked = keys[i] * 2
        for y in range(max(0, y0 - radius), min(height, y0 + radius + 1)):
            row = y * width
            for x in range(max(0, x0 - radius), min(width, x0 + radius + 1)):
                if code_at[row + x] == code_blocked:
                    sum_t += blocker_at[row + x]
                    blocked += 1
        reach = min(radius, int(sum_t / blocked * spread / footprint[i] + 0.5))
        if reach == 0:  # a penumbra under a pixel: the disc's centre decides (the caller's ray)
            out[i] = np.nan
            continue
        total = 0.0
        count = 0
        for y in range(max(0, y0 - reach), min(height, y0 + reach + 1)):
            row = y * width
            for x in range(max(0, x0 - reach), min(width, x0 + reach + 1)):
                code = code_at[row + x]
                if code >= 0 and code >> 1 == keys[i]:
                    total += code & 1
                    count += 1
        out[i] = total / count
    return out


def _per_pixel(pixels: np.ndarray, image: tuple[int, int], values: np.ndarray, empty) -> np.ndarray:
    """(H * W,) ``values`` at their ``pixels``, ``empty`` elsewhere."""
    out = np.full(image[0] * image[1], empty, np.asarray(values).dtype)
    out[pixels] = values
    return out


@dataclass
class Penumbrae:
    """The soft sun's rays of one view (N hits' ``pixels``, row-major in an image of ``image`` (h, w)
    pixels, their face sides ``keys`` and whether each ray saw the sun, ``seen``) and which hits'
    windows of ``radius`` pixels hold rays of both answers (``mixed``): only those read the blockers'
    distances, and only of the blocked rays in their windows (``far``): everywhere else an
    occlusion ray's answer is enough (docs/realism.md, The sun's penumbra)."""

    pixels: np.ndarray
    image: tuple[int, int]
    keys: np.ndarray
    seen: np.ndarray
    radius: int
    mixed: np.ndarray
    far: np.ndarray
    code_at: np.ndarray  # (H * W,) each pixel's key * 2 + answer, -1 where no hit

    @classmethod
    def of(cls, pixels, image: tuple[int, int], keys, seen, radius: int) -> Penumbrae:
        height, width = image
        pixels, keys = np.asarray(pixels, np.int64), np.asarray(keys, np.int64)
        seen = np.asarray(seen, np.bool_)
        code_at = _per_pixel(pixels, image, keys * 2 + seen, -1)
        mixed, far_at = np.zeros(len(pixels), np.bool_), np.zeros(height * width, np.bool_)
        _mixed_windows(width, height, pixels, keys, seen, code_at, int(radius), mixed, far_at)
        far = np.flatnonzero(vec.take(far_at, pixels))
        return cls(pixels, (height, width), keys, seen, int(radius), mixed, far, code_at)

    def fraction(self, blocker: np.ndarray, footprint: np.ndarray, spread: float) -> np.ndarray:
        """(N,) float32: the share of the sun's disc each hit sees: the mean of the rays of the
        pixels on its face side within its penumbra's half-width, in pixels: the blockers' mean
        distance (``blocker`` (N,), read at ``far``) times ``spread`` (the tangent of the disc's
        angular radius) over the hit's ``footprint`` (metres a pixel spans there), at most
        ``radius``. Where the blockers are far (a canopy metres up under a wide sun) the window's
        rays average. Where they are near (a blade over the lawn, a leaf on a leaf) the penumbra is
        under a pixel and the share is NaN: the caller traces the ray to the disc's centre there,
        the hard shadow's answer, which is 1 exactly where the point sees more than half the disc
        across a straight edge, so its error is the least one ray can give; a stratum's ray is
        right on average but wrong more often (docs/realism.md, The sun's penumbra)."""
        height, width = self.image
        blocker_at = _per_pixel(self.pixels, self.image, np.asarray(blocker, np.float64), 0.0)
        out = np.empty(len(self.pixels))
        return _penumbra_mean(
            width, height, self.pixels, self.seen, self.mixed, self.keys, self.code_at, blocker_at,
            np.asarray(footprint, np.float64), float(spread), self.radius, out,
        ).astype(np.float32)  # fmt: skip


def map_phase(pixels: np.ndarray, width: int, subsets: int) -> np.ndarray:
    """(N,) int32: which of ``subsets`` (a power of two) subsets of the depth maps' directions each
    pixel reads (``ShadowMaps.visible_fraction``): its place in a block of ``subsets`` pixels (2 x 2
    for four), so that a window around any pixel holds every subset."""
    across = 1 << ((int(subsets).bit_length()) // 2)  # 1, 2, 2, 4, 4 for 1, 2, 4, 8, 16
    down = max(1, int(subsets) // across)
    x, y = pixels % width, pixels // width
    return ((x % across) + across * (y % down)).astype(np.int32)


@dataclass
class SkyShare:
    """A view's own-sky factors (or the soft sun's shares), for the other camera of its pair: the
    view's camera-to-world ``pose`` (4, 4), its intrinsics ``intr``, and per pixel (row-major) the
    face side its factor belongs to (``face * 2 + side``, -1 where it has none) and the factor."""

    pose: np.ndarray
    intr: Intrinsics
    side: np.ndarray  # (H * W,) int64
    factor: np.ndarray  # (H * W,) float32

    @classmethod
    def of(cls, pose, intr: Intrinsics, pixels: np.ndarray, sides: np.ndarray, factor: np.ndarray) -> SkyShare:
        """The share of a view whose hits ``pixels`` (N,), on face sides ``sides`` (N,), got ``factor``."""
        side = np.full(intr.height * intr.width, -1, np.int64)
        side[pixels] = sides
        out = np.ones(intr.height * intr.width, np.float32)
        out[pixels] = factor
        return cls(np.asarray(pose, np.float64), intr, side, out)

    def lookup(self, points: np.ndarray, sides: np.ndarray) -> np.ndarray:
        """(N,) float32: for each world point (N, 3) on face side ``sides`` (N,), the factor of the
        pixel whose centre lies nearest where the point projects in this view, where that pixel's
        factor belongs to the same face side; NaN elsewhere (outside the image, behind the camera,
        another face or side there, or no factor)."""
        intr = self.intr
        rot, centre = self.pose[:3, :3], self.pose[:3, 3]
        cam = (np.asarray(points, np.float64) - centre) @ rot  # BLAS's product, as Intrinsics.project's callers
        intrinsics = (float(intr.fx), float(intr.fy), float(intr.cx), float(intr.cy), intr.width, intr.height)
        return _nearest_factor(cam, *intrinsics, self.side, self.factor, np.asarray(sides))


@kernel
def _nearest_factor(cam, fx, fy, cx, cy, width, height, side, factor, sides):
    """``SkyShare.lookup`` after the camera-frame product: ``Intrinsics.project`` (NaN behind the
    camera), the nearest pixel centre (``np.rint``: ties to even), its factor where it lies in the
    image and holds the same face side, else NaN; the float64 steps of numpy's whole arrays."""
    out = np.empty(cam.shape[0], np.float32)
    for i in range(cam.shape[0]):
        z = cam[i, 2]
        safe = z if z > 1e-9 else np.nan
        u = np.rint(fx * cam[i, 0] / safe + cx)
        v = np.rint(fy * cam[i, 1] / safe + cy)
        out[i] = np.nan
        if u >= 0 and u < width and v >= 0 and v < height:  # False where NaN
            pixel = np.int64(v * width + u)
            if side[pixel] == sides[i]:
                out[i] = factor[pixel]
    return out


@dataclass
class PairSky:
    """A view's own-sky estimate as exchanged within its camera pair: ``partner``, the other view's
    factors to take where they apply (None: every pixel traces its own); ``estimated``, set by the
    render: this view's estimated pixels, their face sides and factors (``SkyShare.of``'s inputs).
    ``sun_partner`` and ``sun_estimated``: the same for the soft sun's share of the disc
    (``render.soft_shadow_radius``), on the face side the sun lights (``face * 2 + side``); a view
    offers only the shares of pixels whose windows' rays all agreed (``Penumbrae.mixed``)."""

    partner: SkyShare | None = None
    estimated: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    sun_partner: SkyShare | None = None
    sun_estimated: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None


def sun_ray_origins(points: np.ndarray, geometric: np.ndarray, idx: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(len(idx), 3) origins of the hard sun's shadow rays from the points ``idx``, whose cosines
    to the sun are ``c``: just off the sun's side of their ``geometric`` normals (``offsets.leave``).
    One place for every view's rays, so a ray the right view traces is the left view's."""
    side = vec.gather(geometric, idx) * np.sign(c)[:, None]
    return leave(vec.gather(points, idx), side, np.zeros(len(idx), np.float32))


def paired_sun_rays(tracer, points, geometric, idx, c, to_sun, image, pair: PairSky, radius: int) -> np.ndarray:
    """(len(idx),) bool: whether the points ``idx`` (cosines ``c``) of a view's hits (``image``:
    ``shading.sun_image``) see the sun's centre along ``to_sun``, from one ray each where the
    pair's other camera offers no answer for the same face side lit (``pair.sun_partner``, taken at
    its nearest pixel); a view without one traces every ray and offers the answers of pixels whose
    same-face window of ``radius`` pixels agreed (``pair.sun_estimated``; docs/scale-out.md)."""
    pixels, shape, faces, _ = image
    sides = vec.take(faces, idx).astype(np.int64) * 2 + (c < 0)
    seen = np.empty(len(idx), np.bool_)
    own = np.arange(len(idx))
    if pair.sun_partner is not None:
        shared = pair.sun_partner.lookup(vec.gather(points, idx), sides)
        taken = np.isfinite(shared)
        seen[taken] = shared[taken] > 0.5
        own = np.flatnonzero(~taken)
    seen[own] = ~tracer.occluded(sun_ray_origins(points, geometric, vec.take(idx, own), c[own]), to_sun[None, :])
    if pair.sun_partner is None:
        at_pixels = vec.take(pixels, idx)
        agreed = ~Penumbrae.of(at_pixels, shape, sides, seen, radius).mixed
        pair.sun_estimated = (at_pixels[agreed], sides[agreed], seen[agreed].astype(np.float32))
    return seen
