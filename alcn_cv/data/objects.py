"""Textured relief objects and their placement on 2.5D surfaces.

A :class:`ReliefObject` is what the Phos-like training windows and the detection benchmark
show: an albedo texture (photograph crop or procedural, sometimes with printed marks), a
silhouette, a height map in pixels (a box with bevelled edges, a dome, a cylinder or a flat
slab, plus embossed detail and random bumps) and a material. Under directional light its height
map gives self-shading and a cast shadow on whatever it stands on.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np

from alcn_cv.data.render import MATERIAL_FIELDS, Material, Surface, sample_material
from alcn_cv.data.textures import fractal_noise, procedural_texture, random_texture

__all__ = [
    "ReliefObject",
    "SHAPES",
    "make_object",
    "make_catalog",
    "paste",
    "background_surface",
    "to_surface",
]

#: Silhouette/height profiles of :func:`make_object`.
SHAPES: tuple[str, ...] = ("box", "dome", "cylinder", "slab", "blob")


@dataclass
class ReliefObject:
    """A textured relief object in its canonical frame (``size x size`` pixels).

    Attributes:
        albedo: float32 (S, S, 3) linear RGB.
        height: float32 (S, S) height above the ground in canonical pixels (0 outside).
        mask: float32 (S, S) antialiased silhouette in [0, 1].
        material: its :class:`~alcn_cv.data.render.Material`.
        shape: one of :data:`SHAPES`.
    """

    albedo: np.ndarray
    height: np.ndarray
    mask: np.ndarray
    material: Material
    shape: str

    @property
    def size(self) -> int:
        return self.albedo.shape[0]

    @functools.cached_property
    def packed(self) -> np.ndarray:
        """Albedo and height stacked (S, S, 4) for one warp."""
        return np.dstack([self.albedo, self.height])


def _silhouette(rng: np.random.Generator, s: int, shape: str) -> np.ndarray:
    """Binary-ish silhouette (float32, supersampled then reduced for antialiasing)."""
    ss = 4
    big = np.zeros((s * ss, s * ss), np.float32)
    c = s * ss / 2
    r = 0.46 * s * ss
    if shape in ("box", "slab"):
        aspect = rng.uniform(0.65, 1.0)
        hw, hh = (r, r * aspect) if rng.random() < 0.5 else (r * aspect, r)
        rad = rng.uniform(0, 0.25) * min(hw, hh)
        x0, y0, x1, y1 = c - hw, c - hh, c + hw, c + hh
        cv2.rectangle(big, (int(x0 + rad), int(y0)), (int(x1 - rad), int(y1)), 1.0, -1)
        cv2.rectangle(big, (int(x0), int(y0 + rad)), (int(x1), int(y1 - rad)), 1.0, -1)
        for px, py in ((x0 + rad, y0 + rad), (x1 - rad, y0 + rad), (x0 + rad, y1 - rad), (x1 - rad, y1 - rad)):
            cv2.circle(big, (int(px), int(py)), int(rad), 1.0, -1)
    elif shape in ("dome", "cylinder"):
        axes = (int(r), int(r * rng.uniform(0.7, 1.0)))
        cv2.ellipse(big, (int(c), int(c)), axes, float(rng.uniform(0, 180)), 0, 360, 1.0, -1)
    else:  # blob: star-convex shape with smooth random radius
        n = 64
        ang = np.linspace(0, 2 * np.pi, n, endpoint=False)
        k = np.arange(1, 5)
        coef = rng.normal(0, 0.12, (4, 2)) / k[:, None]
        rad = r * (0.85 + (coef[:, :1] * np.cos(np.outer(k, ang)) + coef[:, 1:] * np.sin(np.outer(k, ang))).sum(0))
        pts = np.stack([c + rad * np.cos(ang), c + rad * np.sin(ang)], 1)
        cv2.fillPoly(big, [np.round(pts).astype(np.int32)], 1.0)
    return cv2.resize(big, (s, s), interpolation=cv2.INTER_AREA)


def make_object(
    rng: np.random.Generator,
    size: int = 96,
    *,
    shape: str | None = None,
    material: str | Material | None = None,
    relief: float | None = None,
) -> ReliefObject:
    """A random textured relief object.

    Args:
        rng: random generator.
        size: canonical side in pixels.
        shape: one of :data:`SHAPES` (random when None).
        material: a material family name, a :class:`Material`, or None for a random one.
        relief: maximum height as a fraction of ``size`` (random 0.05-0.25 when None).
    """
    shape = shape or str(rng.choice(SHAPES))
    mask = _silhouette(rng, size, shape)
    inside = (mask > 0.5).astype(np.uint8)
    dist = cv2.distanceTransform(inside, cv2.DIST_L2, 5).astype(np.float32)
    relief = float(relief if relief is not None else rng.uniform(0.05, 0.25))
    hmax = relief * size
    if shape == "box":
        bevel = rng.uniform(0.04, 0.12) * size
        prof = np.clip(dist / bevel, 0, 1)
    elif shape == "dome":
        prof = np.sqrt(np.clip(1 - (1 - dist / max(dist.max(), 1)) ** 2, 0, 1))
    elif shape == "cylinder":
        yy, xx = np.mgrid[0:size, 0:size].astype(np.float32) / size - 0.5
        a = rng.uniform(0, np.pi)
        u = (xx * np.cos(a) + yy * np.sin(a)) / 0.46
        prof = np.sqrt(np.clip(1 - u * u, 0, 1)) * np.clip(dist / 2.0, 0, 1)
    elif shape == "slab":
        prof = np.clip(dist / 1.5, 0, 1) * 0.3
    else:
        prof = np.clip(dist / max(dist.max(), 1), 0, 1) ** 0.6
    tex = random_texture(rng, size, p_photo=0.6)
    if rng.random() < 0.4:  # printed marks (labels, logos) on top of the texture
        marks = procedural_texture(rng, size, "print")
        alpha = (np.abs(marks - marks[0, 0]).sum(-1, keepdims=True) > 0.05).astype(np.float32)
        tex = tex * (1 - alpha) + marks * alpha
    lum = tex @ np.array([0.299, 0.587, 0.114], np.float32)
    emboss = cv2.GaussianBlur(lum, (0, 0), rng.uniform(0.7, 2.0)) * rng.uniform(0.0, 0.05) * size
    bumps = fractal_noise(rng, (size, size), base=int(rng.integers(3, 9))) * rng.uniform(0.0, 0.06) * size
    height = (hmax * prof + (emboss + bumps) * np.clip(dist / 3.0, 0, 1)) * mask
    mat = material if isinstance(material, Material) else sample_material(rng, material)
    return ReliefObject(tex.astype(np.float32), height.astype(np.float32), mask.astype(np.float32), mat, shape)


def make_catalog(n: int, seed: int, size: int = 96) -> list[ReliefObject]:
    """``n`` distinct objects, deterministic for ``seed`` (object ``k`` depends on ``(seed, k)`` only)."""
    return [make_object(np.random.default_rng([seed, k]), size) for k in range(n)]


def background_surface(
    rng: np.random.Generator, h: int, w: int, texture: np.ndarray | None = None, *, relief: float = 1.5
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A textured, slightly uneven ground (albedo, height, material) of ``h x w`` pixels.

    Args:
        texture: albedo to crop/resize from (float32 RGB); a random texture when None.
        relief: amplitude of the ground's relief in pixels.
    """
    if texture is None:
        texture = random_texture(rng, (h, w))
    elif texture.shape[:2] != (h, w):
        texture = cv2.resize(texture, (w, h), interpolation=cv2.INTER_LINEAR)
    albedo = np.ascontiguousarray(texture, np.float32)
    lum = albedo @ np.array([0.299, 0.587, 0.114], np.float32)
    height = (fractal_noise(rng, (h, w), base=int(rng.integers(2, 8))) + 0.5 * lum) * relief * rng.uniform(0.2, 1.0)
    mat = np.empty((h, w, len(MATERIAL_FIELDS)), np.float32)
    mat[:] = sample_material(rng, str(rng.choice(["matte", "matte", "plastic", "velvet"]))).vector()
    return albedo, height.astype(np.float32), mat


def paste(
    albedo: np.ndarray,
    height: np.ndarray,
    material: np.ndarray,
    obj: ReliefObject,
    centre: tuple[float, float],
    scale: float,
    angle_deg: float = 0.0,
    *,
    tilt: tuple[float, float] = (0.0, 0.0),
) -> np.ndarray:
    """Place ``obj`` on a surface in place, standing on it; return its coverage mask (H, W).

    Args:
        albedo, height, material: the surface arrays (H, W, 3), (H, W), (H, W, 6), modified.
        obj: the object.
        centre: (x, y) of the object's canonical centre in surface pixels.
        scale: surface pixels per canonical pixel (heights scale with it).
        angle_deg: in-plane rotation (counter-clockwise in the image).
        tilt: small perspective-like shear (sx, sy) added to the affine map.

    Returns:
        float32 (H, W) coverage in [0, 1] of the pasted object.
    """
    h, w = height.shape
    s = obj.size
    M = cv2.getRotationMatrix2D((s / 2 - 0.5, s / 2 - 0.5), angle_deg, scale)
    M[0, 1] += tilt[0] * scale
    M[1, 0] += tilt[1] * scale
    M[:, 2] += np.array(centre) - (s / 2 - 0.5)
    # Only warp the bounding region of the object.
    r = 0.75 * s * scale * (1 + abs(tilt[0]) + abs(tilt[1]))
    x0, y0 = max(0, int(centre[0] - r)), max(0, int(centre[1] - r))
    x1, y1 = min(w, int(np.ceil(centre[0] + r)) + 1), min(h, int(np.ceil(centre[1] + r)) + 1)
    cov = np.zeros((h, w), np.float32)
    if x1 <= x0 or y1 <= y0:
        return cov
    Mr = M.copy()
    Mr[:, 2] -= (x0, y0)
    size = (x1 - x0, y1 - y0)
    warped = cv2.warpAffine(obj.packed, Mr, size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    a = cv2.warpAffine(obj.mask, Mr, size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    sl = (slice(y0, y1), slice(x0, x1))
    a3 = a[..., None]
    albedo[sl] = albedo[sl] * (1 - a3) + warped[..., :3] * a3
    base = height[sl]
    # The object stands on the ground: it rests on the local mean height under it.
    rest = float((base * a).sum() / max(a.sum(), 1e-6))
    height[sl] = base * (1 - a) + (rest + warped[..., 3] * scale) * a
    material[sl] = material[sl] * (1 - a3) + obj.material.vector() * a3
    cov[sl] = a
    return cov


def to_surface(items: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> Surface:
    """Stack (albedo, height, material) triples into a batched :class:`Surface`."""
    return Surface(
        np.stack([i[0] for i in items]).astype(np.float32),
        np.stack([i[1] for i in items]).astype(np.float32),
        np.stack([i[2] for i in items]).astype(np.float32),
    )
