"""Materials, shading, shadows and camera effects of the data engine.

The renderer is a vectorised numpy/OpenCV shader that works on batches of *G-buffers*: per
pixel a 3D position ``P``, a unit normal ``N``, a unit direction to the viewer ``V``, a linear
RGB albedo and a vector of material parameters (:data:`MATERIAL_FIELDS`). Two kinds of
G-buffers feed it:

- 2.5D *height fields* (:class:`Surface`): a textured plane seen from above whose relief is a
  height map, in pixel units (x right, y down, z up towards the viewer). Directional light then
  makes self-shading and cast shadows as on real objects on a table; this renders the
  Normalizer's training windows and the detection benchmark's scenes.
- Rasterised triangle meshes (:mod:`alcn_cv.data.raster`), for the pose sequences.

Reflectance (per light, all terms multiplied by the light's colour, fall-off, spot cone and
shadow visibility)::

    diffuse  = kd * albedo * ((1 - f) * max(n.l, 0) + f * sqrt(max(n.l, 0)))    f = "flatten"
    specular = ks * mix(1, albedo, metallic) * (s + 8) / 16 * max(n.h, 0)**s        (Blinn-Phong)
    sheen    = sheen * mix(1, albedo, 0.5) * (sqrt(max(n.l, 0)) * 2 (1 - n.v)**2 + (1 - l.h)**5)

``flatten`` and ``sheen`` give a velvet-like look (a soft, flat fall-off and bright rims and
grazing light, neither Lambertian nor specular; after Koenderink & Pont's and Ashikhmin's
velvet models); metals have strong, tight, albedo-tinted highlights. Point and spot lights fall
off as ``1 / (1 + (d / range)**2)``; spots have a smooth cone. Height fields also get an
ambient-occlusion term (crevices receive less ambient light). The camera model applies an
exposure gain, signal-dependent sensor noise (shot + read noise, in linear units), clipping
(saturation), a gamma curve, optional motion blur and 8-bit quantisation.

The lights and their families are in :mod:`alcn_cv.data.lighting`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from alcn_cv.data.lighting import LightArrays, Lighting, shadow_shape
from alcn_cv.errors import InputError

__all__ = [
    "MATERIAL_FIELDS",
    "Material",
    "MATERIALS",
    "sample_material",
    "Surface",
    "heightfield_geometry",
    "heightfield_shadows",
    "shade",
    "expose",
    "render_surfaces",
]

#: Order of the per-pixel material parameters in :attr:`Surface.material`.
MATERIAL_FIELDS: tuple[str, ...] = ("diffuse", "specular", "shininess", "sheen", "flatten", "metallic")


@dataclass(frozen=True)
class Material:
    """Reflectance parameters of one material (see the module docstring for the model).

    Attributes:
        name: family name (``matte``, ``plastic``, ``velvet`` or ``metal``).
        diffuse: diffuse gain kd (0-1).
        specular: Blinn-Phong gain ks (0-2).
        shininess: Blinn-Phong exponent s (1-500).
        sheen: velvet sheen gain (0-1).
        flatten: 0 = Lambertian fall-off, 1 = flat sqrt fall-off (velvet).
        metallic: 0 = white highlights, 1 = highlights tinted by the albedo.
    """

    name: str
    diffuse: float = 1.0
    specular: float = 0.0
    shininess: float = 10.0
    sheen: float = 0.0
    flatten: float = 0.0
    metallic: float = 0.0

    def vector(self) -> np.ndarray:
        """The parameters in :data:`MATERIAL_FIELDS` order, float32 (6,)."""
        return np.array([getattr(self, f) for f in MATERIAL_FIELDS], np.float32)


#: Reference materials; :func:`sample_material` jitters them.
MATERIALS: dict[str, Material] = {
    "matte": Material("matte", diffuse=1.0, specular=0.02, shininess=6.0),
    "plastic": Material("plastic", diffuse=0.9, specular=0.3, shininess=40.0),
    "velvet": Material("velvet", diffuse=0.8, specular=0.0, shininess=1.0, sheen=0.5, flatten=0.8),
    "metal": Material("metal", diffuse=0.25, specular=0.6, shininess=200.0, metallic=0.85),
}


def sample_material(rng: np.random.Generator, name: str | None = None) -> Material:
    """A random material of family ``name`` (random family when None), parameters jittered."""
    name = name or str(rng.choice(list(MATERIALS)))
    if name not in MATERIALS:
        raise InputError(f"unknown material {name!r}; known: {sorted(MATERIALS)}")
    m = MATERIALS[name]
    j = lambda v, r: float(v * np.exp(rng.uniform(-r, r)))  # noqa: E731
    return dataclasses.replace(
        m,
        diffuse=min(1.0, j(m.diffuse, 0.15)),
        specular=j(m.specular, 0.5),
        shininess=j(m.shininess, 0.5),
        sheen=j(m.sheen, 0.4),
        flatten=float(np.clip(m.flatten + rng.uniform(-0.15, 0.15), 0, 1)) if m.flatten else 0.0,
    )


@dataclass
class Surface:
    """A batch of 2.5D height-field scenes (the G-buffer source of :func:`render_surfaces`).

    Attributes:
        albedo: float32 (B, H, W, 3) linear RGB reflectance in [0, 1].
        height: float32 (B, H, W) relief height in pixels (z towards the viewer).
        material: float32 (B, H, W, 6) per-pixel :data:`MATERIAL_FIELDS`.
    """

    albedo: np.ndarray
    height: np.ndarray
    material: np.ndarray


def heightfield_geometry(
    height: np.ndarray, camera: tuple[float, float, float] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, normals and view directions of height fields.

    Args:
        height: float32 (B, H, W) heights in pixels.
        camera: viewer position (x, y, z) in pixels for perspective view directions; None for
            an orthographic viewer straight above.

    Returns:
        ``(P, N, V)``: float32 (B, H, W, 3) positions, unit normals and unit view directions
        (V is (1, 1, 1, 3) for the orthographic viewer).
    """
    b, h, w = height.shape
    gy, gx = np.gradient(height, axis=(1, 2))
    inv = 1.0 / np.sqrt(gx * gx + gy * gy + 1.0)
    N = np.stack([-gx * inv, -gy * inv, inv], axis=-1).astype(np.float32)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    P = np.stack([np.broadcast_to(xx, (b, h, w)), np.broadcast_to(yy, (b, h, w)), height], axis=-1)
    if camera is None:
        V = np.array([0, 0, 1], np.float32).reshape(1, 1, 1, 3)
    else:
        V = np.asarray(camera, np.float32) - P
        V /= np.linalg.norm(V, axis=-1, keepdims=True)
    return P, N, V


def heightfield_shadows(
    height: np.ndarray, lights: LightArrays, *, steps: int = 12, max_dist: float | None = None, softness: float = 0.7
) -> np.ndarray:
    """Cast and self shadows of height fields by marching towards each light.

    A pixel is shadowed from a light when the relief along the ray towards it rises above the
    ray (nearest-neighbour samples at ``steps`` equally spaced horizontal distances up to
    ``max_dist``; the occlusion fades over ``softness`` pixels of height, which gives a narrow
    penumbra).

    Args:
        height: float32 (B, H, W) heights in pixels.
        lights: packed lights of the batch.
        steps: samples per ray.
        max_dist: longest shadow in pixels; default ``max(H, W) / 2``.
        softness: height difference (px) over which occlusion goes from 0 to 1.

    Returns:
        float32 (B, L, H, W) visibility in [0, 1] (1 = lit).
    """
    b, h, w = height.shape
    nl = lights.pos.shape[1]
    max_dist = float(max_dist or max(h, w) / 2)
    step = max_dist / steps
    hflat = height.reshape(-1)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    base = (np.arange(b, dtype=np.int64) * (h * w)).reshape(b, 1, 1)
    hrange = float(height.max() - height.min()) if height.size else 0.0
    vis = np.ones((b, nl, h, w), np.float32)
    if hrange < 1e-3:
        return vis
    for li in range(nl):
        active = np.any(lights.colour[:, li] > 0, axis=-1)
        if not active.any():
            continue
        pos = lights.pos[:, li].reshape(b, 1, 1, 3)
        wgt = lights.w[:, li].reshape(b, 1, 1)
        lx = pos[..., 0] - wgt * xx
        ly = pos[..., 1] - wgt * yy
        lz = pos[..., 2] - wgt * height
        hl = np.sqrt(lx * lx + ly * ly) + 1e-6
        dx, dy, slope = lx / hl, ly / hl, lz / hl
        # Point lights: stop at the light's horizontal distance; directional: never.
        reach = np.where(wgt > 0, hl, np.inf)
        occ = np.zeros((b, h, w), np.float32)
        min_slope = float(np.min(np.where(active.reshape(b, 1, 1), slope, np.inf)))
        for k in range(1, steps + 1):
            d = k * step
            if min_slope * d > hrange:
                break
            sx = np.rint(xx + dx * d).astype(np.int64)
            sy = np.rint(yy + dy * d).astype(np.int64)
            inside = (sx >= 0) & (sx < w) & (sy >= 0) & (sy < h) & (d < reach)
            np.clip(sx, 0, w - 1, out=sx)
            np.clip(sy, 0, h - 1, out=sy)
            hs = hflat[base + sy * w + sx]
            o = np.clip((hs - height - slope * d) / softness, 0.0, 1.0) * inside
            np.maximum(occ, o, out=occ)
        vis[:, li] = 1.0 - occ
    return vis


def shade(
    P: np.ndarray,
    N: np.ndarray,
    V: np.ndarray,
    albedo: np.ndarray,
    material: np.ndarray,
    lights: LightArrays,
    ambient: np.ndarray,
    visibility: np.ndarray | None = None,
    ambient_occlusion: np.ndarray | None = None,
) -> np.ndarray:
    """Radiance of a batch of G-buffers (see the module docstring for the model).

    Args:
        P: float32 (B, H, W, 3) positions.
        N: float32 (B, H, W, 3) unit normals.
        V: float32 (B, H, W, 3) or broadcastable unit directions to the viewer.
        albedo: float32 (B, H, W, 3) linear RGB in [0, 1].
        material: float32 (B, H, W, 6) :data:`MATERIAL_FIELDS`.
        lights: packed lights (B items, L slots).
        ambient: float32 (B, 3) ambient light.
        visibility: float32 (B, L, H, W) shadow visibility, or None (all lit).
        ambient_occlusion: float32 (B, H, W) ambient occlusion in [0, 1], or None.

    Returns:
        float32 (B, H, W, 3) linear radiance (unbounded; the camera clips it).
    """
    comp = lambda x: [np.ascontiguousarray(x[..., i], dtype=np.float32) for i in range(3)]  # noqa: E731
    px, py, pz = comp(P)
    nx, ny, nz = comp(N)
    vx, vy, vz = comp(V)
    kd, ks, shin, sheen, flat, metal = (np.ascontiguousarray(material[..., i]) for i in range(6))
    alb = comp(albedo)
    amb = np.asarray(ambient, np.float32).reshape(-1, 3)
    ao = np.float32(1.0) if ambient_occlusion is None else ambient_occlusion
    out = [amb[:, c].reshape(-1, 1, 1) * alb[c] * ao for c in range(3)]
    nv = np.clip(nx * vx + ny * vy + nz * vz, 0.0, 1.0)
    rim = 2.0 * (1.0 - nv) ** 2
    any_spec = bool(np.any(ks > 0))
    any_sheen = bool(np.any(sheen > 0))
    any_metal = bool(np.any(metal > 0))
    shp = (-1, 1, 1)
    for li in range(lights.pos.shape[1]):
        active = np.any(lights.colour[:, li] > 0, axis=1)
        if not active.any():
            continue
        # Shade only the items that have a light in this slot (slots 2 and 3 are often empty).
        sel = slice(None) if active.all() else np.nonzero(active)[0]

        def g(a: np.ndarray, sel: slice | np.ndarray = sel) -> np.ndarray:
            return a if a.shape[0] == 1 else a[sel]

        Px, Py, Pz, Nx, Ny, Nz, Vx, Vy, Vz = (g(a) for a in (px, py, pz, nx, ny, nz, vx, vy, vz))
        Kd, Ks, Shin, Sheen, Flat, Metal, Rim = (g(a) for a in (kd, ks, shin, sheen, flat, metal, rim))
        Alb = [g(a) for a in alb]
        col = lights.colour[sel, li]
        w = lights.w[sel, li].reshape(shp)
        lx = lights.pos[sel, li, 0].reshape(shp) - w * Px
        ly = lights.pos[sel, li, 1].reshape(shp) - w * Py
        lz = lights.pos[sel, li, 2].reshape(shp) - w * Pz
        d2 = lx * lx + ly * ly + lz * lz
        inv = 1.0 / np.sqrt(d2)
        lx *= inv
        ly *= inv
        lz *= inv
        factor = None
        if np.any(lights.inv_range2[sel, li] > 0):
            factor = 1.0 / (1.0 + d2 * lights.inv_range2[sel, li].reshape(shp))
        if np.any(lights.cos_outer[sel, li] > -1.0):
            sd = lights.spot_dir[sel, li]
            cos_a = -(lx * sd[:, 0].reshape(shp) + ly * sd[:, 1].reshape(shp) + lz * sd[:, 2].reshape(shp))
            co = lights.cos_outer[sel, li].reshape(shp)
            ci = lights.cos_inner[sel, li].reshape(shp)
            t = np.clip((cos_a - co) / np.maximum(ci - co, 1e-6), 0.0, 1.0)
            cone = t * t * (3.0 - 2.0 * t)
            factor = cone if factor is None else factor * cone
        if visibility is not None:
            vis = visibility[sel, li]
            factor = vis if factor is None else factor * vis
        nl = np.maximum(Nx * lx + Ny * ly + Nz * lz, 0.0)
        snl = np.sqrt(nl)
        diff = Kd * (nl + Flat * (snl - nl))
        spec = sh = None
        if any_spec or any_sheen:
            hx, hy, hz = lx + Vx, ly + Vy, lz + Vz
            hinv = 1.0 / (np.sqrt(hx * hx + hy * hy + hz * hz) + 1e-12)
            lit = nl > 0
        if any_spec:
            nh = np.clip((Nx * hx + Ny * hy + Nz * hz) * hinv, 0.0, 1.0)
            spec = Ks * (Shin + 8.0) / 16.0 * np.power(nh, Shin) * lit
        if any_sheen:
            lh = np.clip((lx * hx + ly * hy + lz * hz) * hinv, 0.0, 1.0)
            gl = 1.0 - lh
            gl2 = gl * gl
            sh = Sheen * (snl * Rim + gl2 * gl2 * gl * lit)
        for c in range(3):
            term = Alb[c] * diff
            if spec is not None:
                term += (spec * (1.0 - Metal + Metal * Alb[c])) if any_metal else spec
            if sh is not None:
                term += sh * (0.5 + 0.5 * Alb[c])
            scale = col[:, c].reshape(shp)
            contrib = (term * scale) if factor is None else term * (factor * scale)
            if isinstance(sel, slice):
                out[c] += contrib
            else:
                out[c][sel] += contrib
    return np.stack(out, axis=-1).astype(np.float32, copy=False)


def expose(
    radiance: np.ndarray,
    lightings: Sequence[Lighting],
    rng: np.random.Generator,
) -> np.ndarray:
    """Camera response: gradient, exposure gain, sensor noise, saturation, gamma, blur, 8 bits.

    Args:
        radiance: float32 (B, H, W) or (B, H, W, C) linear radiance.
        lightings: one :class:`Lighting` per batch item (gain, gamma, noise, gradient, blur).
        rng: random generator for the noise.

    Returns:
        uint8 array of the same shape (channels in the input's order).
    """
    b, h, w = radiance.shape[:3]
    shp = (b, 1, 1) + (1,) * (radiance.ndim - 3)
    gain = np.array([lt.gain for lt in lightings], np.float32).reshape(shp)
    x = radiance * gain
    grad = np.array([lt.gradient for lt in lightings], np.float32)
    if np.any(grad != 0):
        u = np.linspace(-1, 1, w, dtype=np.float32).reshape(1, 1, w)
        v = np.linspace(-1, 1, h, dtype=np.float32).reshape(1, h, 1)
        ramp = np.exp(grad[:, 0].reshape(b, 1, 1) * u + grad[:, 1].reshape(b, 1, 1) * v)
        x = x * ramp.reshape(b, h, w, *([1] * (radiance.ndim - 3)))
    shot = np.array([lt.shot_noise for lt in lightings], np.float32).reshape(shp)
    read = np.array([lt.read_noise for lt in lightings], np.float32).reshape(shp)
    sigma = np.sqrt(shot * np.clip(x, 0.0, 1.0) + read * read)
    x = x + sigma * rng.standard_normal(x.shape, dtype=np.float32)
    np.clip(x, 0.0, 1.0, out=x)
    inv_gamma = (1.0 / np.array([lt.gamma for lt in lightings], np.float32)).reshape(shp)
    x = np.power(x, inv_gamma)
    for i, lt in enumerate(lightings):
        if lt.motion_blur is not None:
            x[i] = _motion_blur(x[i], *lt.motion_blur)
    return np.rint(x * 255.0).astype(np.uint8)


def _motion_blur(img: np.ndarray, length: float, angle_deg: float) -> np.ndarray:
    k = int(max(3, np.ceil(length))) | 1
    kernel = np.zeros((k, k), np.float32)
    c = k // 2
    a = np.deg2rad(angle_deg)
    dx, dy = np.cos(a) * length / 2, np.sin(a) * length / 2
    cv2.line(
        kernel,
        (int(round(c * 16 - dx * 16)), int(round(c * 16 - dy * 16))),
        (int(round(c * 16 + dx * 16)), int(round(c * 16 + dy * 16))),
        1.0,
        1,
        cv2.LINE_AA,
        4,
    )
    kernel /= kernel.sum()
    return cv2.filter2D(img, -1, kernel, borderType=cv2.BORDER_REFLECT_101)


def render_surfaces(
    surface: Surface,
    lightings: Sequence[Lighting],
    rng: np.random.Generator,
    *,
    gray: bool = False,
    camera_height: float | None = None,
    shadow_steps: int = 12,
    shadow_scale: int = 1,
) -> np.ndarray:
    """Render a batch of height fields, each under its own lighting, to 8-bit images.

    Args:
        surface: the batch (B, H, W).
        lightings: one :class:`Lighting` per item.
        rng: random generator (shadow shapes, noise).
        gray: return (B, H, W) grayscale (luminance of the linear RGB radiance, before noise)
            instead of (B, H, W, 3) BGR.
        camera_height: perspective viewer at (W/2, H/2, camera_height) px for view-dependent
            highlights; orthographic when None.
        shadow_steps: ray-marching samples per light.
        shadow_scale: compute shadows on a grid downsampled by this factor (then upsampled),
            for large scenes.

    Returns:
        uint8 (B, H, W) grayscale or (B, H, W, 3) BGR.
    """
    b, h, w = surface.height.shape
    if len(lightings) != b:
        raise InputError(f"need one lighting per batch item: {len(lightings)} for {b}")
    # Independent streams for the shadow shapes and the noise: item i's output does not depend
    # on the batch size (the first m items of a batch equal a batch of those m items).
    shape_rng, noise_rng = rng.spawn(2)
    lights = LightArrays.pack([lt.lights for lt in lightings])
    cam = None if camera_height is None else (w / 2.0, h / 2.0, float(camera_height))
    P, N, V = heightfield_geometry(surface.height, cam)
    if shadow_scale > 1:
        hs, ws = h // shadow_scale, w // shadow_scale
        small = np.stack([cv2.resize(x, (ws, hs), interpolation=cv2.INTER_AREA) for x in surface.height])
        small = small / shadow_scale
        ls = dataclasses.replace(
            lights, pos=lights.pos * np.where(lights.w[..., None] > 0, 1.0 / shadow_scale, 1.0).astype(np.float32)
        )
        vs = heightfield_shadows(small.astype(np.float32), ls, steps=shadow_steps)
        vis = np.stack([np.stack([cv2.resize(v, (w, h), interpolation=cv2.INTER_LINEAR) for v in vb]) for vb in vs])
    else:
        vis = heightfield_shadows(surface.height, lights, steps=shadow_steps)
    for i, lt in enumerate(lightings):
        if lt.shadow_shape is not None:
            vis[i, 0] *= shadow_shape(shape_rng, (h, w), lt.shadow_shape, penumbra=max(0.6, 0.006 * max(h, w)))
    # Ambient occlusion: crevices (below the local mean height) receive less ambient light.
    ao = np.empty((b, h, w), np.float32)
    sig = 3.0 if max(h, w) <= 128 else 6.0
    for i in range(b):
        ao[i] = cv2.GaussianBlur(surface.height[i], (0, 0), sig)
    ao = np.clip(1.0 - 0.08 * np.maximum(ao - surface.height, 0.0), 0.3, 1.0)
    ambient = np.stack([lt.ambient for lt in lightings]).astype(np.float32)
    rad = shade(P, N, V, surface.albedo, surface.material, lights, ambient, vis, ao)
    if gray:
        rad = rad[..., 0] * 0.299 + rad[..., 1] * 0.587 + rad[..., 2] * 0.114
        return expose(rad, lightings, noise_rng)
    return expose(rad[..., ::-1].copy(), lightings, noise_rng)
