"""Top-down maps of the synthetic world in a drone or satellite look, for BEV-to-map matching.

Map pixel ``(row, col)`` is world ``x = x_max - row * resolution``, ``y = y_max - col *
resolution``: the map's axes are those of a BEV at yaw 0 (rows backwards along x, columns
backwards along y; see :mod:`jbevo.vision.bev`), so a BEV matches the map after a turn by its yaw.

The map's appearance differs from the ground camera's on purpose, as a map made by another
sensor on another day would: a blur (lower ground resolution), a different exposure and tone
curve (season-like change), large soft illumination changes (cloud shadows) and noise; it shows
no dynamic obstacles.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from jbevo.data.map import Map
from jbevo.data.synthetic.structures import Boxes
from jbevo.data.synthetic.world import World


@dataclass(frozen=True)
class MapStyle:
    """``blur`` (metres, Gaussian sigma), ``gain``/``offset``/``gamma`` of the tone curve,
    ``shadows`` (contrast of the 30-100 m illumination field) and ``noise`` (std)."""

    name: str = "drone"
    blur: float = 0.05
    gain: float = 0.9
    offset: float = 0.08
    gamma: float = 0.8
    shadows: float = 0.15
    noise: float = 0.01


MAP_STYLES = {
    "drone": MapStyle(),
    "satellite": MapStyle("satellite", blur=0.2, gain=0.7, offset=0.15, gamma=1.3, shadows=0.25, noise=0.02),
}


def render_map(
    world: World,
    xy: np.ndarray,
    resolution: float = 0.2,
    margin: float = 40.0,
    style: MapStyle | str = "drone",
    seed: int = 0,
    structures: Boxes | None = None,
) -> Map:
    """The map covering the points ``xy`` (``(N, 2)``, e.g. a trajectory) plus ``margin`` metres,
    at ``resolution`` metres per pixel, in ``style``; ``structures`` (a street's boxes,
    :mod:`jbevo.data.synthetic.structures`) show their tops (roofs, car roofs) in their shade."""
    if isinstance(style, str):
        if style not in MAP_STYLES:
            raise ValueError(f"unknown map style {style!r}; known: {sorted(MAP_STYLES)}")
        style = MAP_STYLES[style]
    xy = np.asarray(xy, float).reshape(-1, 2)
    if not len(xy) or not np.all(np.isfinite(xy)):
        raise ValueError("xy must hold at least one finite point")
    x_max, y_max = xy[:, 0].max() + margin, xy[:, 1].max() + margin
    rows = int(np.ceil((x_max - xy[:, 0].min() + margin) / resolution)) + 1
    cols = int(np.ceil((y_max - xy[:, 1].min() + margin) / resolution)) + 1
    x = x_max - resolution * jnp.arange(rows, dtype=jnp.float32)[:, None]
    y = y_max - resolution * jnp.arange(cols, dtype=jnp.float32)[None, :]
    footprint = max(resolution, 2.0 * style.blur)  # the texture's pyramid does the blurring
    texture = jax.jit(World.sample)(world, x * jnp.ones_like(y), y * jnp.ones_like(x), footprint)
    texture = np.asarray(texture)
    if structures is not None:
        texture = paint_tops(texture, structures, x_max, y_max, resolution)
    rng = np.random.default_rng(seed)
    field = _smooth_field(rng, (rows, cols), 50.0 / resolution)
    image = style.gain * texture**style.gamma + style.offset
    image = image * (1.0 + style.shadows * field) + style.noise * rng.standard_normal((rows, cols))
    image = np.round(np.clip(image, 0.0, 1.0) * 255).astype(np.uint8)
    return Map(jnp.asarray(image), float(x_max), float(y_max), float(resolution))


def paint_tops(image: np.ndarray, boxes: Boxes, x_max: float, y_max: float, resolution: float) -> np.ndarray:
    """``image`` (map pixel ``(row, col)`` at world ``(x_max - row r, y_max - col r)``) with every
    box's footprint filled with its shade, as seen from above."""
    out = np.array(image, np.float32)
    rows, cols = out.shape
    for (cx, cy), heading, (hl, hw), shade in zip(boxes.centre, boxes.heading, boxes.half, boxes.shade):
        reach = np.hypot(hl, hw)
        r0, r1 = int(np.floor((x_max - cx - reach) / resolution)), int(np.ceil((x_max - cx + reach) / resolution))
        c0, c1 = int(np.floor((y_max - cy - reach) / resolution)), int(np.ceil((y_max - cy + reach) / resolution))
        r0, r1, c0, c1 = max(r0, 0), min(r1, rows - 1), max(c0, 0), min(c1, cols - 1)
        if r0 > r1 or c0 > c1:
            continue
        dx = x_max - resolution * np.arange(r0, r1 + 1)[:, None] - cx
        dy = y_max - resolution * np.arange(c0, c1 + 1)[None, :] - cy
        u = dx * np.cos(heading) + dy * np.sin(heading)
        v = -dx * np.sin(heading) + dy * np.cos(heading)
        inside = (np.abs(u) <= hl) & (np.abs(v) <= hw)
        out[r0 : r1 + 1, c0 : c1 + 1][inside] = shade
    return out


def _smooth_field(rng: np.random.Generator, shape: tuple[int, int], scale_px: float) -> np.ndarray:
    """Unit-std noise smoothed to about ``scale_px`` pixels (FFT low-pass)."""
    f0 = np.fft.fftfreq(shape[0])[:, None]
    f1 = np.fft.fftfreq(shape[1])[None, :]
    low = np.exp(-0.5 * (np.hypot(f0, f1) * scale_px) ** 2)
    out = np.real(np.fft.ifft2(np.fft.fft2(rng.standard_normal(shape)) * low))
    return out / (out.std() + 1e-12)


__all__ = ["MAP_STYLES", "MapStyle", "paint_tops", "render_map"]
