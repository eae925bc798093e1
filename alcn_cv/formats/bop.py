"""BOP pose datasets (https://github.com/thodan/bop_toolkit/blob/master/docs/bop_datasets_format.md).

A scene folder holds ``scene_camera.json`` (per image id: ``cam_K`` row-major 3x3, ``depth_scale``,
optionally the camera pose ``cam_R_w2c``/``cam_t_w2c``), ``scene_gt.json`` (per image id: a list
of ``{"obj_id", "cam_R_m2c", "cam_t_m2c"}`` model-to-camera poses) and ``rgb/<im_id:06d>.png``.
Models are ``models/obj_<obj_id:06d>.ply`` and the dataset root's ``camera.json`` gives the image
size. **Units are millimetres** (translations and model
vertices); the intrinsics follow OpenCV's convention (pixel centres at integer coordinates,
top-left pixel centre at (0, 0)), so ``x = K (R X + t)`` gives OpenCV pixel coordinates.

PLY models are read and written in ASCII or binary little-endian, with optional normals
(``nx ny nz``), colours (``red green blue``, 0-255) and texture coordinates (``texture_u
texture_v`` in [0, 1], v up as in BOP; the texture image is named by a ``comment TextureFile``
line).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from alcn_cv.errors import DatasetError, InputError
from alcn_cv.formats import validate_json
from alcn_cv.io import atomic_write, make_folder, read_image, read_json, write_json

__all__ = [
    "BopObjectPose",
    "BopFrame",
    "BopScene",
    "PlyModel",
    "load_scene",
    "write_scene",
    "write_camera",
    "read_ply",
    "write_ply",
    "models_info",
]

#: Translations and models smaller than this (mm) are taken as written in metres.
_MIN_PLAUSIBLE_MM = 5.0


@dataclass
class BopObjectPose:
    """Model-to-camera pose of one object in one frame: ``x_cam = R @ x_model + t`` (mm)."""

    obj_id: int
    R: np.ndarray
    t: np.ndarray


@dataclass
class BopFrame:
    """One image of a scene.

    Attributes:
        im_id: image id.
        rgb_path: the colour image (``rgb/<im_id:06d>.png``, or ``.jpg``).
        K: float64 (3, 3) OpenCV intrinsics.
        depth_scale: depth unit in mm (BOP), None when absent.
        objects: ground-truth poses (empty when the scene has no ``scene_gt.json``).
        R_w2c, t_w2c: camera pose world -> camera (mm) when given, else None.
    """

    im_id: int
    rgb_path: Path
    K: np.ndarray
    depth_scale: float | None
    objects: list[BopObjectPose] = field(default_factory=list)
    R_w2c: np.ndarray | None = None
    t_w2c: np.ndarray | None = None

    def object_index(self, obj_id: int) -> int | None:
        """The index of ``obj_id``'s first pose in :attr:`objects` (that of its ``mask_visib`` image,
        ``<im_id:06d>_<index:06d>.png``), or ``None`` when it is not annotated in this frame."""
        return next((i for i, o in enumerate(self.objects) if o.obj_id == obj_id), None)

    def pose(self, obj_id: int) -> BopObjectPose:
        """The pose of ``obj_id`` in this frame (KeyError when absent)."""
        index = self.object_index(obj_id)
        if index is None:
            raise KeyError(f"object {obj_id} not annotated in image {self.im_id}")
        return self.objects[index]


@dataclass
class BopScene:
    """A BOP scene: its folder and its frames sorted by image id."""

    path: Path
    frames: list[BopFrame]

    def __len__(self) -> int:
        return len(self.frames)

    def frame(self, im_id: int) -> BopFrame:
        for f in self.frames:
            if f.im_id == im_id:
                return f
        raise KeyError(f"no image {im_id} in {self.path}")


def _rotation(file: Path, key: str, values: list[float]) -> np.ndarray:
    R = np.asarray(values, np.float64).reshape(3, 3)
    if not np.isfinite(R).all() or abs(np.linalg.det(R) - 1.0) > 1e-3 or np.abs(R @ R.T - np.eye(3)).max() > 1e-3:
        raise DatasetError(f"{file}: field {key}: not a rotation matrix (det {np.linalg.det(R):.4f})")
    return R


def load_scene(scene_dir: str | os.PathLike, *, check_images: bool = False) -> BopScene:
    """Read a BOP scene folder.

    Args:
        scene_dir: folder with ``scene_camera.json``, ``rgb/`` and optionally ``scene_gt.json``.
        check_images: also read every image (:func:`alcn_cv.io.read_image`) and check that it exists and is
            whole (no truncated JPEG), that its size is the dataset's (``camera.json`` two folders up, when
            present) and that the principal point lies inside it.

    Raises:
        DatasetError: missing, truncated or malformed files; a field violating the schema; a
            non-rotation; translations that look like metres rather than millimetres (wrong
            unit); ground truth for images without a camera; with ``check_images``, missing,
            unreadable or truncated images or images of the wrong size.
    """
    root = Path(scene_dir)
    cam_file = root / "scene_camera.json"
    cams = read_json(cam_file)
    validate_json(cams, "bop_scene_camera", cam_file)
    gt_file = root / "scene_gt.json"
    gts: dict[str, Any] = {}
    if gt_file.exists():
        gts = read_json(gt_file)
        validate_json(gts, "bop_scene_gt", gt_file)
        extra = sorted(set(gts) - set(cams), key=int)
        if extra:
            raise DatasetError(f"{gt_file}: field {extra[0]}: image id has no entry in {cam_file.name}")
    frames = []
    for key in sorted(cams, key=int):
        c = cams[key]
        K = np.asarray(c["cam_K"], np.float64).reshape(3, 3)
        if K[0, 0] <= 0 or K[1, 1] <= 0 or np.abs(K[2] - (0, 0, 1)).max() > 1e-9:
            raise DatasetError(f"{cam_file}: field {key}.cam_K: not an intrinsics matrix {K.tolist()}")
        R_w2c = t_w2c = None
        if "cam_R_w2c" in c or "cam_t_w2c" in c:
            if "cam_R_w2c" not in c or "cam_t_w2c" not in c:
                raise DatasetError(f"{cam_file}: field {key}: cam_R_w2c and cam_t_w2c must come together")
            R_w2c = _rotation(cam_file, f"{key}.cam_R_w2c", c["cam_R_w2c"])
            t_w2c = np.asarray(c["cam_t_w2c"], np.float64)
        objects = []
        for i, g in enumerate(gts.get(key, [])):
            R = _rotation(gt_file, f"{key}[{i}].cam_R_m2c", g["cam_R_m2c"])
            t = np.asarray(g["cam_t_m2c"], np.float64)
            if np.linalg.norm(t) < _MIN_PLAUSIBLE_MM:
                raise DatasetError(
                    f"{gt_file}: field {key}[{i}].cam_t_m2c: {t.tolist()} is too small for "
                    "millimetres (wrong unit? BOP uses mm)"
                )
            objects.append(BopObjectPose(int(g["obj_id"]), R, t))
        rgb = root / "rgb" / f"{int(key):06d}.png"
        if not rgb.exists() and (root / "rgb" / f"{int(key):06d}.jpg").exists():
            rgb = root / "rgb" / f"{int(key):06d}.jpg"
        frames.append(
            BopFrame(int(key), rgb, K, float(c["depth_scale"]) if "depth_scale" in c else None, objects, R_w2c, t_w2c)
        )
    if check_images:
        # BOP keeps the image size in the dataset's camera.json (two levels up), when present.
        size = None
        cam_json = root.parent.parent / "camera.json"
        if cam_json.exists():
            cj = read_json(cam_json)
            if not isinstance(cj, dict) or not all(isinstance(cj.get(k), int) for k in ("width", "height")):
                raise DatasetError(f"{cam_json}: fields width and height must be integers")
            size = (cj["width"], cj["height"])
        for f in frames:
            try:
                h, w = read_image(f.rgb_path).shape[:2]
            except InputError as exc:
                raise DatasetError(f"{cam_file}: field {f.im_id}: {exc}") from None
            if size is not None and (w, h) != size:
                raise DatasetError(f"{cam_json}: fields width/height: {size[0]}x{size[1]} but {f.rgb_path} is {w}x{h}")
            if not (0 <= f.K[0, 2] < w and 0 <= f.K[1, 2] < h):
                raise DatasetError(
                    f"{cam_file}: field {f.im_id}.cam_K: principal point outside the {w}x{h} image {f.rgb_path}"
                )
    return BopScene(root, frames)


def write_camera(root: str | os.PathLike, K: np.ndarray, width: int, height: int, depth_scale: float = 1.0) -> Path:
    """Write a BOP dataset's ``camera.json`` (fx, fy, cx, cy, width, height, depth_scale) atomically."""
    path = Path(root) / "camera.json"
    write_json(
        path,
        {
            "cx": float(K[0, 2]),
            "cy": float(K[1, 2]),
            "depth_scale": float(depth_scale),
            "fx": float(K[0, 0]),
            "fy": float(K[1, 1]),
            "height": int(height),
            "width": int(width),
        },
    )
    return path


def _flat(a: np.ndarray) -> list[float]:
    return [float(round(v, 9)) for v in np.asarray(a, np.float64).reshape(-1)]


def write_scene(
    scene_dir: str | os.PathLike,
    frames: list[BopFrame],
) -> Path:
    """Write ``scene_camera.json`` and ``scene_gt.json`` of ``frames`` (images are the caller's).

    Both files are validated against their schemas and written atomically.
    """
    root = Path(scene_dir)
    make_folder(root)
    cams, gts = {}, {}
    for f in frames:
        c: dict[str, Any] = {"cam_K": _flat(f.K), "depth_scale": 1.0 if f.depth_scale is None else f.depth_scale}
        if f.R_w2c is not None:
            c["cam_R_w2c"] = _flat(f.R_w2c)
            c["cam_t_w2c"] = _flat(f.t_w2c)
        cams[str(f.im_id)] = c
        gts[str(f.im_id)] = [
            {"cam_R_m2c": _flat(o.R), "cam_t_m2c": _flat(o.t), "obj_id": int(o.obj_id)} for o in f.objects
        ]
    validate_json(cams, "bop_scene_camera", root / "scene_camera.json")
    validate_json(gts, "bop_scene_gt", root / "scene_gt.json")
    write_json(root / "scene_camera.json", cams, indent=None)
    write_json(root / "scene_gt.json", gts, indent=None)
    return root


@dataclass
class PlyModel:
    """A triangle mesh read from or written to PLY.

    Attributes:
        vertices: float64 (N, 3), millimetres for BOP models.
        faces: int64 (M, 3) vertex indices.
        normals: float64 (N, 3) or None.
        colors: uint8 (N, 3) RGB or None.
        texcoords: float64 (N, 2) (u, v) in [0, 1], v up, or None.
        texture_file: name of the texture image next to the PLY, or None.
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray | None = None
    colors: np.ndarray | None = None
    texcoords: np.ndarray | None = None
    texture_file: str | None = None


_PLY_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}


def _ply_int(path: Path, token: str) -> int:
    try:
        return int(token)
    except ValueError:
        raise DatasetError(f"{path}: element face: {token!r} is not an integer") from None


def read_ply(path: str | os.PathLike, *, unit_check: bool = True) -> PlyModel:
    """Read a triangle-mesh PLY (ASCII or binary little-endian).

    Args:
        path: the file.
        unit_check: raise when the model is smaller than 5 mm across (a model in metres).

    Raises:
        DatasetError: missing, truncated or malformed file, non-triangle faces, or a wrong unit.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise DatasetError(f"{path}: file not found") from None
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise DatasetError(f"{path}: not a PLY file (missing 'ply' magic or 'end_header')")
    header = data[:end].decode("ascii", "replace").splitlines()
    newline = data.find(b"\n", end)
    body = data[newline + 1 :] if newline >= 0 else b""
    fmt = None
    texture_file = None
    elements: list[tuple[str, int, list[tuple[str, ...]]]] = []
    for line in header[1:]:
        tok = line.split()
        if not tok:
            continue
        if tok[0] == "format":
            fmt = tok[1]
        elif tok[0] == "comment" and len(tok) >= 3 and tok[1] == "TextureFile":
            texture_file = tok[2]
        elif tok[0] == "element":
            if len(tok) != 3 or not tok[2].isdigit():
                raise DatasetError(f"{path}: header: expected 'element NAME COUNT', got {line.strip()!r}")
            elements.append((tok[1], int(tok[2]), []))
        elif tok[0] == "property":
            if not elements:
                raise DatasetError(f"{path}: header: property before any element")
            prop = tuple(tok[1:])
            types = prop[1:3] if prop[:1] == ("list",) else prop[:1]
            if len(prop) != (4 if prop[:1] == ("list",) else 2) or any(t not in _PLY_TYPES for t in types):
                raise DatasetError(
                    f"{path}: header: bad property {line.strip()!r} (types: {', '.join(sorted(_PLY_TYPES))})"
                )
            elements[-1][2].append(prop)
    if fmt not in ("ascii", "binary_little_endian"):
        raise DatasetError(f"{path}: header field format: {fmt!r} not supported (ascii, binary_little_endian)")
    out: dict[str, Any] = {}
    offset = 0
    tokens = body.decode("ascii", "replace").split() if fmt == "ascii" else None
    for name, count, props in elements:
        if name == "face":
            if len(props) != 1 or props[0][0] != "list":
                raise DatasetError(f"{path}: element face: expected one list property")
            _, ctype, itype, _ = props[0]
            if fmt == "ascii":
                faces = []
                for _ in range(count):
                    if offset >= len(tokens):
                        raise DatasetError(f"{path}: truncated (element face)")
                    n = _ply_int(path, tokens[offset])
                    if n != 3:
                        raise DatasetError(f"{path}: element face: only triangles are supported, found {n}-gon")
                    if offset + 1 + n > len(tokens):
                        raise DatasetError(f"{path}: truncated (element face)")
                    faces.append([_ply_int(path, t) for t in tokens[offset + 1 : offset + 1 + n]])
                    offset += 1 + n
                out["faces"] = np.asarray(faces, np.int64).reshape(-1, 3)
            else:
                dt = np.dtype([("n", _PLY_TYPES[ctype]), ("i", _PLY_TYPES[itype], 3)]).newbyteorder("<")
                nbytes = dt.itemsize * count
                if offset + nbytes > len(body):
                    raise DatasetError(f"{path}: truncated (element face)")
                arr = np.frombuffer(body, dt, count, offset)
                if count and np.any(arr["n"] != 3):
                    raise DatasetError(f"{path}: element face: only triangles are supported")
                out["faces"] = arr["i"].astype(np.int64)
                offset += nbytes
            continue
        if any(p[0] == "list" for p in props):
            raise DatasetError(f"{path}: element {name}: list properties are only supported for faces")
        names = [p[1] for p in props]
        if fmt == "ascii":
            n = len(props) * count
            if offset + n > len(tokens):
                raise DatasetError(f"{path}: truncated (element {name})")
            try:
                vals = np.asarray(tokens[offset : offset + n], np.float64).reshape(count, len(props))
            except ValueError as exc:
                raise DatasetError(f"{path}: element {name}: {exc}") from None
            offset += n
            cols = {k: vals[:, i] for i, k in enumerate(names)}
        else:
            dt = np.dtype([(k, "<" + _PLY_TYPES[p[0]]) for k, p in zip(names, props)])
            nbytes = dt.itemsize * count
            if offset + nbytes > len(body):
                raise DatasetError(f"{path}: truncated (element {name})")
            arr = np.frombuffer(body, dt, count, offset)
            offset += nbytes
            cols = {k: arr[k].astype(np.float64) for k in names}
        out[name] = cols
    if "vertex" not in out or "faces" not in out:
        raise DatasetError(f"{path}: needs 'vertex' and 'face' elements")
    v = out["vertex"]
    if not all(k in v for k in "xyz"):
        raise DatasetError(f"{path}: element vertex: missing x, y or z")
    verts = np.stack([v["x"], v["y"], v["z"]], 1)
    faces = out["faces"]
    if faces.size and (faces.min() < 0 or faces.max() >= len(verts)):
        raise DatasetError(f"{path}: element face: vertex index out of range")
    if unit_check and len(verts) and np.ptp(verts, axis=0).max() < _MIN_PLAUSIBLE_MM:
        raise DatasetError(
            f"{path}: element vertex: model is {np.ptp(verts, axis=0).max():.4g} units across; "
            "BOP models are in millimetres (wrong unit?)"
        )
    normals = np.stack([v["nx"], v["ny"], v["nz"]], 1) if all(k in v for k in ("nx", "ny", "nz")) else None
    colors = (
        np.stack([v["red"], v["green"], v["blue"]], 1).astype(np.uint8)
        if all(k in v for k in ("red", "green", "blue"))
        else None
    )
    tc = np.stack([v["texture_u"], v["texture_v"]], 1) if "texture_u" in v and "texture_v" in v else None
    return PlyModel(verts, faces, normals, colors, tc, texture_file)


def write_ply(path: str | os.PathLike, model: PlyModel, *, binary: bool = True) -> Path:
    """Write a PLY file atomically (binary little-endian by default, as BOP's models)."""

    path = Path(path)
    n = len(model.vertices)
    props: list[tuple[str, str, np.ndarray]] = [(k, "float", model.vertices[:, i]) for i, k in enumerate("xyz")]
    if model.normals is not None:
        props += [(k, "float", model.normals[:, i]) for i, k in enumerate(("nx", "ny", "nz"))]
    if model.colors is not None:
        props += [(k, "uchar", model.colors[:, i]) for i, k in enumerate(("red", "green", "blue"))]
    if model.texcoords is not None:
        props += [(k, "float", model.texcoords[:, i]) for i, k in enumerate(("texture_u", "texture_v"))]
    lines = ["ply", f"format {'binary_little_endian' if binary else 'ascii'} 1.0", "comment generated by alcn_cv"]
    if model.texture_file:
        lines.append(f"comment TextureFile {model.texture_file}")
    lines.append(f"element vertex {n}")
    lines += [f"property {t} {k}" for k, t, _ in props]
    lines += [f"element face {len(model.faces)}", "property list uchar int vertex_indices", "end_header"]
    head = ("\n".join(lines) + "\n").encode("ascii")
    if binary:
        vdt = np.dtype([(k, "<f4" if t == "float" else "u1") for k, t, _ in props])
        va = np.empty(n, vdt)
        for k, _, col in props:
            va[k] = col
        fdt = np.dtype([("n", "u1"), ("i", "<i4", 3)])
        fa = np.empty(len(model.faces), fdt)
        fa["n"] = 3
        fa["i"] = model.faces
        payload = va.tobytes() + fa.tobytes()
    else:
        rows = []
        for r in range(n):
            rows.append(" ".join(f"{float(c[r]):.6g}" if t == "float" else str(int(c[r])) for _, t, c in props))
        rows += [f"3 {a} {b} {c}" for a, b, c in model.faces]
        payload = ("\n".join(rows) + "\n").encode("ascii")
    return atomic_write(path, head + payload)


def models_info(models: dict[int, PlyModel]) -> dict[str, dict[str, float]]:
    """BOP ``models_info.json`` content: diameter and bounding box (mm) per object id."""
    from scipy.spatial import ConvexHull  # here: scipy.spatial takes 0.2 s to import, and only this needs it

    info = {}
    for oid, m in models.items():
        v = m.vertices
        lo, hi = v.min(0), v.max(0)
        # Diameter: largest vertex distance (exact on the convex hull's vertices).
        hull = v[ConvexHull(v).vertices] if len(v) > 4 else v
        d = np.sqrt(((hull[:, None] - hull[None]) ** 2).sum(-1)).max()
        info[str(oid)] = {
            "diameter": round(float(d), 6),
            "min_x": round(float(lo[0]), 6),
            "min_y": round(float(lo[1]), 6),
            "min_z": round(float(lo[2]), 6),
            "size_x": round(float(hi[0] - lo[0]), 6),
            "size_y": round(float(hi[1] - lo[1]), 6),
            "size_z": round(float(hi[2] - lo[2]), 6),
        }
    return info
