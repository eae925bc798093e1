"""A small vectorised z-buffer rasteriser for the pose sequences (numpy only).

Projection is exactly OpenCV's pinhole model: a camera-frame point (x, y, z) lands at
``u = fx x / z + cx``, ``v = fy y / z + cy`` with pixel centres at integer coordinates (the
top-left pixel's centre is (0, 0)), as :func:`cv2.projectPoints` without distortion. A pixel is
covered by a triangle when its centre is inside the projected triangle; depth and attributes
are interpolated perspective-correctly. So the ground-truth pose projects any model point onto
the pixel where this rasteriser drew it.

The table is an infinite textured plane ``z = 0`` in the world frame (z up), intersected per
pixel. Shadows come from shadow maps rendered with the same rasteriser (orthographic for
directional lights, perspective for point and spot lights). Shading is
:func:`alcn_cv.data.render.shade`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from alcn_cv.data.lighting import Light, LightArrays, Lighting, shadow_shape
from alcn_cv.data.render import MATERIAL_FIELDS, Material, expose, shade
from alcn_cv.errors import InputError

__all__ = [
    "Mesh",
    "box_mesh",
    "ellipsoid_mesh",
    "merge_meshes",
    "look_at",
    "rasterize",
    "SceneObject",
    "TableScene",
    "ShadowSettings",
    "render_frame",
]


@dataclass
class Mesh:
    """A triangle mesh in its own frame (millimetres).

    Attributes:
        vertices: float64 (N, 3).
        faces: int64 (M, 3), counter-clockwise seen from outside.
        normals: float64 (N, 3) smooth vertex normals, or None for flat faces.
        uv: float32 (N, 2) texture coordinates in texture pixels (OpenCV convention), or None.
        colors: float32 (N, 3) linear RGB vertex colours (used without a texture), or None.
        texture: float32 (H, W, 3) linear RGB, or None.
        material: reflectance.
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray | None = None
    uv: np.ndarray | None = None
    colors: np.ndarray | None = None
    texture: np.ndarray | None = None
    material: Material = field(default_factory=lambda: Material("matte"))


def box_mesh(size: tuple[float, float, float], atlas: np.ndarray, material: Material) -> Mesh:
    """A box centred at the origin, each face textured by one cell of a 3x2 ``atlas``.

    Args:
        size: (sx, sy, sz) in mm.
        atlas: float32 (2T, 3T, 3) linear RGB: cells (row, col) = +z, -z, +x / -x, +y, -y.
        material: reflectance.
    """
    sx, sy, sz = (s / 2.0 for s in size)
    t = atlas.shape[0] // 2
    # Each face: origin corner, u axis, v axis (outward normal = u x v).
    faces = [
        ((-sx, -sy, sz), (2 * sx, 0, 0), (0, 2 * sy, 0)),  # +z
        ((-sx, sy, -sz), (2 * sx, 0, 0), (0, -2 * sy, 0)),  # -z
        ((sx, -sy, -sz), (0, 2 * sy, 0), (0, 0, 2 * sz)),  # +x
        ((-sx, sy, -sz), (0, -2 * sy, 0), (0, 0, 2 * sz)),  # -x
        ((sx, sy, -sz), (-2 * sx, 0, 0), (0, 0, 2 * sz)),  # +y
        ((-sx, -sy, -sz), (2 * sx, 0, 0), (0, 0, 2 * sz)),  # -y
    ]
    verts, uvs, tris = [], [], []
    for k, (o, u, v) in enumerate(faces):
        o, u, v = np.array(o, float), np.array(u, float), np.array(v, float)
        r, c = divmod(k, 3)
        base = len(verts)
        for a, b in ((0, 0), (1, 0), (1, 1), (0, 1)):
            verts.append(o + a * u + b * v)
            # Texel centres span [c*t, c*t + t - 1]; keep half a texel away from the cell edge.
            uvs.append((c * t + 0.5 + a * (t - 2), r * t + 0.5 + (1 - b) * (t - 2)))
        n = np.cross(u, v)
        tri1, tri2 = (base, base + 1, base + 2), (base, base + 2, base + 3)
        centre = o + (u + v) / 2
        if np.dot(n, centre) < 0:  # keep faces counter-clockwise from outside
            tri1, tri2 = tri1[::-1], tri2[::-1]
        tris += [tri1, tri2]
    return Mesh(
        np.array(verts),
        np.array(tris, np.int64),
        None,
        np.array(uvs, np.float32),
        None,
        atlas.astype(np.float32),
        material,
    )


def ellipsoid_mesh(
    centre: tuple[float, float, float],
    radii: tuple[float, float, float],
    colour: tuple[float, float, float],
    material: Material,
    *,
    segments: int = 24,
    rings: int = 16,
) -> Mesh:
    """A UV-sphere ellipsoid with smooth normals and a uniform vertex colour."""
    th = np.linspace(0, np.pi, rings + 1)
    ph = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    T, Pm = np.meshgrid(th, ph, indexing="ij")
    unit = np.stack([np.sin(T) * np.cos(Pm), np.sin(T) * np.sin(Pm), np.cos(T)], -1).reshape(-1, 3)
    r = np.asarray(radii, float)
    verts = unit * r + np.asarray(centre, float)
    normals = unit / r
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    tris = []
    for i in range(rings):
        for j in range(segments):
            a, b = i * segments + j, i * segments + (j + 1) % segments
            c, d = a + segments, b + segments
            if i > 0:
                tris.append((a, c, b))
            if i < rings - 1:
                tris.append((b, c, d))
    cols = np.tile(np.asarray(colour, np.float32), (len(verts), 1))
    return Mesh(verts, np.array(tris, np.int64), normals, None, cols, None, material)


def merge_meshes(meshes: list[Mesh]) -> Mesh:
    """Concatenate vertex-coloured meshes with smooth normals (one material: the first's)."""
    verts, faces, normals, cols = [], [], [], []
    off = 0
    for m in meshes:
        if m.colors is None or m.normals is None:
            raise InputError("merge_meshes needs vertex colours and normals")
        verts.append(m.vertices)
        faces.append(m.faces + off)
        normals.append(m.normals)
        cols.append(m.colors)
        off += len(m.vertices)
    return Mesh(
        np.concatenate(verts),
        np.concatenate(faces),
        np.concatenate(normals),
        None,
        np.concatenate(cols),
        None,
        meshes[0].material,
    )


def look_at(
    eye: np.ndarray, target: np.ndarray, up: tuple[float, float, float] | np.ndarray = (0.0, 0.0, 1.0)
) -> tuple[np.ndarray, np.ndarray]:
    """World-to-camera pose of an OpenCV camera (x right, y down, z forward) at ``eye``.

    Returns:
        ``(R_w2c, t_w2c)``: float64 (3, 3) and (3,).
    """
    z = np.asarray(target, float) - np.asarray(eye, float)
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, np.array([0.0, 1.0, 0.0]))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ np.asarray(eye, float)


#: Triangles with a vertex nearer than this depth are dropped by :func:`rasterize` (perspective only).
NEAR = 1.0
#: Triangle-pixel candidate pairs :func:`rasterize` processes at once (a memory bound).
MAX_PAIRS = 2_000_000


def rasterize(
    xy: np.ndarray,
    depth: np.ndarray,
    faces: np.ndarray,
    width: int,
    height: int,
    *,
    perspective: bool = True,
    with_attributes: bool = True,
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Rasterise triangles given in screen coordinates with a z-buffer.

    Args:
        xy: float64 (N, 2) vertex pixel coordinates (pixel centres at integers).
        depth: float64 (N,) camera-frame z (perspective) or any depth (orthographic).
        faces: int64 (M, 3) vertex indices.
        width, height: buffer size.
        perspective: interpolate ``1 / z`` (perspective-correct) rather than ``z``.
        with_attributes: also return the triangle index and barycentric buffers (else None).

    Returns:
        ``(zbuf, tri, bary)``: float64 (H, W) depth (inf where empty), int64 (H, W) triangle
        index (-1 where empty), float64 (H, W, 3) perspective-correct barycentric weights.
    """
    zbuf = np.full(height * width, np.inf)
    tri_buf = np.full(height * width, -1, np.int64) if with_attributes else None
    bary = np.zeros((height * width, 3)) if with_attributes else None

    def result():
        if not with_attributes:
            return zbuf.reshape(height, width), None, None
        return zbuf.reshape(height, width), tri_buf.reshape(height, width), bary.reshape(height, width, 3)

    if len(faces) == 0:
        return result()
    P = xy[faces]  # (M, 3, 2)
    Z = depth[faces]
    ok = np.isfinite(P).all(axis=(1, 2)) & np.isfinite(Z).all(axis=1)
    if perspective:
        ok &= (NEAR < Z).all(axis=1)
    x0 = np.clip(np.ceil(P[..., 0].min(1)), 0, width)
    x1 = np.clip(np.floor(P[..., 0].max(1)), -1, width - 1)
    y0 = np.clip(np.ceil(P[..., 1].min(1)), 0, height)
    y1 = np.clip(np.floor(P[..., 1].max(1)), -1, height - 1)
    area = (P[:, 1, 0] - P[:, 0, 0]) * (P[:, 2, 1] - P[:, 0, 1]) - (P[:, 2, 0] - P[:, 0, 0]) * (P[:, 1, 1] - P[:, 0, 1])
    ok &= (x1 >= x0) & (y1 >= y0) & (np.abs(area) > 1e-12)
    ids = np.nonzero(ok)[0]
    if not len(ids):  # every triangle culled: behind the camera, off the buffer or degenerate
        return result()
    bw = (x1[ids] - x0[ids] + 1).astype(np.int64)
    counts = bw * (y1[ids] - y0[ids] + 1).astype(np.int64)
    cand_pix, cand_z, cand_tri, cand_w = [], [], [], []
    start = 0
    csum = np.cumsum(counts)
    while start < len(ids):
        base = csum[start - 1] if start else 0
        stop = max(start + 1, int(np.searchsorted(csum, base + MAX_PAIRS, side="right")))
        sel = ids[start:stop]
        cnt = counts[start:stop]
        t = np.repeat(sel, cnt)
        local = np.arange(int(cnt.sum())) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        wloc = np.repeat(bw[start:stop], cnt)
        px = x0[t] + local % wloc
        py = y0[t] + local // wloc
        a = P[t]
        inv_area = 1.0 / area[t]
        w0 = ((a[:, 1, 0] - px) * (a[:, 2, 1] - py) - (a[:, 2, 0] - px) * (a[:, 1, 1] - py)) * inv_area
        w1 = ((a[:, 2, 0] - px) * (a[:, 0, 1] - py) - (a[:, 0, 0] - px) * (a[:, 2, 1] - py)) * inv_area
        w2 = 1.0 - w0 - w1
        inside = (w0 >= 0) & (w1 >= 0) & (w2 >= 0)
        t, px, py, w0, w1, w2 = t[inside], px[inside], py[inside], w0[inside], w1[inside], w2[inside]
        z = Z[t]
        if perspective:
            iz = w0 / z[:, 0] + w1 / z[:, 1] + w2 / z[:, 2]
            zz = 1.0 / iz
            wts = np.stack([w0 / z[:, 0], w1 / z[:, 1], w2 / z[:, 2]], 1) * zz[:, None]
        else:
            zz = w0 * z[:, 0] + w1 * z[:, 1] + w2 * z[:, 2]
            wts = np.stack([w0, w1, w2], 1)
        cand_pix.append((py * width + px).astype(np.int64))
        cand_z.append(zz)
        cand_tri.append(t)
        cand_w.append(wts)
        start = stop
    pix = np.concatenate(cand_pix)
    zz = np.concatenate(cand_z)
    if len(pix):
        tt = np.concatenate(cand_tri)
        ww = np.concatenate(cand_w)
        order = np.lexsort((tt, zz, pix))  # nearest first; ties broken by triangle index
        ps = pix[order]
        first = np.ones(len(ps), bool)
        first[1:] = ps[1:] != ps[:-1]
        sel = order[first]
        zbuf[pix[sel]] = zz[sel]
        if with_attributes:
            tri_buf[pix[sel]] = tt[sel]
            bary[pix[sel]] = ww[sel]
    return result()


@dataclass
class SceneObject:
    """A mesh placed in the world: ``x_world = R @ x_model + t`` (mm); ``obj_id`` 0 = clutter."""

    mesh: Mesh
    R: np.ndarray
    t: np.ndarray
    obj_id: int = 0


@dataclass
class TableScene:
    """A table-top scene: objects on an infinite textured table ``z = 0`` (world z up).

    Attributes:
        objects: meshes placed in the world.
        table: float32 (H, W, 3) linear RGB texture of the table, repeated (mirrored).
        table_mm_per_px: texture scale.
        table_material: reflectance of the table.
        wall: linear RGB colour of whatever lies beyond the table (rays not hitting it).
    """

    objects: list[SceneObject]
    table: np.ndarray
    table_mm_per_px: float = 1.0
    table_material: Material = field(default_factory=lambda: Material("matte"))
    wall: tuple[float, float, float] = (0.2, 0.2, 0.2)

    def world_meshes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Concatenated world-frame geometry: vertices (N, 3), faces (M, 3), object index per face."""
        verts, faces, owner = [], [], []
        off = 0
        for k, o in enumerate(self.objects):
            v = o.mesh.vertices @ o.R.T + o.t
            verts.append(v)
            faces.append(o.mesh.faces + off)
            owner.append(np.full(len(o.mesh.faces), k, np.int64))
            off += len(v)
        if not verts:
            return np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
        return np.concatenate(verts), np.concatenate(faces), np.concatenate(owner)


def _shadow_maps(verts: np.ndarray, faces: np.ndarray, lights: list[Light], extent: float, res: int = 1024):
    """One shadow map per light: (kind, projection data, depth map)."""
    maps = []
    for li in lights:
        if li.kind == "directional":
            d = np.asarray(li.vector, float)
            d /= np.linalg.norm(d)
            R, _ = look_at(np.zeros(3), -d, np.array([0.0, 1.0, 0.0]) if abs(d[2]) > 0.99 else np.array([0, 0, 1.0]))
            cam = verts @ R.T
            scale = res / (2 * extent)
            xy = cam[:, :2] * scale + (res - 1) / 2
            zb, _, _ = rasterize(xy, cam[:, 2], faces, res, res, perspective=False, with_attributes=False)
            maps.append(("ortho", R, scale, zb))
        else:
            pos = np.asarray(li.vector, float)
            R, t = look_at(pos, np.zeros(3))
            f = (res / 2) / np.tan(np.deg2rad(70))
            K = np.array([[f, 0, (res - 1) / 2], [0, f, (res - 1) / 2], [0, 0, 1.0]])
            cam = verts @ R.T + t
            xy = cam[:, :2] / cam[:, 2:3] * f + (res - 1) / 2
            zb, _, _ = rasterize(xy, cam[:, 2], faces, res, res, perspective=True, with_attributes=False)
            maps.append(("persp", (R, t, K), None, zb))
    return maps


def _lookup_shadow(
    kind: str,
    proj: np.ndarray | tuple[np.ndarray, np.ndarray, np.ndarray],
    scale: float | None,
    zb: np.ndarray,
    P: np.ndarray,
    bias: float,
) -> np.ndarray:
    res = zb.shape[0]
    if kind == "ortho":
        cam = P @ proj.T
        uv = cam[..., :2] * scale + (res - 1) / 2
        z = cam[..., 2]
    else:
        R, t, K = proj
        cam = P @ R.T + t
        z = cam[..., 2]
        uv = cam[..., :2] / np.maximum(z[..., None], 1e-6) * K[0, 0] + (res - 1) / 2
    vis = np.zeros(P.shape[:-1], np.float32)
    taps = ((0, 0), (1, 0), (-1, 0), (0, 1), (0, -1))
    for dx, dy in taps:  # percentage-closer filtering over 5 taps
        u = np.rint(uv[..., 0] + dx).astype(np.int64)
        v = np.rint(uv[..., 1] + dy).astype(np.int64)
        inside = (u >= 0) & (u < res) & (v >= 0) & (v < res)
        occ = zb[np.clip(v, 0, res - 1), np.clip(u, 0, res - 1)]
        vis += ((~inside) | (z <= occ + bias)).astype(np.float32)
    return vis / len(taps)


def _sample_mipmapped(tex: np.ndarray, mapx: np.ndarray, mapy: np.ndarray, levels: int = 6) -> np.ndarray:
    """Sample a (mirrored, repeating) texture with trilinear mip-mapping (no aliasing far away).

    The level of detail is log2 of the texture footprint of one pixel (texels per pixel, from
    the finite differences of the sampling maps).
    """
    fx = np.maximum(
        np.abs(np.diff(mapx, axis=1, append=mapx[:, -1:])), np.abs(np.diff(mapy, axis=1, append=mapy[:, -1:]))
    )
    fy = np.maximum(np.abs(np.diff(mapx, axis=0, append=mapx[-1:])), np.abs(np.diff(mapy, axis=0, append=mapy[-1:])))
    lod = np.clip(np.log2(np.maximum(np.maximum(fx, fy), 1e-6)), 0, levels - 1)
    out = np.zeros(mapx.shape + (3,), np.float32)
    level = tex
    for k in range(levels):
        w = np.clip(1.0 - np.abs(lod - k), 0.0, 1.0)
        if w.any():
            s = 2.0**k
            smp = cv2.remap(
                level,
                (mapx + 0.5) / s - 0.5,
                (mapy + 0.5) / s - 0.5,
                cv2.INTER_LINEAR,
                borderMode=cv2.BORDER_REFLECT_101,
            )
            out += w[..., None] * smp
        level = cv2.pyrDown(level)
    return out


@dataclass(frozen=True)
class ShadowSettings:
    """How :func:`render_frame` casts shadows.

    Attributes:
        res: side of the shadow maps in pixels.
        gobo_seed: seed of the hard shadow shape (``Lighting.shadow_shape``), fixed in the world
            so that it stays put from frame to frame.
    """

    res: int = 1024
    gobo_seed: int = 0


@dataclass
class _GBuffer:
    """Per-pixel inputs of the shader: world point, unit normal, linear RGB albedo, material
    parameters (:data:`MATERIAL_FIELDS`), and the object id of each pixel."""

    P: np.ndarray
    N: np.ndarray
    albedo: np.ndarray
    material: np.ndarray
    obj_id: np.ndarray


def _table_gbuffer(
    scene: TableScene, K: np.ndarray, R_w2c: np.ndarray, t_w2c: np.ndarray, width: int, height: int
) -> tuple[_GBuffer, np.ndarray, np.ndarray]:
    """Intersect each pixel's ray with the table ``z = 0`` and shade it as table (or wall beyond).

    Returns:
        The G-buffer, the camera centre (3,) and the camera z of the table point per pixel
        (inf where the ray misses the table).
    """
    vv, uu = np.mgrid[0:height, 0:width].astype(np.float64)
    ray_c = np.stack([(uu - K[0, 2]) / K[0, 0], (vv - K[1, 2]) / K[1, 1], np.ones_like(uu)], -1)
    ray_w = ray_c @ R_w2c  # = R^T d
    C = -R_w2c.T @ t_w2c
    with np.errstate(divide="ignore", invalid="ignore"):
        s = -C[2] / ray_w[..., 2]
    hit = (ray_w[..., 2] < 0) & (s > 0)
    s_table = np.where(hit, s, np.inf)  # camera z of the table point (ray_c z = 1)
    P = C + ray_w * np.where(hit, s, 0.0)[..., None]
    N = np.zeros((height, width, 3))
    N[..., 2] = 1.0
    albedo = np.empty((height, width, 3), np.float32)
    material = np.empty((height, width, len(MATERIAL_FIELDS)), np.float32)
    material[:] = scene.table_material.vector()
    tex = scene.table
    mapx = (P[..., 0] / scene.table_mm_per_px + tex.shape[1] / 2).astype(np.float32)
    mapy = (-P[..., 1] / scene.table_mm_per_px + tex.shape[0] / 2).astype(np.float32)
    albedo[:] = _sample_mipmapped(tex, mapx, mapy)
    albedo[~hit] = scene.wall
    obj_id = np.where(hit, 0, -1).astype(np.int64)
    return _GBuffer(P, N, albedo, material, obj_id), C, s_table


def _draw_objects(
    gb: _GBuffer,
    scene: TableScene,
    verts: np.ndarray,
    faces: np.ndarray,
    owner: np.ndarray,
    on_obj: np.ndarray,
    tri: np.ndarray,
    bary: np.ndarray,
) -> None:
    """Overwrite the G-buffer where an object is in front of the table: position, normal,
    albedo (texture or vertex colours), material and object id."""
    fidx = np.nonzero(on_obj.reshape(-1))[0]
    if not len(fidx):
        return
    t_sel = tri.reshape(-1)[fidx]
    b = bary.reshape(-1, 3)[fidx]
    own = owner[t_sel]
    fv = faces[t_sel]
    gb.P.reshape(-1, 3)[fidx] = (verts[fv] * b[..., None]).sum(1)
    first_face = np.cumsum([0] + [len(o.mesh.faces) for o in scene.objects])
    Nf = gb.N.reshape(-1, 3)
    Af = gb.albedo.reshape(-1, 3)
    Mf = gb.material.reshape(-1, len(MATERIAL_FIELDS))
    Of = gb.obj_id.reshape(-1)
    for k, o in enumerate(scene.objects):
        m = own == k
        if not m.any():
            continue
        pix = fidx[m]
        lf = t_sel[m] - first_face[k]
        lv = o.mesh.faces[lf]  # local vertex ids (n, 3)
        bk = b[m]
        if o.mesh.normals is not None:
            n_loc = (o.mesh.normals[lv] * bk[..., None]).sum(1)
        else:
            v3 = o.mesh.vertices[lv]
            n_loc = np.cross(v3[:, 1] - v3[:, 0], v3[:, 2] - v3[:, 0])
        n_w = n_loc @ o.R.T
        Nf[pix] = n_w / np.linalg.norm(n_w, axis=1, keepdims=True)
        if o.mesh.texture is not None:
            uv = (o.mesh.uv[lv] * bk[..., None].astype(np.float32)).sum(1).astype(np.float32)
            Af[pix] = cv2.remap(
                o.mesh.texture, uv[:, :1], uv[:, 1:], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
            ).reshape(-1, 3)
        else:
            Af[pix] = (o.mesh.colors[lv] * bk[..., None]).sum(1)
        Mf[pix] = o.mesh.material.vector()
        Of[pix] = o.obj_id


def _shadow_visibility(
    gb: _GBuffer, verts: np.ndarray, faces: np.ndarray, lighting: Lighting, shadows: ShadowSettings
) -> np.ndarray:
    """float32 (1, L, H, W) visibility of each light from each pixel: shadow maps, and the
    world-fixed hard shadow pattern (window frame, blinds...) on light 0."""
    height, width = gb.obj_id.shape
    extent = float(np.max(np.abs(verts[:, :2]))) * 1.3 + 50 if len(verts) else 500.0
    vis = np.ones((1, max(1, len(lighting.lights)), height, width), np.float32)
    maps = _shadow_maps(verts, faces, lighting.lights, extent, shadows.res)
    for i, (kind, proj, scale, zb) in enumerate(maps):
        # Normal-offset lookup (1.5 shadow-map texels along the normal) against shadow acne.
        vis[0, i] = _lookup_shadow(kind, proj, scale, zb, gb.P + gb.N * (3.0 * extent / shadows.res), bias=1.5)
    if lighting.shadow_shape is not None and lighting.lights:
        gob = shadow_shape(np.random.default_rng(shadows.gobo_seed), (512, 512), lighting.shadow_shape, penumbra=1.5)
        gx = (gb.P[..., 0] / 800.0 * 512 + 256).astype(np.float32)
        gy = (gb.P[..., 1] / 800.0 * 512 + 256).astype(np.float32)
        vis[0, 0] *= cv2.remap(gob, gx, gy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT_101)
    return vis


def render_frame(
    scene: TableScene,
    K: np.ndarray,
    R_w2c: np.ndarray,
    t_w2c: np.ndarray,
    width: int,
    height: int,
    lighting: Lighting,
    rng: np.random.Generator,
    shadows: ShadowSettings = ShadowSettings(),
) -> tuple[np.ndarray, np.ndarray]:
    """Render one BGR uint8 frame of ``scene`` seen by an OpenCV pinhole camera.

    The steps: rasterise the objects, intersect the table (:func:`_table_gbuffer`), draw the
    visible objects into the G-buffer (:func:`_draw_objects`), light visibility
    (:func:`_shadow_visibility`), then :func:`~alcn_cv.data.render.shade` and
    :func:`~alcn_cv.data.render.expose`.

    Args:
        scene: the table-top scene.
        K: float64 (3, 3) intrinsics (OpenCV convention, no distortion).
        R_w2c, t_w2c: camera pose (mm).
        width, height: image size.
        lighting: lights in world coordinates (mm) and the camera's response.
        rng: random generator (sensor noise).
        shadows: shadow-map resolution and the seed of the hard shadow shape.

    Returns:
        ``(image, obj_id)``: uint8 (H, W, 3) BGR, and int64 (H, W) the ``obj_id`` of the object each pixel
        shows (0 for clutter and the table, -1 beyond the table).
    """
    verts, faces, owner = scene.world_meshes()
    cam = verts @ R_w2c.T + t_w2c
    z = cam[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        xy = np.stack([K[0, 0] * cam[:, 0] / z + K[0, 2], K[1, 1] * cam[:, 1] / z + K[1, 2]], 1)
    zbuf, tri, bary = rasterize(xy, z, faces, width, height, perspective=True)
    gb, C, s_table = _table_gbuffer(scene, K, R_w2c, t_w2c, width, height)
    on_obj = (tri >= 0) & (zbuf <= s_table)
    _draw_objects(gb, scene, verts, faces, owner, on_obj, tri, bary)
    vis = _shadow_visibility(gb, verts, faces, lighting, shadows)
    V = C - gb.P
    V /= np.linalg.norm(V, axis=-1, keepdims=True) + 1e-12
    lights = LightArrays.pack([lighting.lights])
    rad = shade(
        gb.P[None].astype(np.float32),
        gb.N[None].astype(np.float32),
        V[None].astype(np.float32),
        gb.albedo[None],
        gb.material[None],
        lights,
        lighting.ambient[None],
        vis,
    )
    img = expose(rad[..., ::-1].copy(), [lighting], rng)[0]
    return img, gb.obj_id
