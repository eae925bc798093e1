"""The second stage: a new detector on frozen-Normalizer outputs (alcn_cv.train.stage2)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from alcn_cv.errors import InputError
from alcn_cv.nets import Detector
from alcn_cv.train import train_detector
from alcn_cv.train.stage2 import evaluate_detector


def _toy(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Background = noise; class 1 = a bright square; class 2 = a dark disc."""
    rng = np.random.default_rng(seed)
    labels = rng.integers(0, 3, n)
    x = rng.normal(0, 0.3, (n, 32, 32)).astype(np.float32)
    yy, xx = np.mgrid[:32, :32]
    x[labels == 1, 10:22, 10:22] += 1.5
    x[labels == 2] -= 1.5 * (((yy - 16) ** 2 + (xx - 16) ** 2) < 36)
    return x, labels.astype(np.int64)


def _small() -> Detector:
    return Detector(3, channels=(4, 8), hidden=16)


def test_learns_and_is_deterministic():
    x, y = _toy(160, 0)
    xv, yv = _toy(100, 1)
    state = torch.get_rng_state()
    nets = [
        train_detector(x, y, 3, epochs=3, batch_size=32, lr=3e-3, seed=5, val=(xv, yv), progress=False, net=None)
        for _ in range(2)
    ]
    assert torch.equal(state, torch.get_rng_state())  # the global random state is untouched
    for a, b in zip(nets[0].parameters(), nets[1].parameters()):
        assert torch.equal(a, b)
    assert not nets[0].training
    _, acc = evaluate_detector(nets[0], xv, yv)
    assert acc > 0.9


def test_seed_changes_result_and_custom_net():
    x, y = _toy(64, 0)
    a = train_detector(x, y, 3, epochs=1, batch_size=16, lr=1e-3, seed=0, progress=False, net=_small())
    b = train_detector(x, y, 3, epochs=1, batch_size=16, lr=1e-3, seed=1, progress=False, net=_small())
    assert isinstance(a, Detector) and a.classifier[0].out_channels == 16
    assert not torch.equal(a.classifier[-1].weight, b.classifier[-1].weight)


@pytest.mark.parametrize(
    "windows, labels, match",
    [
        (np.zeros((4, 48, 48), np.float32), np.zeros(4, np.int64), "32, 32"),
        (np.zeros((4, 32, 32), np.float64), np.zeros(4, np.int64), "float32"),
        (np.full((4, 32, 32), np.nan, np.float32), np.zeros(4, np.int64), "NaN"),
        (np.zeros((4, 32, 32), np.float32), np.zeros(3, np.int64), "labels"),
        (np.zeros((4, 32, 32), np.float32), np.array([0, 1, 2, 3]), r"\[0, 2\]"),
    ],
)
def test_bad_input(windows, labels, match):
    with pytest.raises(InputError, match=match):
        train_detector(windows, labels, 3, epochs=1, batch_size=2, lr=1e-3, seed=0, progress=False)


@pytest.mark.parametrize(
    "labels, match", [(np.zeros(0, np.int64), "empty"), ([0, 1], "labels"), (np.zeros(2, np.float32), "labels")]
)
def test_evaluate_detector_names_bad_labels_of_a_network_without_num_classes(labels, match):
    """A network that does not say its classes: the labels' own check names what is wrong (it was a bare
    ValueError of ``labels.max()`` for none, an AttributeError for a list)."""
    net = torch.nn.Sequential(torch.nn.Flatten(), torch.nn.Linear(32 * 32, 3))
    windows = np.zeros((len(labels), 32, 32), np.float32)
    with pytest.raises(InputError, match=match):
        evaluate_detector(net, windows, labels)
    loss, accuracy = evaluate_detector(net, np.zeros((2, 32, 32), np.float32), np.array([0, 2]))
    assert np.isfinite(loss) and 0 <= accuracy <= 1


def test_an_objects_folder_mask_marks_all_its_images(tmp_path):
    """The photometric-stereo sets (`psm/NAME/NAME.mask.png`, one view under several lights) hold one mask for all
    their images, which `alcn bench invariance` reads: `train-detector` took their whole frames, black background
    included, as the object."""
    import cv2

    from alcn_cv.train.stage2 import _read_objects

    (tmp_path / "owl").mkdir()
    for i in range(2):
        cv2.imwrite(str(tmp_path / "owl" / f"owl.{i}.png"), np.full((20, 30), 100 + i, np.uint8))
    mask = np.zeros((20, 30), np.uint8)
    mask[5:15, 10:20] = 255
    cv2.imwrite(str(tmp_path / "owl" / "owl.mask.png"), mask)
    ((name, items),) = _read_objects(tmp_path)
    assert name == "owl" and len(items) == 2  # the mask is not an image of the object
    for _, marked in items:
        np.testing.assert_array_equal(marked, mask > 0)
    (tmp_path / "owl" / "owl.mask.png").unlink()
    assert _read_objects(tmp_path)[0][1][0][1] == [0, 0, 30, 20]  # no mask: the whole image


def test_object_masks_are_read_as_every_mask_is(tmp_path):
    """`alcn train-detector` read a mask as nonzero where `bench invariance` and the data sets read white above 127:
    one file gave two objects. Both now take :func:`alcn_cv.io.read_mask`."""
    import cv2

    from alcn_cv.train.stage2 import _read_objects

    (tmp_path / "owl").mkdir()
    cv2.imwrite(str(tmp_path / "owl" / "owl.0.png"), np.zeros((20, 30), np.uint8))
    mask = np.zeros((20, 30), np.uint8)
    mask[5:15, 10:20] = 255
    mask[0:5, 0:5] = 100  # a grey halo of an antialiased brush: outside
    cv2.imwrite(str(tmp_path / "owl" / "owl.mask.png"), mask)
    np.testing.assert_array_equal(_read_objects(tmp_path)[0][1][0][1], mask > 127)
    cv2.imwrite(str(tmp_path / "owl" / "owl.mask.png"), (mask > 0).astype(np.uint8))  # a 0/1 mask
    with pytest.raises(InputError, match=r"owl.mask.png: no pixel above 127; a mask is white \(255\)"):
        _read_objects(tmp_path)


def test_normalize_windows_keeps_the_detectors_centre():
    """The detector sees the centre 32x32 of each normalized 64x64 window, standardized: a crop at the corner would
    train it on the background around the object."""
    from types import SimpleNamespace

    from alcn_cv.filters.standardize import standardize_windows
    from alcn_cv.train.stage2 import normalize_windows

    windows = np.random.default_rng(0).integers(0, 256, (3, 64, 64), dtype=np.uint8)
    identity = SimpleNamespace(normalize=lambda gray: gray)
    expected = standardize_windows(windows[:, 16:48, 16:48].astype(np.float32) / np.float32(255))
    np.testing.assert_array_equal(normalize_windows(windows, identity), expected)
