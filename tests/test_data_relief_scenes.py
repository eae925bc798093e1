"""Rendered registered scenes under many lights (alcn_cv.data.relief_scenes)."""

import jsonschema
import numpy as np
import pytest

from alcn_cv.data.manifest import MANIFEST_SCHEMA, read_manifest
from alcn_cv.data.relief_scenes import KIND, generate, render_scene
from alcn_cv.data.scenes import load_scene_folder
from alcn_cv.errors import InputError
from alcn_cv.io import read_json
from alcn_cv.train.real_light import training_scene


def test_a_scene_is_one_geometry_under_different_lights():
    frames, families = render_scene(np.random.default_rng(0), 64, 4, objects=(1, 2))
    assert frames.shape == (4, 64, 64) and frames.dtype == np.uint8 and len(families) == 4
    # Same scene, other light: the frames differ, but they stay correlated (registered content).
    f = frames.reshape(4, -1).astype(np.float64)
    assert len({f[i].mean().round(1) for i in range(4)}) > 1
    assert np.corrcoef(f).min() > -0.5


def test_render_scene_is_deterministic_and_checks_its_arguments():
    a, _ = render_scene(np.random.default_rng([3, 1]), 48, 2, objects=(1, 1))
    b, _ = render_scene(np.random.default_rng([3, 1]), 48, 2, objects=(1, 1))
    assert np.array_equal(a, b)
    with pytest.raises(InputError):
        render_scene(np.random.default_rng(0), 48, 1)


def test_generate_writes_folders_the_trainer_reads(tmp_path):
    out = generate(tmp_path / "scenes", scenes=2, frames=3, side=96, seed=5, progress=False)
    manifest = read_manifest(out, KIND)
    jsonschema.validate(manifest, read_json(MANIFEST_SCHEMA))
    assert sorted(manifest["lights"]) == ["scene_000", "scene_001"]
    scenes = load_scene_folder(out)
    assert [s.name for s in scenes] == ["scene_000", "scene_001"]
    scene = training_scene(scenes[1], 48, 32)
    assert scene.frames.shape == (3, 96 + 96, 96 + 96) and len(scene.candidates) > 0
    # Scene i depends on (seed, i) only: a run of one scene gives the same first scene.
    one = generate(tmp_path / "one", scenes=1, frames=3, side=96, seed=5, progress=False)
    assert (one / "scene_000" / "frame_02.png").read_bytes() == (out / "scene_000" / "frame_02.png").read_bytes()


def test_arguments_and_output_are_checked_before_the_progress_bar(tmp_path, monkeypatch, capsys):
    """The side in pixels (side), --frames and an output under a file fail in one line before any scene is
    rendered (the checks of render_scene run in the workers, after the bar has started)."""
    import alcn_cv.data.relief_scenes as relief_scenes
    from alcn_cv.cli import main

    blocker = tmp_path / "file.json"
    blocker.write_text("mine")
    monkeypatch.setattr(relief_scenes, "parallel_map", lambda *args, **kwargs: pytest.fail("rendered"))
    for side in (10, 2049):  # 100000 asked numpy for 149 GiB, a MemoryError traceback
        with pytest.raises(
            InputError, match=rf"--side is the side of the frames in pixels, from 32 to 2048; got {side}"
        ):
            generate(tmp_path / "s", side=side, progress=False)
    with pytest.raises(InputError, match=r"--frames"):
        generate(tmp_path / "s", frames=1, progress=False)
    with pytest.raises(InputError, match="is a file"):
        generate(blocker / "s", progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file.json"]
    (tmp_path / "done").mkdir()
    (tmp_path / "done" / "manifest.json").write_text("{}")
    with pytest.raises(FileExistsError, match="--overwrite"):  # an earlier output: refused before the rendering
        generate(tmp_path / "done", progress=False)
    # `data detect --conf small` is a preset; the frames' side here is --side, and argparse's error says what it is
    for bad in ("small", "10", "100000"):
        with pytest.raises(SystemExit) as exit_:
            main(["data", "scenes", "--side", bad, "--out", str(tmp_path / "s")])
        assert exit_.value.code == 2
        err = capsys.readouterr().err
        assert f"argument --side: an integer at least 32 and at most 2048, got '{bad}'" in err
    assert not (tmp_path / "s").exists()


def test_directional_scenes_are_the_gallery_then_the_probes(tmp_path):
    """--lighting directional: a frontal light, then AZIMUTHS probes per elevation; the folder holds what
    render_scenes gives in memory, and identification finds a scene's own gallery image."""
    from alcn_cv.bench.directional import identification
    from alcn_cv.data.relief_scenes import render_scenes
    from alcn_cv.data.relief_settings import AZIMUTHS, DIRECTIONAL_FRAMES, ELEVATIONS

    out = generate(tmp_path / "d", scenes=2, side=48, seed=7, lighting="directional", progress=False)
    manifest = read_manifest(out, KIND)
    jsonschema.validate(manifest, read_json(MANIFEST_SCHEMA))
    assert manifest["parameters"]["frames"] == DIRECTIONAL_FRAMES == 1 + len(ELEVATIONS) * AZIMUTHS
    assert manifest["lights"]["scene_001"] == ["ambient"] + ["side"] * (DIRECTIONAL_FRAMES - 1)
    memory = [frames for frames, _ in render_scenes(2, side=48, seed=7, lighting="directional", progress=False)]
    assert [s.frames.shape for s in load_scene_folder(out)] == [(DIRECTIONAL_FRAMES, 48, 48)] * 2
    assert all(np.array_equal(s.frames, m) for s, m in zip(load_scene_folder(out), memory))
    gallery_as_probes = np.stack(memory).astype(np.float32)
    gallery_as_probes[:, 1:] = gallery_as_probes[:, :1]
    assert identification(gallery_as_probes, 16) == {f"elevation {e}": 100.0 for e in ELEVATIONS}
    with pytest.raises(InputError, match=f"--lighting directional renders {DIRECTIONAL_FRAMES} frames"):
        generate(tmp_path / "e", frames=12, lighting="directional", progress=False)
    with pytest.raises(InputError, match="unknown --lighting 'sideways'"):
        render_scenes(1, lighting="sideways")
