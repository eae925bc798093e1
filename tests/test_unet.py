"""The free-form U-Net baseline: the network (alcn_cv.train.unet_normalizer), its training (alcn_cv.train.unet) and its
benchmark method (alcn_cv.bench.unet, ``unet:weights=PATH`` in alcn_cv.bench.relight)."""

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from alcn_cv.bench.relight import LocallyStandardized, build_method
from alcn_cv.bench.unet import UNetNormalization
from alcn_cv.data.scenes import load_scene_folder
from alcn_cv.errors import InputError, WeightFileError
from alcn_cv.nets.gain import GainNormalizer
from alcn_cv.train.config import UNET_CONFS, UNetConfig
from alcn_cv.train.real_light import (
    anywhere_locations,
    consistency_loss,
    crop_windows,
    identification_loss,
    sample_locations,
    training_scene,
)
from alcn_cv.train.unet import centre_outputs, output_range, train_unet, unet_pair_loss
from alcn_cv.train.unet_normalizer import UNetNormalizer
from alcn_cv.weight_file import load_normalizer_file, save_normalizer_file
from scene_sets import make_sets

CROP, PATCH = 96, 32
#: A tiny run: 12 steps of 12 locations (and 4 drawn anywhere) on crops of 96 around patches of 32, a U-Net of 4
#: channels and 2 levels.
TINY = UNetConfig(
    relit=0,
    steps=12,
    locations=12,
    crop=CROP,
    patch=PATCH,
    min_distance=8,
    anywhere=4,
    temperature=0.5,
    repeatability=0.0,
    lr=3e-3,
    save_every=6,
    net={"channels": 4, "levels": 2, "eps": 0.01},
)


def _trained_like(seed: int = 0, **config) -> UNetNormalizer:
    """A U-Net whose weights are not the initialisation's (a larger last layer, so outputs differ)."""
    torch.manual_seed(seed)
    net = UNetNormalizer(**config)
    with torch.no_grad():
        net.head.weight.mul_(20.0)
    return net.eval()


@pytest.mark.parametrize("shape", [(2, 1, 37, 50), (1, 1, 1, 1), (1, 1, 3, 200), (3, 1, 64, 64)])
def test_any_size_gives_its_shape_in_the_open_interval(shape):
    net = _trained_like()
    with torch.no_grad():
        out = net(torch.rand(shape))
    assert out.shape == shape and torch.isfinite(out).all() and out.abs().max() < 1
    assert out.numel() == 1 or out.std() > 0.01


def test_bad_input_and_arguments_are_refused():
    with pytest.raises(InputError):
        UNetNormalizer()(torch.rand(1, 3, 16, 16))
    for bad in ({"channels": 0}, {"levels": 0}, {"eps": 0.0}, {"channels": 2.5}):
        with pytest.raises(InputError):
            UNetNormalizer(**bad)
    for eps in (float("inf"), float("nan")):
        with pytest.raises(InputError, match="eps must be positive and finite"):
            UNetNormalizer(eps=eps)


def test_more_parameters_than_the_gain_normalizer():
    """More than the shipped gain Normalizer's (the arrays of its weight file): the U-Net is not the smaller one."""
    from alcn_cv.runtime import MODELS
    from alcn_cv.weight_file import load_normalizer_file

    count = lambda net: sum(a.size for a in net.state_arrays().values())  # noqa: E731  # what a weight file stores
    shipped = sum(a.size for a in load_normalizer_file(MODELS["gain"]).arrays.values())
    assert count(GainNormalizer()) == shipped
    assert count(UNetNormalizer()) > 5 * shipped


@pytest.mark.parametrize("levels", [1, 2, 3, 4])
def test_reach_bounds_the_receptive_field(levels):
    net = _trained_like(levels=levels, channels=4)
    farthest = 0
    for centre in range(100, 100 + net.multiple):
        image = torch.rand(1, 1, 232, 232, requires_grad=True)
        net(image)[0, 0, centre, centre].backward()
        rows = image.grad[0, 0].abs().sum(1).nonzero()[:, 0]
        farthest = max(farthest, centre - int(rows.min()), int(rows.max()) - centre)
    assert 0 < farthest <= net.reach


@pytest.mark.parametrize(("crop", "patch"), [(160, 32), (96, 32), (70, 20)])
def test_centre_outputs_equal_the_centre_of_the_whole_crop(crop, patch):
    net = _trained_like()
    crops = torch.rand(3, 1, crop, crop)
    lo = (crop - patch) // 2
    with torch.no_grad():
        centre = centre_outputs(net, crops, patch)
        whole = net(crops)[..., lo : lo + patch, lo : lo + patch]
    torch.testing.assert_close(centre, whole, atol=1e-5, rtol=1e-5)


def test_save_and_load_give_the_same_outputs(tmp_path):
    net = _trained_like(channels=4, levels=2)
    path = save_normalizer_file(tmp_path / "u.npz", net.state_arrays(), net.file_meta(trained=True))
    loaded = UNetNormalizer.from_file(load_normalizer_file(path))
    image = torch.rand(1, 1, 30, 41)
    with torch.no_grad():
        torch.testing.assert_close(loaded(image), net(image), rtol=0, atol=0)
    assert loaded.config == {"channels": 4, "levels": 2, "eps": 0.01}
    gain = GainNormalizer()
    other = save_normalizer_file(tmp_path / "g.npz", gain.state_arrays(), gain.file_meta(trained=False))
    with pytest.raises(WeightFileError):
        UNetNormalizer.from_file(load_normalizer_file(other))


def test_the_objective_is_identification_plus_weighted_consistency(tmp_path):
    root = make_sets(tmp_path)
    scene = training_scene(load_scene_folder(root / "webcam" / "street")[0], CROP // 2, PATCH)
    rng = np.random.default_rng(0)
    centres, anywhere = sample_locations(scene.candidates, 8, 8, rng), anywhere_locations(scene, 4, rng)
    net = _trained_like(channels=4)
    every = np.concatenate([centres, anywhere])
    with torch.no_grad():
        first, second = (centre_outputs(net, crop_windows(scene.frames[f], every, CROP), PATCH) for f in (0, 1))
        losses = {
            weight: float(unet_pair_loss(net, scene, (0, 1), centres, replace(TINY, consistency=weight), anywhere))
            for weight in (0.0, 2.0)
        }
    assert losses[0.0] == pytest.approx(float(identification_loss(first[:8], second[:8], TINY.temperature)))
    assert losses[2.0] == pytest.approx(losses[0.0] + 2.0 * float(consistency_loss(first, second)), rel=1e-5)


def test_a_short_training_writes_its_files_and_lowers_the_loss(tmp_path, monkeypatch):
    torch.set_num_threads(1)
    root = make_sets(tmp_path / "data")
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.chdir(tmp_path)
    cfg = replace(TINY, scenes=[str(Path("data") / "webcam" / "street"), str(root / "webcam" / "square")])
    path = train_unet(cfg, tmp_path / "run", conf="test")
    meta = load_normalizer_file(path).meta
    assert path.name == "unet_normalizer.npz" and meta["architecture"] == "unet" and meta["trained"]
    assert meta["training"]["conf"] == "test" and meta["training"]["config"]["steps"] == 12
    # a file users share: the folders as given, the home folder written ~ (they were recorded absolute)
    assert meta["training"]["config"]["scenes"] == ["data/webcam/street", "~/data/webcam/square"]
    assert str(tmp_path) not in json.dumps(meta)
    history = json.loads((tmp_path / "run" / "history.json").read_text())
    assert [h["step"] for h in history] == list(range(1, 13)) and all(np.isfinite(h["loss"]) for h in history)
    assert "trained 12 steps" in (tmp_path / "run" / "train.log").read_text()
    with pytest.raises(InputError, match=r"holds an earlier run .*: --overwrite replaces it, or give") as refused:
        train_unet(cfg, tmp_path / "run", conf="test")
    assert "--resume" not in str(refused.value)  # `alcn train-unet` has none
    # The output range: where the outputs on the training frames lie (all 3 frames of each scene, unpadded).
    trained = UNetNormalizer.from_file(load_normalizer_file(path))
    scenes = [training_scene(load_scene_folder(f)[0], CROP // 2, PATCH) for f in cfg.scenes]
    lo, hi = meta["output_range"]
    assert (lo, hi) == pytest.approx(output_range(trained, scenes)) and -1 < lo < hi < 1
    pad = CROP // 2
    with torch.no_grad():
        outputs = torch.cat([trained(torch.from_numpy(s.frames[:, None, pad:-pad, pad:-pad])) for s in scenes])
    assert 0.995 < float(((outputs >= lo) & (outputs <= hi)).float().mean()) < 1
    # The trained file identifies better than its initialisation (the same seed builds the same start).
    torch.manual_seed(cfg.seed)
    untrained = UNetNormalizer(channels=4, levels=2)
    scene = scenes[0]
    rng = np.random.default_rng(5)
    losses = {"untrained": 0.0, "trained": 0.0}
    with torch.no_grad():
        for _ in range(4):
            centres = sample_locations(scene.candidates, 12, 8, rng)
            pair = tuple(int(f) for f in rng.choice(len(scene.frames), 2, replace=False))
            losses["untrained"] += float(unet_pair_loss(untrained, scene, pair, centres, cfg))
            losses["trained"] += float(unet_pair_loss(trained, scene, pair, centres, cfg))
    assert losses["trained"] < losses["untrained"]


def test_the_bench_spec_builds_and_applies(tmp_path):
    net = _trained_like(channels=4, levels=2)
    path = save_normalizer_file(tmp_path / "u.npz", net.state_arrays(), net.file_meta(trained=True))
    method = build_method(f"unet:weights={path}")
    assert isinstance(method, UNetNormalization)
    image = np.random.default_rng(0).integers(0, 256, (45, 70), dtype=np.uint8)
    out = method.apply(image)
    assert out.shape == image.shape and out.dtype == np.uint8 and out.std() > 1
    with torch.no_grad():
        expected = net(torch.from_numpy(image.astype(np.float32) / 255)[None, None])[0, 0].numpy()
    np.testing.assert_allclose(method.normalize(image.astype(np.float32) / 255), expected, atol=1e-6)
    assert isinstance(build_method(f"unet:weights={path}+lstd"), LocallyStandardized)
    # The file's output range is apply()'s fixed map: its lowest and highest responses go to 0 and 255.
    meta = net.file_meta(trained=True, output_range=(expected.min(), expected.max()))
    narrow = save_normalizer_file(tmp_path / "n.npz", net.state_arrays(), meta)
    stretched = build_method(f"unet:weights={narrow}").apply(image)
    assert (stretched.min(), stretched.max()) == (0, 255)
    for bad in ("unet", f"unet:weights={path}:scale=2"):
        with pytest.raises(InputError):
            build_method(bad)
    with pytest.raises(WeightFileError):
        build_method(f"unet:weights={tmp_path / 'missing.npz'}")
    # where an ALCN Normalizer goes, the file says what it is and what runs it
    from alcn_cv import createALCN

    with pytest.raises(WeightFileError, match=r"u.npz: the U-Net baseline .* `alcn bench relight --methods unet:"):
        createALCN(weights=path)


def test_the_cli_trains_with_the_preset_and_its_settings(tmp_path, monkeypatch):
    import alcn_cv.train.unet as unet
    from alcn_cv.cli import main

    runs = []
    monkeypatch.setattr(unet, "train_unet", lambda cfg, out, **record: runs.append((cfg, record)) or out)
    options = ["--set", "steps=7", "--set", "net.levels=2", "--seed", "3"]
    assert main(["train-unet", "--out", str(tmp_path), *options]) == 0
    ((cfg, record),) = runs
    assert (cfg.steps, cfg.seed, cfg.crop) == (7, 3, UNET_CONFS["gain"].crop)
    assert cfg.net == {"channels": 8, "levels": 2, "eps": 0.01} and record["conf"] == "gain"
    assert "--set net.levels=2" in record["command"]
