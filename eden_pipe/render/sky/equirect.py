"""Equirectangular (latitude-longitude) panoramas: the orientation convention and lookups.

Convention (Blender's, so a map made for Blender lights a garden the same way;
world Z up, azimuth measured from +x toward +y as everywhere in the sky):

* row 0 is the zenith (+z), the last row the nadir; rows are uniform in the
  polar angle: pixel row i spans theta in [i, i + 1] * pi / H;
* the image's centre column looks along +x; +y is a quarter of the width to
  the left of the centre, -y a quarter to the right (the map reads as seen from
  inside the sphere): column coordinate u = 0.5 - azimuth / (2 pi) (mod 1);
* ``rotation`` (radians, ``lighting.environment_rotation_deg``) turns the map
  about +z: a feature at map azimuth a appears at world azimuth a + rotation.

Texel centres sit at integer coordinates (``lut.sample``); lookups are bilinear and
wrap across the seam of the azimuth.
"""

from __future__ import annotations

import math

import numpy as np

from eden_pipe.render import lut, vec


def pixel_directions(height: int, width: int, rotation: float = 0.0, rows: slice = slice(None)) -> np.ndarray:
    """(H * W, 3) world unit directions of the pixel centres (row-major), or of ``rows`` only."""
    theta = (np.arange(height)[rows] + 0.5) * (math.pi / height)
    phi = (0.5 - (np.arange(width) + 0.5) / width) * (2.0 * math.pi) + rotation
    t, p = np.meshgrid(theta, phi, indexing="ij")
    st = np.sin(t)
    return np.stack([st * np.cos(p), st * np.sin(p), np.cos(t)], axis=-1).reshape(-1, 3)


def pixel_solid_angles(height: int, width: int) -> np.ndarray:
    """(H * W,) exact solid angle of each pixel (they sum to 4 pi)."""
    edges = np.arange(height + 1) * (math.pi / height)
    rows = (np.cos(edges[:-1]) - np.cos(edges[1:])) * (2.0 * math.pi / width)
    return np.repeat(rows, width)


def texel_coordinates(
    directions: np.ndarray, height: int, width: int, rotation: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """(cols, rows) float32 texel coordinates of world directions (any length)."""
    d = np.asarray(directions, np.float32).reshape(-1, 3)
    length = np.maximum(vec.length(d), np.float32(1e-12))
    azimuth = np.arctan2(d[:, 1], d[:, 0]) - np.float32(rotation)
    u = np.float32(0.5) - azimuth * np.float32(0.5 / math.pi)
    cols = lut.periodic(u * np.float32(width) - np.float32(0.5), width)
    rows = np.arccos(np.clip(d[:, 2] / length, -1.0, 1.0)) * np.float32(height / math.pi) - np.float32(0.5)
    return cols.astype(np.float32), rows.astype(np.float32)


class Panorama:
    """An equirectangular image (H, W, C) looked up by world direction (bilinear)."""

    def __init__(self, image: np.ndarray, rotation: float = 0.0):
        self.height, self.width, self.channels = image.shape
        self.rotation = float(rotation)
        self._table = lut.wrap_columns(np.asarray(image, np.float32))

    def lookup(self, directions: np.ndarray) -> np.ndarray:
        """(N, 3) world directions -> (N, C) float32."""
        cols, rows = texel_coordinates(directions, self.height, self.width, self.rotation)
        return lut.sample(self._table, cols, rows)
