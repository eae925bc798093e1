"""The gain Normalizer's lite variant: ``alcn distill`` from a gain teacher, and the shipped
``createALCN(model="gain-lite")`` against its torch model."""

from __future__ import annotations

import hashlib
import shlex

import cv2
import numpy as np
import pytest

torch = pytest.importorskip("torch")

import alcn_cv  # noqa: E402
from alcn_cv.cli import main as cli  # noqa: E402
from alcn_cv.data.frames import synthetic_frame  # noqa: E402
from alcn_cv.enhance.alcn import ALCN  # noqa: E402
from alcn_cv.nets.gain import GainNormalizer  # noqa: E402
from alcn_cv.runtime import MODELS  # noqa: E402
from alcn_cv.train.config import GainDistillConfig, LiteDistillConfig  # noqa: E402
from alcn_cv.weight_file import load_normalizer_file, save_normalizer_file  # noqa: E402


def _scenes(root, count=2, frames=5, shape=(96, 128)):
    """Small registered scenes: one textured view under several light strengths."""
    rng = np.random.default_rng(0)
    folders = []
    for i in range(count):
        view = cv2.GaussianBlur(rng.random(shape).astype(np.float32), (0, 0), 1.5)
        view = (view - view.min()) / (view.max() - view.min())
        folder = root / f"scene{i}"
        folder.mkdir()
        for j in range(frames):
            cv2.imwrite(str(folder / f"f{j}.png"), np.clip(view * (80 + 60 * j) + 10, 0, 255).astype(np.uint8))
        folders.append(folder)
    return folders


def _teacher(path):
    """A gain teacher whose maps vary over the image (random perturbation of the DoG start)."""
    torch.manual_seed(1)
    net = GainNormalizer(learn_scales=True)
    with torch.no_grad():
        for p in net.parameters():
            if p.requires_grad:
                p.add_(0.2 * torch.randn_like(p))
    return save_normalizer_file(
        path, net.state_arrays(), net.file_meta(trained=True, description="a test teacher")
    ), net


def test_distill_from_a_gain_teacher_writes_a_smaller_gain_student(tmp_path):
    from alcn_cv.train import distill

    teacher_path, teacher = _teacher(tmp_path / "teacher.npz")
    scenes = _scenes(tmp_path)
    cfg = GainDistillConfig(
        teacher=str(teacher_path), scenes=[str(s) for s in scenes], relit=0, n_rendered=0, epochs=25
    )
    out = distill.main(tmp_path / "student.npz", cfg, "test", conf="gain-lite", progress=False)
    header = load_normalizer_file(out).meta
    assert header["architecture"] == "gain" and header["config"]["channels"] == 8 and header["trained"] is True
    assert header["teacher"]["sha256"] == hashlib.sha256(teacher_path.read_bytes()).hexdigest()
    assert header["equalization"]["tau"] == pytest.approx(teacher.tau_value())
    assert header["divisive"]["scale"] == pytest.approx(float(teacher.floor_scale.detach()))
    fit = header["distillation"]
    assert fit["conf"] == "gain-lite" and fit["settings"]["epochs"] == 25
    assert fit["validation"]["maps_relative_error"] < fit["validation_initial"]["maps_relative_error"]
    assert fit["settings"]["frames"] == {"train": 8, "validation": 2}  # every 5th frame of each scene held out
    card = out.with_suffix(".md").read_text()
    assert "Command: `test`" in card and "teacher.npz" in card and "carry those photographs' terms" in card
    # the student runs through ALCN on every backend, its ONNX export included
    gray = synthetic_frame(160, 120, False).astype(np.float32) / np.float32(255)
    fast, opencv = ALCN(weights=out), ALCN(weights=out, backend="opencv")
    with torch.inference_mode():
        expected = fast.net(torch.from_numpy(gray)[None, None])[0, 0].numpy()
    # the OpenCV mixture against torch's, to float rounding as the division amplifies it: an input moved by 1e-7 of
    # itself moves the torch output by up to 8e-6 (the shipped default), 5e-6 (a student distilled here)
    np.testing.assert_allclose(fast.normalize(gray), expected, atol=5e-5, rtol=0)
    np.testing.assert_allclose(opencv.normalize(gray), expected, atol=1e-4, rtol=0)


def test_distill_gain_is_seeded_and_rejects_other_teachers(tmp_path):
    from alcn_cv.train import distill

    teacher_path, _ = _teacher(tmp_path / "teacher.npz")
    scenes = _scenes(tmp_path, count=1)
    (tmp_path / "short").mkdir()
    cfg = GainDistillConfig(teacher=str(teacher_path), scenes=[str(s) for s in scenes], relit=0, n_rendered=1, epochs=2)
    runs = [distill.distill_gain(cfg, progress=False)[0] for _ in range(2)]
    for a, b in zip(runs[0].state_arrays().values(), runs[1].state_arrays().values()):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(alcn_cv.errors.InputError, match="not a gain"):
        distill.distill_gain(GainDistillConfig(teacher="lite", scenes=cfg.scenes), progress=False)
    family = "gain Normalizer, not of the paper.s family.*--conf gain-lite"  # said before rendering
    with pytest.raises(alcn_cv.errors.InputError, match=family):
        distill.distill(LiteDistillConfig(teacher=str(teacher_path)), progress=False)
    short = [str(s) for s in _scenes(tmp_path / "short", count=1, frames=3)]
    with pytest.raises(alcn_cv.errors.DatasetError, match="validation"):
        distill.distill_gain(
            GainDistillConfig(teacher=str(teacher_path), scenes=short, relit=0, n_rendered=0), progress=False
        )


def test_distill_command_from_a_gain_teacher(tmp_path, capsys):
    teacher_path, _ = _teacher(tmp_path / "teacher.npz")
    scenes = _scenes(tmp_path, count=1)
    out = tmp_path / "gain_lite.npz"
    args = [
        "--set",
        f"teacher='{teacher_path}'",
        "--set",
        "epochs=1",
        "--set",
        "channels=4",
        "--set",
        "dilations=[1, 2]",
        "--set",
        f"scenes=['{scenes[0]}']",
        "--set",
        "relit=0",
        "--set",
        "n_rendered=0",
    ]
    assert cli(["distill", "--conf", "gain-lite", "--out", str(out), *args, "--no-progress"]) == 0
    assert capsys.readouterr().out.strip() == str(out) and out.with_suffix(".onnx").is_file()
    config = load_normalizer_file(out).meta["config"]
    assert (config["channels"], config["dilations"]) == (4, [1, 2])
    assert (
        f"Command: `{shlex.join(['alcn', 'distill', '--conf', 'gain-lite', '--out', str(out), *args])}`"
        in out.with_suffix(".md").read_text()
    )


@pytest.mark.parametrize("backend", ["fast", "opencv"])
def test_shipped_gain_lite_model_equals_its_torch_model(backend):
    alcn = alcn_cv.createALCN(model="gain-lite", backend=backend)
    assert alcn.weights_path == MODELS["gain-lite"] and alcn.trained and alcn.mixture == "exact"
    header = load_normalizer_file(MODELS["gain-lite"]).meta
    assert header["config"]["channels"] < load_normalizer_file(MODELS["gain"]).meta["config"]["channels"]
    assert "photographs that permit any use" in MODELS["gain-lite"].with_suffix(".md").read_text()
    reference = ALCN(model="gain-lite", backend="fast").net
    gray = synthetic_frame(320, 200, False, seed=5).astype(np.float32) / np.float32(255)
    with torch.inference_mode():
        expected = reference(torch.from_numpy(gray)[None, None])[0, 0].numpy()
    np.testing.assert_allclose(alcn.normalize(gray), expected, atol=1e-5 if backend == "fast" else 1e-3, rtol=0)


def test_gain_alcn_pickles_after_use():
    import copy
    import pickle

    alcn = ALCN(model="gain-lite")
    frame = synthetic_frame(200, 120, False)
    out = alcn.apply(frame)
    for clone in (pickle.loads(pickle.dumps(alcn)), copy.deepcopy(alcn)):
        np.testing.assert_array_equal(clone.apply(frame), out)


def test_the_maps_error_ignores_a_scale_of_the_whole_frames_maps():
    """The divisive step after the maps cancels a scale of the whole frame's maps, so the distillation copies their
    shape only: maps 3 times the teacher's cost nothing, mirrored ones do."""
    from types import SimpleNamespace

    from alcn_cv.train.distill import _GridSample, _maps_error

    maps = torch.randn(1, 2, 5, 6, generator=torch.Generator().manual_seed(0))
    sample = _GridSample(torch.zeros(1, 4, 5, 6), maps, float(maps.pow(2).sum(1).mean()))
    scaled = SimpleNamespace(maps_from_features=lambda features: 3.0 * maps)
    assert float(_maps_error(scaled, sample)) == pytest.approx(0.0, abs=1e-10)
    mirrored = SimpleNamespace(maps_from_features=lambda features: maps.flip(-1))
    assert float(_maps_error(mirrored, sample)) > 0.1


def test_relit_frames_are_clipped_as_a_camera_would():
    """The relit frame is the frame times a gain of 0.3 to 1.5, clipped to [0, 1] (a camera saturates); unclipped,
    the student learned from intensities no camera gives."""
    from alcn_cv.train.distill import _relit

    frame = np.linspace(0, 1, 48 * 64, dtype=np.float32).reshape(48, 64)
    brighter = 0
    for seed in range(12):
        out = _relit(frame, np.random.default_rng(seed))
        assert out.shape == frame.shape and out.dtype == np.float32 and out.min() >= 0.0 and out.max() <= 1.0
        rows = out if out[0, 0] == 0.0 else out[:, ::-1]  # mirrored half of the time
        gain = float(rows[0, 1] / frame[0, 1])
        assert 0.3 <= gain <= 1.5
        np.testing.assert_allclose(rows, np.clip(frame * np.float32(gain), 0, 1), rtol=1e-6, atol=1e-7)
        brighter += gain > 1
    assert brighter  # some frames saturate: the clip is exercised


def test_a_single_rendered_scene_is_trained_on_not_held_out():
    """The last rendered scene is held out for validation only when there are two or more: holding out the only one
    left the distillation nothing rendered to learn from."""
    from alcn_cv.train.distill import _gain_frames

    train, val = _gain_frames([], 1, 0, False)
    assert len(train) == 4 and val == []
    train, val = _gain_frames([], 2, 0, False)
    assert len(train) == 4 and len(val) == 4
