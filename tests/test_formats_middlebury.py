from __future__ import annotations

import re

import numpy as np
import pytest

from alcn_cv.errors import DatasetError
from alcn_cv.formats.middlebury import read_middlebury

_LINE = "a.png 1520.4 0 302.32 0 1525.9 246.87 0 0 1 1 0 0 0 1 0 0 0 1 0.01 -0.02 0.6"


def test_reads_synthetic_file(tmp_path):
    (tmp_path / "x_par.txt").write_text(f"1\n{_LINE}\n")
    (tmp_path / "a.png").write_bytes(b"")
    (view,) = read_middlebury(tmp_path)
    assert view.name == "a.png" and view.path == tmp_path / "a.png"
    np.testing.assert_allclose(view.K[0], [1520.4, 0, 302.32])
    np.testing.assert_allclose(view.t_w2c, [0.01, -0.02, 0.6])
    np.testing.assert_allclose(view.center, [-0.01, 0.02, -0.6])


@pytest.mark.parametrize(
    "text, match",
    [
        ("2\n" + _LINE + "\n", "header says 2"),
        ("x\n" + _LINE + "\n", "number of images"),
        ("1\n" + _LINE.replace("0.6", "abc") + "\n", "field K/R/t"),
        ("1\n" + _LINE.rsplit(" ", 1)[0] + "\n", "22 fields"),
        ("1\n" + _LINE.replace(" 1 0 0 0 1 0 0 0 1 ", " 2 0 0 0 1 0 0 0 1 ") + "\n", "not a rotation"),
        ("1\n" + _LINE.replace("a.png", "b.png") + "\n", "b.png not found"),
    ],
)
def test_malformed(tmp_path, text, match):
    (tmp_path / "x_par.txt").write_text(text)
    (tmp_path / "a.png").write_bytes(b"")
    with pytest.raises(DatasetError, match=match):
        read_middlebury(tmp_path / "x_par.txt")


@pytest.mark.shared_data
@pytest.mark.parametrize("name", ["templeSparseRing", "dinoSparseRing"])
def test_real_sets(shared_data, name):
    views = read_middlebury(shared_data / "middlebury" / name)
    assert len(views) == 16
    for v in views:
        np.testing.assert_allclose(v.R_w2c @ v.R_w2c.T, np.eye(3), atol=1e-4)
    # The centre of the object's bounding box (given in the README) lies in front of every
    # camera and projects inside the 640x480 image.
    readme = (shared_data / "middlebury" / name / "README.txt").read_text()
    corners = np.array(re.findall(r"\(([-\d.]+) ([-\d.]+) ([-\d.]+)\)", readme), dtype=float)
    centre = corners.mean(axis=0)
    for v in views:
        x = v.P @ np.r_[centre, 1.0]
        assert x[2] > 0
        u, w = x[:2] / x[2]
        assert 0 < u < 640 and 0 < w < 480


def test_binary_file_is_a_dataset_error(tmp_path):
    (tmp_path / "x_par.txt").write_bytes(b"\xff\xfe\x00binary")
    with pytest.raises(DatasetError, match="not a text file"):
        read_middlebury(tmp_path)


_MB_LINE = "a.png 1520.4 0 302.32 0 1525.9 246.87 0 0 1 1 0 0 0 1 0 0 0 1 0.01 -0.02 0.6"


def test_a_scaled_camera_matrix_is_normalized_to_k33_one(tmp_path):
    """``x = K [R | t] X`` is homogeneous: a file whose K is scaled (K[2, 2] = 2) names the same camera."""
    scaled = "a.png 3040.8 0 604.64 0 3051.8 493.74 0 0 2 1 0 0 0 1 0 0 0 1 0.01 -0.02 0.6"
    (tmp_path / "x_par.txt").write_text(f"1\n{scaled}\n")
    (tmp_path / "a.png").write_bytes(b"")
    (view,) = read_middlebury(tmp_path)
    np.testing.assert_allclose(view.K, [[1520.4, 0, 302.32], [0, 1525.9, 246.87], [0, 0, 1]])


def test_a_reflection_is_not_a_rotation(tmp_path):
    """An orthonormal R of determinant -1 (a mirrored camera) is refused, not read as a pose."""
    mirrored = _MB_LINE.replace(" 1 0 0 0 1 0 0 0 1 ", " -1 0 0 0 1 0 0 0 1 ")
    (tmp_path / "x_par.txt").write_text(f"1\n{mirrored}\n")
    (tmp_path / "a.png").write_bytes(b"")
    with pytest.raises(DatasetError, match="not a rotation"):
        read_middlebury(tmp_path)


def test_the_center_of_a_turned_camera(tmp_path):
    """``center`` is ``-R.T @ t``: with a quarter turn about z (not its own transpose), ``-R @ t`` gives another
    point, which the identity rotation of the other tests cannot tell apart."""
    turned = _LINE.replace(" 1 0 0 0 1 0 0 0 1 ", " 0 -1 0 1 0 0 0 0 1 ")
    (tmp_path / "x_par.txt").write_text(f"1\n{turned}\n")
    (view,) = read_middlebury(tmp_path, check_images=False)
    np.testing.assert_allclose(view.R_w2c, [[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    np.testing.assert_allclose(view.center, [0.02, 0.01, -0.6], atol=1e-12)
    np.testing.assert_allclose(view.R_w2c @ view.center + view.t_w2c, 0.0, atol=1e-12)
