"""Colour conversions used by the models: sRGB <-> linear and RGB <-> HSV; luminance.

Presets give colours in sRGB (what a person picks in a colour chooser); meshes
carry linear RGB albedo (what the renderer integrates). HSV is where the
models jitter colours between plants and leaves.

There are two HSV jitters, on purpose: :func:`jitter_hsv_rows` is the tree
model's (hue ties resolve red first, saturation and value are multiplied) and
:func:`rgb_to_hsv` / :func:`hsv_to_rgb` the leaf library's (ties resolve blue
first). They agree mathematically but not bit for bit on every input, and the
datasets are promised byte-identical, so each model keeps its own.

Still to switch to this module (owned elsewhere): ``render/shading.py``
(``linear_to_srgb``) and ``render/rasterizer.py`` (``srgb_to_linear``).
"""

from __future__ import annotations

import numpy as np

LUMA = np.array([0.2126, 0.7152, 0.0722])  # linear sRGB (Rec. 709 primaries) -> luminance


def luminance(rgb: np.ndarray) -> np.ndarray:
    """(...) luminance of linear sRGB colours (..., 3)."""
    return rgb @ LUMA


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """The sRGB transfer (12.92u below 0.0031308, else 1.055u^(1/2.4) - 0.055) on values clipped to [0, 1]
    (docs/design.md, Image formation)."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def srgb_to_uint8(linear: np.ndarray) -> np.ndarray:
    """Linear RGB to the 8-bit sRGB the PNGs hold."""
    return np.round(linear_to_srgb(linear) * 255.0).astype(np.uint8)


def srgb_to_linear(c) -> np.ndarray:
    """sRGB in [0, 1] (clipped) to linear RGB, the IEC 61966-2-1 curve."""
    c = np.clip(np.asarray(c, np.float64), 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def rgb_to_hsv(rgb: np.ndarray) -> np.ndarray:
    """(..., 3) RGB to HSV with hue in turns [0, 1)."""
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    mx, mn = rgb.max(-1), rgb.min(-1)
    d = mx - mn
    h = np.zeros_like(mx)
    safe = np.maximum(d, 1e-12)
    h = np.where(mx == r, ((g - b) / safe) % 6.0, h)
    h = np.where(mx == g, (b - r) / safe + 2.0, h)
    h = np.where(mx == b, (r - g) / safe + 4.0, h)
    h = np.where(d > 0, h / 6.0, 0.0)
    s = np.where(mx > 0, d / np.maximum(mx, 1e-12), 0.0)
    return np.stack([h % 1.0, s, mx], -1)


def hsv_to_rgb(hsv: np.ndarray) -> np.ndarray:
    """(..., 3) HSV (hue in turns, wrapped; saturation and value clipped to [0, 1]) to RGB."""
    h, s, v = hsv[..., 0] % 1.0, np.clip(hsv[..., 1], 0, 1), np.clip(hsv[..., 2], 0, 1)
    i = np.floor(h * 6.0)
    f = h * 6.0 - i
    p, q, t = v * (1 - s), v * (1 - s * f), v * (1 - s * (1 - f))
    i = i.astype(np.int64) % 6
    r = np.choose(i, [v, q, p, p, t, v])
    g = np.choose(i, [t, v, v, q, p, p])
    b = np.choose(i, [p, p, t, v, v, q])
    return np.stack([r, g, b], -1)


def shift_hsv(base_srgb, dh: float = 0.0, ds: float = 0.0, dv: float = 0.0) -> np.ndarray:
    """An sRGB colour with hue shifted by ``dh`` turns, saturation and value scaled by 1+ds, 1+dv."""
    hsv = rgb_to_hsv(np.asarray(base_srgb, np.float64))
    hsv = hsv * [1.0, 1.0 + ds, 1.0 + dv] + [dh, 0.0, 0.0]
    return hsv_to_rgb(hsv)


def jitter_colors(base_srgb, count: int, rng: np.random.Generator, hue=0.0, sat=0.0, val=0.0) -> np.ndarray:
    """``count`` linear-RGB colours around an sRGB base colour: hue shifted by
    U(-hue, hue) turns, saturation and value scaled by 1 + U(-sat, sat) / 1 + U(-val, val)."""
    hsv = np.broadcast_to(rgb_to_hsv(np.asarray(base_srgb, np.float64)), (count, 3)).copy()
    hsv[:, 0] += rng.uniform(-hue, hue, count) if hue else 0.0
    hsv[:, 1] *= 1.0 + (rng.uniform(-sat, sat, count) if sat else 0.0)
    hsv[:, 2] *= 1.0 + (rng.uniform(-val, val, count) if val else 0.0)
    return srgb_to_linear(hsv_to_rgb(hsv)).astype(np.float32)


def jitter_hsv_rows(rgb: np.ndarray, dh, ds, dv) -> np.ndarray:
    """Rows of RGB with hue shifted by ``dh`` turns and saturation, value multiplied by ``ds``, ``dv``
    (clipped to [0, 1]); the tree model's variant (see the module docstring)."""
    rgb = np.atleast_2d(np.asarray(rgb, dtype=np.float64))
    mx = rgb.max(axis=1)
    mn = rgb.min(axis=1)
    delta = mx - mn
    r, g, b = rgb.T
    h = np.zeros(len(rgb))
    nz = delta > 1e-12
    rm = nz & (mx == r)
    gm = nz & (mx == g) & ~rm
    bm = nz & ~rm & ~gm
    h[rm] = ((g - b)[rm] / delta[rm]) % 6
    h[gm] = (b - r)[gm] / delta[gm] + 2
    h[bm] = (r - g)[bm] / delta[bm] + 4
    h = h / 6.0
    s = np.where(mx > 1e-12, delta / np.maximum(mx, 1e-12), 0.0)
    v = mx
    h = (h + dh) % 1.0
    s = np.clip(s * ds, 0, 1)
    v = np.clip(v * dv, 0, 1)
    i = np.floor(h * 6).astype(int) % 6
    f = h * 6 - np.floor(h * 6)
    pp, q, t = v * (1 - s), v * (1 - f * s), v * (1 - (1 - f) * s)
    out = np.select(
        [i[:, None] == k for k in range(6)],
        [np.stack(c, 1) for c in ((v, t, pp), (q, v, pp), (pp, v, t), (pp, q, v), (t, pp, v), (v, pp, q))],
    )
    return out
