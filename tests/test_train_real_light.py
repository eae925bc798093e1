"""Training the gain Normalizer on registered real scenes (alcn_cv.train.real_light), on a tiny synthetic set."""

import json
import shlex

import numpy as np
import pytest
import torch

from alcn_cv.data.scenes import load_scene_folder
from alcn_cv.filters.torch_divisive import gaussian_energy
from alcn_cv.nets.gain import GainNormalizer
from alcn_cv.train.checkpoint import CHECKPOINT_FORMAT, load_checkpoint
from alcn_cv.train.real_light import (
    RealLightConfig,
    TrainingScene,
    _normalized_centres,
    anywhere_locations,
    consistency_loss,
    draw_step,
    harris_response,
    identification_loss,
    pair_loss,
    repeatability_loss,
    sample_locations,
    textured_locations,
    textured_share,
    train_real_light,
    training_scene,
    training_scenes,
)
from alcn_cv.weight_file import load_normalizer_file
from scene_sets import write_scene

CROP, PATCH = 96, 32


def test_textured_locations_and_sampling():
    frames = np.zeros((2, 64, 80), np.float32)
    frames[:, 20:44, 40:70] = np.random.default_rng(0).random((24, 30))
    centres = textured_locations(frames, 16, step=4)
    assert len(centres) and (centres[:, 0] >= 8).all() and (centres[:, 1] <= 72).all()
    # where the 16x16 patch meets the texture (rows 20:44, cols 40:70, half a patch around them) ...
    assert ((centres[:, 0] >= 20 - 8) & (centres[:, 0] <= 44 + 8)).all()
    assert ((centres[:, 1] >= 40 - 8) & (centres[:, 1] <= 70 + 8)).all()
    kept = set(map(tuple, centres.tolist()))
    assert (8, 8) not in kept and (56, 16) not in kept  # flat windows
    assert all((y, x) in kept for y in (28, 32, 36) for x in (48, 52, 56, 60))  # windows wholly in the texture
    # ... and of those, the more textured half (quantile 0.5) of the grid's 13 x 17 windows: not every one touched
    windows = len(range(8, 64 - 8 + 1, 4)) * len(range(8, 80 - 8 + 1, 4))
    assert windows / 2 <= len(centres) <= 0.52 * windows
    picked = sample_locations(centres, 50, 12, np.random.default_rng(0))
    assert 1 < len(picked) <= 50
    gaps = np.abs(picked[:, None] - picked[None]).max(-1) + 1000 * np.eye(len(picked))
    assert gaps.min() >= 12


def test_a_flat_scene_is_named_not_trained_on_with_a_nan_loss():
    """No textured location: nothing to identify, and the loss of no classes is NaN (it reached the weights)."""
    from alcn_cv.data.scenes import Scene
    from alcn_cv.errors import DatasetError

    flat = Scene("flat", "test", np.full((3, 64, 64), 128, np.uint8), ("a.png", "b.png", "c.png"))
    with pytest.raises(DatasetError, match="'flat' has 0 textured 32x32"):
        training_scene(flat, CROP // 2, PATCH)
    assert torch.isnan(identification_loss(torch.zeros(0, 1, 4, 4), torch.zeros(0, 1, 4, 4), 0.05))


@pytest.mark.parametrize(
    "change, match",
    [
        ({"anywhere": -1}, "anywhere"),
        ({"relit": -1}, "relit"),
        ({"temperature": 0.0}, "temperature"),
        ({"relit": 1}, r"relit must be 0 \(no relit copies\) or at least 2"),  # was let through, to fail later
    ],
)
def test_settings_out_of_range_are_named(change, match):
    from dataclasses import replace

    from alcn_cv.errors import InputError

    with pytest.raises(InputError, match=match):
        replace(RealLightConfig(), **change).check()


def test_identification_loss_prefers_matching_patches():
    a = torch.randn(16, 1, 8, 8)
    assert identification_loss(a, a * 3 + 1, 0.05) < 1e-3  # NCC ignores gain and offset
    assert identification_loss(a, torch.randn(16, 1, 8, 8), 0.05) > 1.0


def test_consistency_loss_is_zero_when_equal_and_scale_free():
    a = torch.randn(8, 1, 8, 8)
    assert float(consistency_loss(a, a)) == 0.0
    b = torch.randn(8, 1, 8, 8)
    assert float(consistency_loss(a, b)) == pytest.approx(float(consistency_loss(10 * a, 10 * b)), rel=1e-5)
    assert 0.5 < float(consistency_loss(a, b)) < 1.5  # unrelated outputs: about 1
    # Unlike identification, it sees a gain between the frames.
    assert float(consistency_loss(a, 3 * a)) == pytest.approx(0.4) and identification_loss(a, 3 * a, 0.05) < 1e-3


def test_harris_response_peaks_at_a_corner_and_repeatability_sees_what_moves():
    square = torch.zeros(1, 1, 32, 32)
    square[..., 10:, 10:] = 1.0
    response = harris_response(square)[0, 0]
    peak = np.unravel_index(int(response.argmax()), response.shape)
    assert abs(peak[0] - 9.5) <= 1.5 and abs(peak[1] - 9.5) <= 1.5  # the corner, not the edges
    assert float(response[20, 5:15].max()) < 0.1 * float(response.max())  # an edge is no corner
    assert float(repeatability_loss(square, 2.0 * square)) > 0.5  # Harris is quartic: a gain changes it
    assert float(repeatability_loss(square, square)) == 0.0
    noisy = square + 0.3 * torch.randn(1, 1, 32, 32, generator=torch.Generator().manual_seed(0))
    other = square + 0.3 * torch.randn(1, 1, 32, 32, generator=torch.Generator().manual_seed(1))
    assert float(repeatability_loss(noisy, other)) > float(repeatability_loss(square + 0.3, square + 0.3))


def test_pair_loss_adds_the_weighted_repeatability(tmp_path):
    scene = training_scene(load_scene_folder(write_scene(tmp_path / "s"))[0], CROP // 2, PATCH)
    net = GainNormalizer(stride=8)
    centres = sample_locations(scene.candidates, 6, 16, np.random.default_rng(0))
    with torch.no_grad():
        plain = float(pair_loss(net, scene, (0, 1), centres, RealLightConfig(crop=CROP, patch=PATCH)))
        both = float(pair_loss(net, scene, (0, 1), centres, RealLightConfig(crop=CROP, patch=PATCH, repeatability=2.0)))
    assert both > plain


def test_training_scenes_add_the_relit_photographs(tmp_path, monkeypatch):
    from alcn_cv.data.permissive_images import Photograph, relit_scenes
    from alcn_cv.train import real_light

    photo = Photograph("photo", np.random.default_rng(0).integers(0, 256, (170, 180), dtype=np.uint8), "CC0", "test")
    monkeypatch.setattr(real_light, "training_photographs", lambda shared: [photo])
    scene_dir = write_scene(tmp_path / "s", h=160, w=170)  # at least the crop (160) on a side
    cfg = RealLightConfig(scenes=[str(scene_dir)], relit=3, light="hard", jitter=1.0, seed=7)
    scenes, rendered = training_scenes(cfg)
    assert [s.name for s in scenes] == ["s", "00_photo"] and rendered == []
    assert scenes[1].frames.shape == (3, 170 + 160, 180 + 160)  # padded by crop // 2
    (expected,) = relit_scenes([photo], 3, 7, "hard", 1.0)
    np.testing.assert_array_equal(scenes[1].frames[:, 80:-80, 80:-80], expected.unit_frames())

    scene = training_scene(load_scene_folder(write_scene(tmp_path / "scene"))[0], CROP // 2, PATCH)
    centres = anywhere_locations(scene, 500, np.random.default_rng(0))
    _, h, w = scene.frames.shape
    assert centres.shape == (500, 2)
    assert (
        centres.min() >= scene.pad and (centres[:, 0] < h - scene.pad).all() and (centres[:, 1] < w - scene.pad).all()
    )


def test_pair_loss_adds_the_weighted_consistency(tmp_path):
    scene = training_scene(load_scene_folder(write_scene(tmp_path / "scene"))[0], CROP // 2, PATCH)
    net = GainNormalizer(channels=8)
    rng = np.random.default_rng(0)
    centres = sample_locations(scene.candidates, 8, 8, rng)
    anywhere = anywhere_locations(scene, 4, rng)
    base = RealLightConfig(crop=CROP, patch=PATCH, temperature=0.5, consistency=0.0)
    weighted = RealLightConfig(crop=CROP, patch=PATCH, temperature=0.5, consistency=2.0)
    with torch.no_grad():
        plain = float(pair_loss(net, scene, (0, 1), centres, base, anywhere))
        both = float(pair_loss(net, scene, (0, 1), centres, weighted, anywhere))
        every = np.concatenate([centres, anywhere])
        outputs = [
            _normalized_centres(
                net,
                torch.from_numpy(
                    np.stack(
                        [
                            scene.frames[f][y - CROP // 2 : y + CROP // 2, x - CROP // 2 : x + CROP // 2]
                            for y, x in every
                        ]
                    )
                )[:, None],
                PATCH,
                [(slice(None), slice(len(centres), None))],
            )
            for f in (0, 1)
        ]
    assert both == pytest.approx(plain + 2.0 * float(consistency_loss(*outputs)), rel=1e-4)


def test_per_pixel_divisive_centres_equal_the_whole_normalization_with_the_crops_floor():
    """The training path of the per-pixel divisive energy: the response on the Gaussian's reach
    around the centre, the floor from the centres of the crops drawn for it."""
    net = GainNormalizer(stride=8, floor_scale=0.7)
    with torch.no_grad():
        net.head.weight.normal_(0.0, 0.05)
    crops = torch.rand(4, 1, CROP, CROP) * torch.tensor([1.0, 0.2, 0.5, 0.05]).view(4, 1, 1, 1)
    lo = (CROP - PATCH) // 2
    centre_of = (..., slice(lo, lo + PATCH), slice(lo, lo + PATCH))
    with torch.no_grad():
        centre = _normalized_centres(net, crops, PATCH, [(slice(0, 2), slice(1, 2)), (slice(2, 4), slice(2, 4))])
        response = net.response(crops)
        energy = gaussian_energy(response, 2.0)[centre_of]
        floor = 0.7 * torch.stack([energy[1].mean(), energy[1].mean(), energy[2:].mean(), energy[2:].mean()]).view(
            4, 1, 1, 1
        )
        expected = net.equalize(net.divide(response, floor))[centre_of]
    torch.testing.assert_close(centre, expected, atol=1e-5, rtol=1e-4)


def test_cli_runs_the_preset_with_its_settings(tmp_path, monkeypatch):
    import alcn_cv.train.real_light as real_light
    from alcn_cv.cli import main

    runs = []
    monkeypatch.setattr(real_light, "train_real_light", lambda cfg, out, **record: runs.append((cfg, record)) or out)
    common = ["train-real-light", "--out", str(tmp_path / "run")]
    assert main([*common, "--set", f"scenes=['{tmp_path}']", "--set", "net.stride=16", "--seed", "3"]) == 0
    assert main(common) == 0
    (changed, record), (preset, _) = runs
    assert preset == RealLightConfig() and preset.net["divisive_sigma"] == 2.0
    assert (changed.net["stride"], changed.seed, changed.scenes) == (16, 3, [str(tmp_path)])
    words = [
        "alcn",
        "train-real-light",
        "--conf",
        "gain",
        "--set",
        f"scenes=['{tmp_path}']",
        "--set",
        "net.stride=16",
        "--seed",
        "3",
    ]
    assert record == {
        "conf": "gain",
        "command": shlex.join(words),
        "progress": True,
        "resume": False,
        "overwrite": False,
        "checkpoint": None,
    }
    assert main([*common, "--no-progress"]) == 0 and runs[-1][1]["progress"] is False
    # (--resume without --conf takes the checkpoint's settings: tests/test_train_real_light_run.py)
    assert main([*common, "--resume", "--conf", "gain"]) == 0 and runs[-1][1]["resume"] is True
    assert main([*common, "--overwrite"]) == 0 and runs[-1][1]["overwrite"] is True


def _tiny(scene_dir, **changes) -> RealLightConfig:
    """A run of a few steps on one written scene (:func:`~scene_sets.write_scene`)."""
    settings = {"steps": 3, "save_every": 3, "locations": 16, "min_distance": 8, "temperature": 0.5, "lr": 0.02}
    return RealLightConfig(
        scenes=[str(scene_dir)], relit=0, crop=CROP, patch=PATCH, net={"channels": 8}, **{**settings, **changes}
    )


def test_three_steps_lower_the_loss(tmp_path):
    torch.set_num_threads(1)
    scene_dir = write_scene(tmp_path / "scene")
    cfg = _tiny(scene_dir)
    path = train_real_light(cfg, tmp_path / "run")
    weight_file = load_normalizer_file(path)
    assert weight_file.meta["trained"] and weight_file.meta["architecture"] == "gain"
    assert (tmp_path / "run" / "checkpoint.pt").is_file() and (tmp_path / "run" / "history.json").is_file()
    trained = GainNormalizer.from_file(weight_file)
    untrained = GainNormalizer(**weight_file.meta["config"])  # the zero last layer: Weber gain + DoG 1/2
    scene = training_scene(load_scene_folder(scene_dir)[0], CROP // 2, PATCH)
    rng = np.random.default_rng(1)
    losses = {"untrained": 0.0, "trained": 0.0}
    with torch.no_grad():
        for _ in range(4):
            centres = sample_locations(scene.candidates, 16, 8, rng)
            pair = tuple(rng.choice(len(scene.frames), 2, replace=False))
            losses["untrained"] += float(pair_loss(untrained, scene, pair, centres, cfg))
            losses["trained"] += float(pair_loss(trained, scene, pair, centres, cfg))
    assert losses["trained"] < losses["untrained"]


def test_a_run_folder_holds_one_run(tmp_path, caplog):
    """A second run into a folder replaces the first's log and removes its step snapshots, which the second run's
    would not all replace (another save_every or fewer steps); a resumed run of `alcn train` appends to its log."""
    import dataclasses
    import logging

    from alcn_cv.errors import InputError
    from alcn_cv.report import log_to
    from alcn_cv.train.config import REAL_LIGHT_CONFS
    from alcn_cv.train.real_light import training_run

    (tmp_path / "train.log").write_text("the first log\n")
    (tmp_path / "gain_normalizer_step4.npz").write_bytes(b"")
    (tmp_path / "mine.npz").write_bytes(b"")
    with training_run(REAL_LIGHT_CONFS["gain"], tmp_path):
        logging.getLogger("alcn_cv.test").info("this run")
    log = (tmp_path / "train.log").read_text()
    assert "first log" not in log and "this run" in log and "removed 1 step snapshots" in log
    assert sorted(p.name for p in tmp_path.glob("*.npz")) == ["mine.npz"]
    with (
        pytest.raises(InputError, match="save_every >= 1"),
        training_run(dataclasses.replace(REAL_LIGHT_CONFS["gain"], save_every=0), tmp_path / "never"),
    ):
        pass
    assert not (tmp_path / "never").exists()  # checked before the folder is made
    with log_to(tmp_path / "train.log", append=True):
        logging.getLogger("alcn_cv.test").info("resumed")
    assert "this run" in (tmp_path / "train.log").read_text()


def test_a_resumed_run_ends_as_an_uninterrupted_one(tmp_path, monkeypatch):
    """train-real-light wrote checkpoint.pt and could not resume from it: now --resume goes on from its step, the
    draws and Adam's state restored, to the same weights."""
    import dataclasses

    import alcn_cv.train.real_light as real_light
    from alcn_cv.errors import WeightFileError

    torch.set_num_threads(1)
    cfg = _tiny(write_scene(tmp_path / "scene"), steps=4, save_every=2)
    whole = load_normalizer_file(train_real_light(cfg, tmp_path / "whole")).arrays
    draw_step = real_light.draw_step
    calls = []

    def stopped_at_step_3(*args):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return draw_step(*args)

    monkeypatch.setattr(real_light, "draw_step", stopped_at_step_3)
    with pytest.raises(KeyboardInterrupt):
        train_real_light(cfg, tmp_path / "resumed")
    calls.clear()
    monkeypatch.setattr(real_light, "draw_step", lambda *args: calls.append(1) or draw_step(*args))
    resumed = load_normalizer_file(train_real_light(cfg, tmp_path / "resumed", resume=True)).arrays
    assert len(calls) == 2  # steps 3 and 4 only: it went on from the checkpoint of step 2
    for key, value in whole.items():
        np.testing.assert_array_equal(resumed[key], value, err_msg=key)
    history = json.loads((tmp_path / "resumed" / "history.json").read_text())
    assert [h["step"] for h in history] == [1, 2, 3, 4]
    with pytest.raises(WeightFileError, match="differs in lr"):
        train_real_light(dataclasses.replace(cfg, lr=0.01), tmp_path / "resumed", resume=True)
    with pytest.raises(WeightFileError, match="not found"):
        train_real_light(cfg, tmp_path / "never", resume=True)
    path = tmp_path / "resumed" / "checkpoint.pt"
    torch.save({**torch.load(path, weights_only=True), "format": CHECKPOINT_FORMAT}, path)  # as alcn train's
    with pytest.raises(WeightFileError, match="not a checkpoint of alcn train-real-light"):
        load_checkpoint(path, cfg)


def test_the_sources_photo_options_are_keywords():
    from alcn_cv.train.real_light import source_scenes

    with pytest.raises(TypeError):
        source_scenes([], 2, 0, "relief", 0.0, ["photos"])  # type: ignore[misc]


def test_identification_is_symmetric_and_ignores_each_patchs_gain_and_offset():
    g = torch.Generator().manual_seed(0)
    a, b = torch.randn(12, 1, 8, 8, generator=g), torch.randn(12, 1, 8, 8, generator=g)
    loss = identification_loss(a, b, 0.1)
    # the symmetric cross-entropy: a among b and b among a
    torch.testing.assert_close(identification_loss(b, a, 0.1), loss)
    # NCC of either side: a gain and an offset of the patches leave it unchanged
    torch.testing.assert_close(identification_loss(3 * a + 1, b, 0.1), loss, rtol=1e-4, atol=1e-5)
    torch.testing.assert_close(identification_loss(a, 2 * b - 5, 0.1), loss, rtol=1e-4, atol=1e-5)


def test_harris_response_is_negative_on_an_edge():
    edge = torch.zeros(1, 1, 32, 32)
    edge[..., 16:] = 1.0
    response = harris_response(edge)[0, 0]
    assert float(response[8:24, 14:18].max()) < 0


def test_a_step_draws_two_different_frames():
    scene = TrainingScene("s", np.zeros((2, 96, 96), np.float32), np.array([[40, 40], [40, 60], [60, 40]]), 16)
    cfg = RealLightConfig(locations=2, min_distance=4, anywhere=2)
    for seed in range(40):
        _, (fa, fb), _, _ = draw_step([scene], [], cfg, np.random.default_rng(seed))
        assert fa != fb


def test_a_smooth_ramp_is_not_texture_a_steeper_one_is():
    x = np.arange(160, dtype=np.float32)
    gentle = np.tile(np.floor(0.6 * x), (64, 1)).astype(np.uint8)  # 0.6 grey level a pixel
    steep = np.tile(np.floor(1.5 * x), (64, 1)).astype(np.uint8)  # 1.5 grey levels a pixel
    assert textured_share(gentle, 16) == 0.0
    assert textured_share(steep, 16) == 1.0


def test_locations_exactly_min_distance_apart_are_both_drawn():
    """``min_distance`` is the least Chebyshev distance allowed ("at least"): a strict ``>`` dropped the candidates
    of a grid whose step is the distance, halving the locations drawn."""
    corners = np.array([[0, 0], [0, 12], [12, 0], [12, 12]])
    for seed in range(5):
        picked = sample_locations(corners, 4, 12, np.random.default_rng(seed))
        assert sorted(map(tuple, picked.tolist())) == sorted(map(tuple, corners.tolist()))
    assert len(sample_locations(corners, 4, 13, np.random.default_rng(0))) == 1


def test_the_objective_identifies_the_textured_locations_only():
    """Identification's classes are the first ``textured`` outputs; those drawn anywhere (flat, alike) join the
    consistency and repeatability terms only. Identifying among all of them asked the network to tell flat patches
    apart."""
    from alcn_cv.train.real_light import objective

    g = torch.Generator().manual_seed(0)
    a, b = torch.randn(10, 1, 8, 8, generator=g), torch.randn(10, 1, 8, 8, generator=g)
    cfg = RealLightConfig(temperature=0.5, consistency=0.0, repeatability=0.0)
    torch.testing.assert_close(objective(a, b, 6, cfg), identification_loss(a[:6], b[:6], 0.5))
    weighted = RealLightConfig(temperature=0.5, consistency=2.0, repeatability=0.5)
    expected = identification_loss(a[:6], b[:6], 0.5) + 2.0 * consistency_loss(a, b) + 0.5 * repeatability_loss(a, b)
    torch.testing.assert_close(objective(a, b, 6, weighted), expected)
