"""A planar ground world of unbounded extent: a seeded, periodic road-like texture and its
anti-aliased sampling at any world position.

The ground ``z = 0`` carries a texture that is a pure function of world ``(x, y)`` (metres) and
of the :class:`Town` (seed and texture mix). It is built once in numpy as a square, seamlessly
periodic tile (``size`` pixels of ``resolution`` metres; the default repeats every 81.92 m, far
more than a BEV spans) from band-limited noise made in the Fourier domain (so it tiles), with
content at several scales:

* asphalt grain (0.1-0.4 m) and mottling (0.5-4 m) everywhere,
* a street grid (two roads per tile and axis) with dashed centre lines, lane lines and kerbs,
* repaired patches (5-20 m blobs, darker), and grass outside the roads (brighter grain).

Anti-aliasing: the tile's mip pyramid (2x2 box filter) is packed into one atlas; a sample at
footprint ``f`` metres (the ground extent of one camera pixel) blends the two pyramid levels
around ``log2(f / resolution)`` (trilinear filtering), so distant ground is smoothed, not
aliased, and does not shimmer as the camera moves.
"""

from __future__ import annotations

from dataclasses import dataclass

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, UInt32


@dataclass(frozen=True)
class Town:
    """The texture mix of a world: ``seed`` and the share of each kind of content.

    Different towns (``TOWNS``) differ in seed and mix so that a model can be trained in one and
    tested in another.
    """

    seed: int = 0
    grass: float = 0.35  # share of the off-road area that is grass
    patches: float = 0.25  # share of the area under repaired patches
    grain: float = 0.08  # contrast of the asphalt grain
    mottle: float = 0.10  # contrast of the 0.5-4 m mottling
    markings: bool = True  # lane lines and kerbs on the street grid


TOWNS = {
    "town01": Town(seed=1),
    "town02": Town(seed=2, grass=0.6, patches=0.1, grain=0.06, mottle=0.12),
    "town03": Town(seed=3, grass=0.15, patches=0.4, grain=0.10, mottle=0.08),
}


def _band_noise(rng: np.random.Generator, n: int, resolution: float, lo: float, hi: float) -> np.ndarray:
    """Periodic unit-variance noise with wavelengths between ``lo`` and ``hi`` metres."""
    f = np.fft.fftfreq(n, d=resolution)
    r = np.hypot(f[:, None], f[None, :])
    band = (r >= 1.0 / hi) & (r <= 1.0 / lo)
    spectrum = np.fft.fft2(rng.standard_normal((n, n))) * band
    out = np.real(np.fft.ifft2(spectrum))
    return out / (out.std() + 1e-12)


def _smoothstep(d: np.ndarray, width: float) -> np.ndarray:
    """1 inside (``d < 0``), 0 outside, with an anti-aliased edge ``width`` wide."""
    return np.clip(0.5 - d / width, 0.0, 1.0)


def _periodic_distance(coord: np.ndarray, centre: float, period: float) -> np.ndarray:
    return np.abs((coord - centre + period / 2) % period - period / 2)


def make_tile(town: Town, size: int = 2048, resolution: float = 0.04) -> np.ndarray:
    """The town's periodic ground tile (``size x size``, values in [0, 1]); row ``r``, column
    ``c`` is world ``(x, y) = (c, r) * resolution`` (modulo the period)."""
    rng = np.random.default_rng(town.seed)
    period = size * resolution
    coords = np.arange(size) * resolution
    x, y = coords[None, :], coords[:, None]
    px = resolution  # edge width: one texel

    grain = _band_noise(rng, size, resolution, 0.1, 0.4)
    mottle = _band_noise(rng, size, resolution, 0.5, 4.0)
    large = _band_noise(rng, size, resolution, 5.0, 20.0)
    regions = _band_noise(rng, size, resolution, 8.0, 40.0)
    blades = _band_noise(rng, size, resolution, 0.08, 0.25)

    # Street grid: two roads per period along x and along y, 10 m wide.
    half_width = 5.0
    spacing = period / 2
    dy = _periodic_distance(y, spacing / 2, spacing)
    dx = _periodic_distance(x, spacing / 2, spacing)
    road = np.maximum(_smoothstep(dy - half_width, px), _smoothstep(dx - half_width, px))

    asphalt = 0.38 + town.grain * grain + town.mottle * mottle
    patch_level = np.quantile(large, 1.0 - town.patches) if town.patches > 0 else np.inf
    patch = _smoothstep(patch_level - large, 0.15)  # 1 inside a patch
    asphalt = asphalt - 0.08 * patch + 0.03 * patch * grain

    grass_level = np.quantile(regions, town.grass) if town.grass > 0 else -np.inf
    grass = _smoothstep(regions - grass_level, 0.5)
    pavement = 0.55 + 0.5 * town.grain * grain + 0.6 * town.mottle * mottle
    turf = 0.30 + 0.12 * blades + 1.2 * town.mottle * mottle
    off_road = grass * turf + (1 - grass) * pavement
    tile = road * asphalt + (1 - road) * off_road

    if town.markings:
        dash_x = _smoothstep(np.abs(((x + 1.5) % 9.0) - 1.5) - 1.5, px)  # 3 m dashes every 9 m
        dash_y = _smoothstep(np.abs(((y + 1.5) % 9.0) - 1.5) - 1.5, px)
        lines = np.zeros_like(tile)
        for offset, dashed in ((0.0, True), (-3.5, False), (3.5, False)):
            along_x = _smoothstep(_periodic_distance(y, spacing / 2 + offset, spacing) - 0.075, px)
            along_y = _smoothstep(_periodic_distance(x, spacing / 2 + offset, spacing) - 0.075, px)
            if dashed:
                along_x, along_y = along_x * dash_x, along_y * dash_y
            lines = np.maximum(lines, np.maximum(along_x * (dx > half_width), along_y * (dy > half_width)))
        kerb_x = _smoothstep(np.abs(dy - half_width) - 0.1, px) * (dx > half_width + 0.1)
        kerb_y = _smoothstep(np.abs(dx - half_width) - 0.1, px) * (dy > half_width + 0.1)
        kerb = np.maximum(kerb_x, kerb_y)
        tile = tile * (1 - lines) + lines * (0.85 + 0.03 * grain)
        tile = tile * (1 - kerb) + kerb * (0.7 + 0.04 * mottle)
    return np.clip(tile, 0.0, 1.0).astype(np.float32)


def _pyramid(tile: np.ndarray, smallest: int = 16) -> list[np.ndarray]:
    levels = [tile]
    while levels[-1].shape[0] > smallest:
        t = levels[-1]
        levels.append(0.25 * (t[0::2, 0::2] + t[1::2, 0::2] + t[0::2, 1::2] + t[1::2, 1::2]))
    return levels


class World(eqx.Module):
    """The ground texture of a :class:`Town` as a packed mip atlas (an array leaf, so a world is a
    pytree that can be passed into jitted code) and its static layout."""

    atlas: UInt32[Array, "R C"]  # texture * 255 of a texel and its right, lower, lower-right neighbours
    resolution: float = eqx.field(static=True)
    sizes: tuple[int, ...] = eqx.field(static=True)  # edge length of each pyramid level

    @classmethod
    def create(cls, town: Town | str = "town01", size: int = 2048, resolution: float = 0.04) -> World:
        """Build the world of ``town`` (a :class:`Town` or a name in ``TOWNS``)."""
        if isinstance(town, str):
            if town not in TOWNS:
                raise ValueError(f"unknown town {town!r}; known: {sorted(TOWNS)}")
            town = TOWNS[town]
        if size < 32 or size & (size - 1):
            raise ValueError(f"size must be a power of two >= 32, got {size}")
        return cls.from_tile(make_tile(town, size, resolution), resolution)

    @classmethod
    def from_tile(cls, tile: np.ndarray, resolution: float) -> World:
        """A world that repeats ``tile`` (square, power-of-two size >= 32, values in [0, 1]; row
        ``r``, column ``c`` at world ``(x, y) = (c, r) * resolution``), e.g. a photo of gravel."""
        tile = np.asarray(tile, np.float32)
        size = tile.shape[0]
        if tile.ndim != 2 or tile.shape[1] != size or size < 32 or size & (size - 1):
            raise ValueError(f"tile must be square with a power-of-two size >= 32, got shape {tile.shape}")
        if not np.all(np.isfinite(tile)) or tile.min() < 0 or tile.max() > 1:
            raise ValueError("tile values must be finite and in [0, 1]")
        if not resolution > 0:
            raise ValueError(f"resolution must be positive, got {resolution}")
        levels = _pyramid(tile)
        # Level 0 on the left, the others stacked in a column to its right; each carries one
        # wrapped row and column so that both bilinear taps of the last texel exist.
        offsets, row = [(0, 0)], 0
        for lv in levels[1:]:
            offsets.append((row, size + 1))
            row += lv.shape[0] + 1
        atlas = np.zeros((size + 1, size + 1 + levels[1].shape[0] + 1), np.float32)
        for lv, (r0, c0) in zip(levels, offsets):
            n = lv.shape[0]
            atlas[r0 : r0 + n + 1, c0 : c0 + n + 1] = np.pad(lv, ((0, 1), (0, 1)), mode="wrap")
        # 8 bits like a camera's pixels, and each texel packs its 2x2 bilinear neighbourhood
        # into one uint32 (t00, t01, t10, t11 from the low byte up): one gather per sample
        # instead of four.
        q = np.round(atlas * 255.0).astype(np.uint32)
        q = np.pad(q, ((0, 1), (0, 1)))
        atlas = q[:-1, :-1] | (q[:-1, 1:] << 8) | (q[1:, :-1] << 16) | (q[1:, 1:] << 24)
        return cls(jnp.asarray(atlas), float(resolution), tuple(lv.shape[0] for lv in levels))

    @property
    def period(self) -> float:
        """Metres after which the texture repeats (along x and y)."""
        return self.sizes[0] * self.resolution

    def _level(self, u0, v0, level) -> Array:
        """Bilinear sample of pyramid ``level`` (an integer array) at base-texel coordinates
        ``(u0, v0)`` already wrapped into ``[0, n0)``."""
        n0 = self.sizes[0]
        inv = 1.0 / jnp.left_shift(1, level).astype(u0.dtype)  # 2^-k (exp2 is not vectorised on CPU)
        n = jnp.right_shift(n0, level)
        # Closed form of the packing in ``from_tile`` (no per-pixel table lookups): level k >= 1 starts at row
        # sum_{j=1}^{k-1} (n_j + 1) = n0 - 2 n_k + k - 1 of the column right of level 0.
        row0 = jnp.where(level > 0, n0 - 2 * n + level - 1, 0)
        col0 = jnp.where(level > 0, n0 + 1, 0)
        # Texel i of level k is centred on base texel i * 2^k + (2^k - 1) / 2; coordinates that
        # fall before texel 0 wrap to the last one (2^k divides n0, so the period is whole).
        nf = n.astype(u0.dtype)
        u = u0 * inv - 0.5 + 0.5 * inv
        v = v0 * inv - 0.5 + 0.5 * inv
        u = jnp.where(u < 0, u + nf, u)
        v = jnp.where(v < 0, v + nf, v)
        iu, iv = jnp.floor(u), jnp.floor(v)
        fu, fv = u - iu, v - iv
        iu = jnp.minimum(iu.astype(jnp.int32), n - 1) + col0
        iv = jnp.minimum(iv.astype(jnp.int32), n - 1) + row0
        packed = self.atlas.reshape(-1)[iv * self.atlas.shape[1] + iu]

        def tap(byte):
            return jnp.bitwise_and(jnp.right_shift(packed, 8 * byte), 255).astype(u0.dtype)

        top = tap(0) * (1 - fu) + tap(1) * fu
        bottom = tap(2) * (1 - fu) + tap(3) * fu
        return (top * (1 - fv) + bottom * fv) * (1.0 / 255.0)

    def sample(self, x: Float[Array, "..."], y: Float[Array, "..."], footprint: Float[Array, "..."] | float = 0.0):
        """Texture at world ``(x, y)`` filtered for a sample spacing of ``footprint`` metres."""
        x, y = jnp.asarray(x), jnp.asarray(y)
        if not jnp.issubdtype(x.dtype, jnp.floating):
            x, y = x.astype(jnp.float32), y.astype(jnp.float32)
        n0 = self.sizes[0]
        u0 = x * (1.0 / self.resolution)
        v0 = y * (1.0 / self.resolution)
        u0 = u0 - n0 * jnp.floor(u0 * (1.0 / n0))
        v0 = v0 - n0 * jnp.floor(v0 * (1.0 / n0))
        lod = jnp.log2(jnp.maximum(jnp.asarray(footprint, x.dtype), 1e-6) / self.resolution)
        lod = jnp.clip(lod, 0.0, len(self.sizes) - 1.0)
        lo = jnp.minimum(jnp.floor(lod).astype(jnp.int32), len(self.sizes) - 2)
        t = lod - lo
        return self._level(u0, v0, lo) * (1 - t) + self._level(u0, v0, lo + 1) * t

    def top_down(self, origin: tuple[float, float], shape: tuple[int, int], resolution: float) -> Array:
        """A top-down raster: pixel ``(row, col)`` is world ``(x, y) = origin + (col, row) *
        resolution``, filtered for that spacing."""
        rows = jnp.arange(shape[0], dtype=jnp.float32)[:, None]
        cols = jnp.arange(shape[1], dtype=jnp.float32)[None, :]
        return self.sample(origin[0] + cols * resolution, origin[1] + rows * resolution, resolution)


__all__ = ["TOWNS", "Town", "World", "make_tile"]
