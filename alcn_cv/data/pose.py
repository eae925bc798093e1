"""Box- and Duck-like pose sequences in the BOP layout (paper Sec. 4.4, Table 1).

A textured box (object 1, like the paper's Box dataset) and a duck built from ellipsoids
(object 2, like ALCN-Duck) stand on a cluttered table. A camera moves along an orbit around
them. The training sequence has one lighting; the eight test sequences have, as in the paper's
Table 1, #1 the training lighting, #2-#4 mild changes and #5-#8 drastic ones (grazing side light
with long shadows, a spot in the dark, coloured lights with a window-frame shadow, over-exposure
with a point light and blinds). Layout (BOP, millimetres, OpenCV intrinsics)::

    ROOT/manifest.json, ROOT/camera.json (BOP: fx, fy, cx, cy, width, height)
    ROOT/models/obj_000001.ply (+ obj_000001.png texture), obj_000002.ply, models_info.json
    ROOT/train/000001/{rgb/000000.png, mask_visib/, scene_camera.json, scene_gt.json,
                       scene_gt_info.json, colmap/{cameras,images,points3D}.txt}
    ROOT/test/000001 .. 000008/ (same, without colmap/)

``scene_camera.json`` holds ``cam_K``, ``depth_scale`` and the camera pose ``cam_R_w2c``/
``cam_t_w2c``; ``scene_gt.json`` the model-to-camera poses; ``mask_visib/<im>_<k>.png`` the visible
pixels of the k-th object of ``scene_gt``; the COLMAP model of the training sequence holds the
known poses (world frame in mm, image names relative to ``rgb/``) and an empty ``points3D.txt``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from alcn_cv.data.lighting import Light, Lighting, directional
from alcn_cv.data.manifest import atomic_output_dir, make_manifest
from alcn_cv.data.parallel import parallel_map
from alcn_cv.data.pose_settings import CONFS, PoseConfig
from alcn_cv.data.raster import (
    Mesh,
    SceneObject,
    ShadowSettings,
    TableScene,
    box_mesh,
    ellipsoid_mesh,
    look_at,
    merge_meshes,
    render_frame,
)
from alcn_cv.data.render import Material
from alcn_cv.data.textures import colour_jitter, photo_crop, procedural_texture, random_texture
from alcn_cv.errors import InputError
from alcn_cv.formats.bop import (
    BopFrame,
    BopObjectPose,
    PlyModel,
    models_info,
    write_camera,
    write_ply,
    write_scene,
)
from alcn_cv.formats.colmap import ColmapImage, camera_from_opencv, write_text_model
from alcn_cv.io import write_image, write_json
from alcn_cv.presets import preset_named, with_given

__all__ = [
    "BOX_SIZE_MM",
    "make_box",
    "make_duck",
    "make_scene",
    "sequence_lighting",
    "trajectory",
    "TRAIN_SWEEPS",
    "generate",
]

#: The box's size (x, y, z) in mm.
BOX_SIZE_MM = (140.0, 95.0, 55.0)
#: Test sequences' lighting: #1 = training, #2-#4 mild, #5-#8 drastic.
SEQUENCE_KINDS = (
    "train",
    "mild_direction",
    "mild_fill",
    "mild_dim",
    "side",
    "spot_dark",
    "colour_window",
    "overexposed_blinds",
)


def _face_texture(rng: np.random.Generator, t: int, kind: str) -> np.ndarray:
    if kind == "top":
        tex = colour_jitter(rng, photo_crop(rng, t), 0.5)
        marks = procedural_texture(rng, t, "print")
        alpha = (np.abs(marks - marks[0, 0]).sum(-1, keepdims=True) > 0.05).astype(np.float32) * 0.85
        return tex * (1 - alpha) + marks * alpha
    return random_texture(rng, t, p_photo=0.5)


def make_box(rng: np.random.Generator, texel: int = 256) -> Mesh:
    """The textured box (object 1): printed photographs and patterns on its six faces."""
    cells = [_face_texture(rng, texel, "top" if k in (0, 2, 4) else "side") for k in range(6)]
    atlas = np.concatenate([np.concatenate(cells[:3], 1), np.concatenate(cells[3:], 1)], 0)
    return box_mesh(BOX_SIZE_MM, atlas, Material("plastic", diffuse=0.9, specular=0.12, shininess=30.0))


def make_duck() -> Mesh:
    """The duck (object 2): body, head, beak, eyes and tail ellipsoids; yellow glossy plastic."""
    plastic = Material("plastic", diffuse=0.9, specular=0.45, shininess=60.0)
    yellow, orange, black = (0.75, 0.5, 0.03), (0.85, 0.2, 0.02), (0.01, 0.01, 0.01)
    parts = [
        ellipsoid_mesh((0, 0, 33), (58, 40, 33), yellow, plastic, segments=32, rings=20),
        ellipsoid_mesh((-52, 0, 48), (16, 12, 12), yellow, plastic),
        ellipsoid_mesh((36, 0, 80), (25, 23, 24), yellow, plastic, segments=28, rings=18),
        ellipsoid_mesh((63, 0, 74), (17, 10, 5), orange, plastic),
        ellipsoid_mesh((52, 13, 88), (4, 4, 4), black, plastic, segments=12, rings=8),
        ellipsoid_mesh((52, -13, 88), (4, 4, 4), black, plastic, segments=12, rings=8),
    ]
    duck = merge_meshes(parts)
    lo, hi = duck.vertices.min(0), duck.vertices.max(0)
    duck.vertices = duck.vertices - (lo + hi) / 2  # model frame at its bounding-box centre
    return duck


def _yaw(deg: float) -> np.ndarray:
    a = np.deg2rad(deg)
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])


def make_scene(
    seed: int, clutter_seed: int, *, clutter: bool = True, texel: int = 256, table_px: int = 1024
) -> TableScene:
    """The table-top scene: box and duck (fixed by ``seed``), clutter and table by ``clutter_seed``.

    ``texel`` is the side of each box face's texture, ``table_px`` that of the table's texture.
    """
    rng = np.random.default_rng([seed, 11])
    box, duck = make_box(rng, texel), make_duck()
    objs = [
        SceneObject(box, _yaw(20.0), np.array([-95.0, -25.0, BOX_SIZE_MM[2] / 2]), 1),
        SceneObject(duck, _yaw(-35.0), np.array([95.0, 30.0, -duck.vertices[:, 2].min()]), 2),
    ]
    crng = np.random.default_rng([seed, 12, clutter_seed])
    if clutter:
        for _ in range(int(crng.integers(5, 10))):
            for _ in range(30):
                r, a = crng.uniform(190, 380), crng.uniform(0, 2 * np.pi)
                pos = np.array([r * np.cos(a), r * np.sin(a)])
                if all(np.linalg.norm(pos - o.t[:2]) > 120 for o in objs):
                    break
            flat = crng.random() < 0.4
            size = (crng.uniform(50, 160), crng.uniform(40, 120), 1.0) if flat else tuple(crng.uniform(20, 70, 3))
            t = max(16, int(max(size[:2]) / 2 * texel / 256))
            atlas = np.concatenate(
                [
                    np.concatenate([random_texture(crng, t) for _ in range(3)], 1),
                    np.concatenate([random_texture(crng, t) for _ in range(3)], 1),
                ],
                0,
            )
            mat = Material(
                str(crng.choice(["matte", "plastic"])), 0.9, float(crng.uniform(0, 0.4)), float(crng.uniform(10, 80))
            )
            objs.append(
                SceneObject(
                    box_mesh(size, atlas, mat), _yaw(crng.uniform(0, 360)), np.array([pos[0], pos[1], size[2] / 2]), 0
                )
            )
    table = random_texture(crng, table_px, p_photo=0.6)
    return TableScene(
        objs,
        table,
        table_mm_per_px=float(crng.uniform(0.6, 1.5)) * 1024 / table_px,
        table_material=Material("matte", 1.0, float(crng.uniform(0.0, 0.15)), 20.0),
        wall=tuple(float(c) for c in crng.uniform(0.05, 0.4, 3)),
    )


#: Elevation sweeps of the training sequence's loops around the objects: the camera circles them
#: once with its elevation going up and down once, as the test trajectories do, then again with
#: it going up and down three times, so that every stretch of azimuth is seen from high and low
#: too (``pose/corner_train.py`` has the measurements).
TRAIN_SWEEPS = (1, 3)


def trajectory(
    n: int, rng: np.random.Generator, *, span_deg: float | None = None, elevation_cycles: float = 1.0
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Camera poses of an orbit around the objects: n (R_w2c, t_w2c) pairs (mm).

    The camera turns by ``span_deg`` (random in 120-300 deg when None) at 520-680 mm from the
    objects, its elevation going ``elevation_cycles`` times up and down between 30 and 60 deg.
    """
    a0 = rng.uniform(0, 360)
    span = span_deg if span_deg is not None else rng.uniform(120, 300)
    ph1, ph2 = rng.uniform(0, 2 * np.pi, 2)
    poses = []
    for f in range(n):
        s = f / max(n - 1, 1)
        az = np.deg2rad(a0 + span * s)
        el = np.deg2rad(45 + 15 * np.sin(2 * np.pi * elevation_cycles * s + ph1))
        d = 600 + 80 * np.sin(2 * np.pi * 1.5 * s + ph2)
        eye = np.array([d * np.cos(el) * np.cos(az), d * np.cos(el) * np.sin(az), d * np.sin(el)])
        target = np.array([15 * np.sin(6 * s + ph1), 15 * np.cos(5 * s + ph2), 35.0])
        poses.append(look_at(eye, target))
    return poses


def _train_lighting() -> Lighting:
    return Lighting(
        "ambient",
        [directional(60.0, 65.0, (0.9, 0.9, 0.9))],
        np.full(3, 0.25, np.float32),
        gain=1.0,
        gamma=2.2,
        shot_noise=5e-4,
        read_noise=1.5e-3,
    )


def sequence_lighting(index: int, rng: np.random.Generator) -> Lighting:
    """Lighting of test sequence ``index`` (1..8, :data:`SEQUENCE_KINDS`; 0 = training)."""
    base = _train_lighting()
    if index <= 1:
        return base
    j = lambda lo, hi: float(rng.uniform(lo, hi))  # noqa: E731
    noise = dict(shot_noise=j(4e-4, 2e-3), read_noise=j(1e-3, 4e-3))
    kind = SEQUENCE_KINDS[(index - 1) % len(SEQUENCE_KINDS)]
    if kind == "mild_direction":
        return Lighting(
            "ambient",
            [directional(60 + j(30, 50), j(45, 55), (0.95, 0.88, 0.78))],
            np.full(3, 0.22, np.float32),
            gain=j(0.85, 1.1),
            **noise,
        )
    if kind == "mild_fill":
        return Lighting(
            "mixed",
            [directional(60, 65, (1.0, 1.0, 1.0)), directional(240 + j(-20, 20), j(30, 45), (0.25, 0.28, 0.35))],
            np.full(3, 0.18, np.float32),
            gain=j(0.9, 1.1),
            **noise,
        )
    if kind == "mild_dim":
        return Lighting(
            "dark",
            [directional(j(0, 40), j(70, 80), (0.8, 0.85, 1.0))],
            np.full(3, 0.2, np.float32),
            gain=j(0.45, 0.6),
            **noise,
        )
    if kind == "side":
        return Lighting(
            "side",
            [directional(j(0, 360), j(14, 20), (1.5, 1.45, 1.3))],
            np.full(3, 0.03, np.float32),
            gain=1.0,
            **noise,
        )
    if kind == "spot_dark":
        a = np.deg2rad(j(0, 360))
        pos = (450 * np.cos(a), 450 * np.sin(a), 500.0)
        axis = -np.asarray(pos) / np.linalg.norm(pos)
        return Lighting(
            "spot",
            [Light("spot", pos, (6.0, 5.6, 5.0), 500.0, tuple(axis), 24.0, 8.0)],
            np.full(3, 0.01, np.float32),
            gain=j(0.6, 0.8),
            **noise,
        )
    if kind == "colour_window":
        return Lighting(
            "colour",
            [
                directional(j(150, 210), j(35, 50), (1.1, 0.25, 0.15)),
                directional(j(-30, 30), j(35, 50), (0.15, 0.35, 1.2)),
            ],
            np.array([0.05, 0.03, 0.08], np.float32),
            gain=1.0,
            shadow_shape="window",
            **noise,
        )
    # overexposed_blinds
    a = np.deg2rad(j(0, 360))
    return Lighting(
        "bright",
        [
            directional(j(0, 360), j(55, 75)),
            Light("point", (250 * np.cos(a), 250 * np.sin(a), 300.0), (1.5, 1.4, 1.3), 350.0),
        ],
        np.full(3, 0.2, np.float32),
        gain=j(2.5, 3.5),
        shadow_shape="blinds",
        **noise,
    )


def _write_sequence(
    seq_dir: Path,
    scene: TableScene,
    poses: Sequence[tuple[np.ndarray, np.ndarray]],
    lighting: Lighting,
    cfg: PoseConfig,
    seed_key: tuple,
) -> list[BopFrame]:
    (seq_dir / "rgb").mkdir(parents=True)
    (seq_dir / "mask_visib").mkdir()
    frames, info = [], {}
    K = cfg.K
    placed = [o for o in scene.objects if o.obj_id > 0]
    for f, (R, t) in enumerate(poses):
        rng = np.random.default_rng([*seed_key, f])
        img, obj_id = render_frame(
            scene,
            K,
            R,
            t,
            cfg.width,
            cfg.height,
            lighting,
            rng,
            ShadowSettings(res=cfg.shadow_res, gobo_seed=seed_key[0]),
        )
        write_image(seq_dir / "rgb" / f"{f:06d}.png", img)
        objs, inf = [], []
        for k, o in enumerate(placed):
            objs.append(BopObjectPose(o.obj_id, R @ o.R, R @ o.t + t))
            m = (obj_id == o.obj_id).astype(np.uint8) * 255
            write_image(seq_dir / "mask_visib" / f"{f:06d}_{k:06d}.png", m)
            ys, xs = np.nonzero(m)
            box = (
                [int(xs.min()), int(ys.min()), int(xs.max() - xs.min() + 1), int(ys.max() - ys.min() + 1)]
                if len(xs)
                else [-1, -1, 0, 0]
            )
            inf.append({"bbox_visib": box, "px_count_visib": int(len(xs))})
        info[str(f)] = inf
        frames.append(BopFrame(f, seq_dir / "rgb" / f"{f:06d}.png", K, 1.0, objs, R, t))
    write_scene(seq_dir, frames)
    write_json(seq_dir / "scene_gt_info.json", info, indent=None)
    return frames


def _write_models(models_dir: Path, scene: TableScene) -> None:
    models_dir.mkdir(parents=True)
    plys = {}
    for o in scene.objects:
        if o.obj_id == 0:
            continue
        m = o.mesh
        name = f"obj_{o.obj_id:06d}"
        if m.texture is not None:
            h, w = m.texture.shape[:2]
            tc = np.stack([(m.uv[:, 0] + 0.5) / w, 1.0 - (m.uv[:, 1] + 0.5) / h], 1)
            enc = np.rint(np.clip(m.texture, 0, 1) ** (1 / 2.2) * 255).astype(np.uint8)[..., ::-1]
            write_image(models_dir / f"{name}.png", enc)
            ply = PlyModel(m.vertices, m.faces, None, None, tc, f"{name}.png")
        else:
            cols = np.rint(np.clip(m.colors, 0, 1) ** (1 / 2.2) * 255).astype(np.uint8)
            ply = PlyModel(m.vertices, m.faces, m.normals, cols)
        write_ply(models_dir / f"{name}.ply", ply)
        plys[o.obj_id] = ply
    write_json(models_dir / "models_info.json", models_info(plys))


def _sequence_job(job: tuple) -> tuple[list[BopFrame], dict]:
    """Render sequence ``k`` (0: training, also writing the models) into the dataset root."""
    k, root, seed, cfg, clutter, training_light, train_sweeps = job
    root = Path(root)
    scene = make_scene(seed, k, clutter=clutter, texel=cfg.texel, table_px=cfg.table_px)
    if k == 0:
        _write_models(root / "models", scene)
        poses = [
            camera_pose
            for cycles in train_sweeps  # every loop starts where the first does
            for camera_pose in trajectory(
                cfg.n_frames, np.random.default_rng([seed, 20]), span_deg=330.0, elevation_cycles=cycles
            )
        ]
        light = _train_lighting()
        frames = _write_sequence(root / "train" / "000001", scene, poses, light, cfg, (seed, 30))
    else:
        light = _train_lighting() if training_light else sequence_lighting(k, np.random.default_rng([seed, 40, k]))
        poses = trajectory(cfg.n_frames, np.random.default_rng([seed, 50, k]))
        frames = _write_sequence(root / "test" / f"{k:06d}", scene, poses, light, cfg, (seed, 60, k))
    return frames, light.describe()


def generate(
    out_dir: str | os.PathLike,
    *,
    seed: int = 0,
    conf: str = "default",
    n_frames: int | None = None,
    n_test: int | None = None,
    clutter: bool = True,
    training_light: bool = False,
    train_sweeps: Sequence[float] = TRAIN_SWEEPS,
    overwrite: bool = False,
    progress: bool = True,
    workers: int = 1,
) -> Path:
    """Render the training and test sequences into ``out_dir`` (BOP layout, atomically).

    Args:
        out_dir: dataset root.
        seed: seed of everything (same seed and parameters give the same bytes).
        conf: a preset of :data:`CONFS`, the values of ``n_frames`` and ``n_test`` when not given.
        n_frames: frames per test sequence and per loop of the training sequence (default: the preset's).
        n_test: number of test sequences (default: the preset's; #k uses lighting ``SEQUENCE_KINDS[k-1]``).
        clutter: put clutter on the table.
        training_light: render every test sequence under the training lighting: the control of
            the same seed's dataset (the same scenes, trajectories and noise), so that what a
            method loses from the control to the dataset is what the light changes cost it.
        train_sweeps: the training sequence's loops around the objects, ``n_frames`` views each,
            by the up-and-down sweeps of their elevation (:data:`TRAIN_SWEEPS`; ``(1,)``: a single
            loop). The test sequences do not depend on it.
        overwrite: replace an existing folder.
        progress: show a progress bar.
        workers: worker processes, one sequence each (the output does not depend on it).

    Raises:
        InputError: an unknown preset (:func:`~alcn_cv.presets.preset_named`), or a value out of range.
    """
    cfg = with_given(preset_named(CONFS, conf), n_frames=n_frames, n_test=n_test)
    if cfg.n_frames < 1 or not 0 <= cfg.n_test <= len(SEQUENCE_KINDS):
        raise InputError(
            f"need frames >= 1 (--frames) and 0 <= test sequences <= {len(SEQUENCE_KINDS)} (--n-test); "
            f"got {cfg.n_frames} and {cfg.n_test}"
        )
    train_sweeps = tuple(float(c) for c in train_sweeps)
    if not train_sweeps or not all(np.isfinite(c) and c >= 0 for c in train_sweeps):  # inf: NaN elevations
        raise InputError(
            f"the training sweeps (--train-sweeps) must be one or more finite numbers >= 0, got "
            f"{' '.join(f'{c:g}' for c in train_sweeps)}"
        )
    sequences = []
    with atomic_output_dir(out_dir, overwrite=overwrite) as tmp:
        write_camera(tmp, cfg.K, cfg.width, cfg.height)
        jobs = [(k, str(tmp), seed, cfg, clutter, training_light, train_sweeps) for k in range(cfg.n_test + 1)]
        results = parallel_map(
            _sequence_job, jobs, workers=workers, desc="pose sequences", unit="seq", progress=progress
        )
        for k, (frames, light) in enumerate(results):
            if k == 0:
                seq = tmp / "train" / "000001"
                cam = camera_from_opencv(cfg.K, None, cfg.width, cfg.height, camera_id=1)
                images = [ColmapImage(f.im_id + 1, f.rgb_path.name, 1, f.R_w2c, f.t_w2c) for f in frames]
                write_text_model(seq / "colmap", [cam], images, units="mm")
                sequences.append({"split": "train", "scene_id": 1, "kind": "train", "lighting": light})
            else:
                sequences.append(
                    {
                        "split": "test",
                        "scene_id": k,
                        "kind": SEQUENCE_KINDS[k - 1],
                        "change": "none" if k == 1 or training_light else ("mild" if k <= 4 else "drastic"),
                        "lighting": light,
                    }
                )
        write_json(
            tmp / "manifest.json",
            make_manifest(
                "pose",
                seed,
                {
                    "conf": conf,
                    "width": cfg.width,
                    "height": cfg.height,
                    "focal": cfg.focal,
                    "n_frames": cfg.n_frames,
                    "n_test": cfg.n_test,
                    "clutter": clutter,
                    "training_light": training_light,
                    "train_sweeps": list(train_sweeps),
                },
                units="mm",
                camera_convention="OpenCV pinhole, pixel centre (0, 0); COLMAP model: cx + 0.5",
                objects=[{"obj_id": 1, "name": "box", "size_mm": list(BOX_SIZE_MM)}, {"obj_id": 2, "name": "duck"}],
                sequences=sequences,
                colmap={"train/000001": "train/000001/colmap (images relative to rgb/)"},
            ),
        )
    return Path(out_dir)
