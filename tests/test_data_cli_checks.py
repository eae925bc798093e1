"""What `alcn data ...` says about bad values and outputs: the option, in one line, before any rendering (a sweep of
bad inputs found numpy's and Python's words, a MemoryError traceback and a set `alcn bench detect` refuses)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from alcn_cv.cli import main
from alcn_cv.data import detect, phos, pose, preview, relief_scenes
from alcn_cv.errors import InputError
from alcn_cv.formats.coco import write_coco


def _argparse_error(args: list[str], capsys) -> str:
    """The last line of argparse's error for ``alcn ARGS`` (exit code 2)."""
    with pytest.raises(SystemExit) as exit_:
        main(args)
    assert exit_.value.code == 2
    return capsys.readouterr().err.strip().splitlines()[-1]


@pytest.fixture
def no_rendering(monkeypatch):
    """Every generator fails the test if it starts rendering."""
    for module in (phos, detect, pose, relief_scenes):
        monkeypatch.setattr(
            module, "parallel_map", lambda *a, name=module.__name__, **k: pytest.fail(f"{name} rendered")
        )


@pytest.mark.parametrize(
    ("command", "option"),
    [
        ("phos", "--seed"),
        ("phos", "--object-seed"),
        ("detect", "--seed"),
        ("detect", "--object-seed"),
        ("pose", "--seed"),
        ("scenes", "--seed"),
        ("compare-psm", "--seed"),
    ],
)
def test_a_negative_seed_names_its_option(command, option, tmp_path, capsys, no_rendering):
    """Was numpy's "expected non-negative integer", which names no option."""
    err = _argparse_error(["data", command, "--out", str(tmp_path / "o"), option, "-3"], capsys)
    assert err.endswith(f"argument {option}: an integer at least 0, got '-3'")
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (["phos", "--objects", "0"], "argument --objects: an integer at least 1, got '0'"),
        (["phos", "--background-fraction", "1.5"], "argument --background-fraction: a number at least 0 and at most 1"),
        (["phos", "--background-fraction", "-0.1"], "argument --background-fraction: a number at least 0 and at most"),
        (["phos", "-n", "0"], "argument -n: an integer at least 1, got '0'"),
        (["phos", "--workers", "0"], "argument --workers: an integer at least 1, got '0'"),
        (["pose", "--train-sweeps", "1", "-1"], "argument --train-sweeps: a number at least 0, got '-1'"),
        (["detect", "--n-train", "-1"], "argument --n-train: an integer at least 1, got '-1'"),
        (["detect", "--n-val", "-2"], "argument --n-val: an integer at least 0, got '-2'"),
        (["detect", "--width", "0"], "argument --width: an integer at least 1 and at most 4096, got '0'"),
        # no test image: `alcn bench detect` refused the set it wrote
        (["detect", "--n-test", "0"], "argument --n-test: an integer at least 1, got '0'"),
        # 100000 asked numpy for 149 GiB: a MemoryError traceback
        (["detect", "--height", "100000"], "argument --height: an integer at least 1 and at most 4096, got '100000'"),
        (["scenes", "--side", "100000"], "argument --side: an integer at least 32 and at most 2048, got '100000'"),
    ],
)
def test_a_value_out_of_range_names_its_option(args, said, tmp_path, capsys, no_rendering):
    """Were Python's names: "need n >= 0 and n_objects >= 1", "background_fraction must be", "train_sweeps ...",
    "n_train >= 1, n_test >= 0 and n_val >= 0"."""
    assert said in _argparse_error(["data", *args, "--out", str(tmp_path / "o")], capsys)
    assert not (tmp_path / "o").exists()


def test_what_only_the_generators_can_check_names_the_options(tmp_path, capsys, no_rendering):
    """A width below twice the preset's object size, an infinite sweep (NaN elevations before) and Python callers'
    values that the command line refuses: before any rendering."""
    assert main(["data", "detect", "--conf", "small", "--width", "100", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "(--width, --height) must be from 144 px (twice the objects' size in preset 'small') to 4096 px" in err
    # an infinite sweep: refused by argparse now (number_in takes no inf), and by the generator for a Python caller
    argv = ["data", "pose", "--conf", "small", "--train-sweeps", "inf", "--out", str(tmp_path / "o")]
    said = _argparse_error(argv, capsys)
    assert "argument --train-sweeps: a number at least 0, got 'inf'" in said
    with pytest.raises(InputError, match=r"the training sweeps \(--train-sweeps\) must be one or more finite numbers"):
        pose.generate(tmp_path / "o", conf="small", train_sweeps=(float("inf"),), progress=False)
    with pytest.raises(InputError, match="n_test >= 1"):  # the data `alcn bench detect` scores on
        detect.generate(tmp_path / "o", conf="small", n_test=0, progress=False)
    with pytest.raises(InputError, match="to 4096 px: got 5000x200"):
        detect.generate(tmp_path / "o", conf="small", width=5000, progress=False)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("command", ["phos", "detect", "pose", "scenes"])
def test_an_existing_output_names_only_the_option(command, tmp_path, capsys, no_rendering):
    """Was "dp1 exists (--overwrite, or overwrite=True, replaces it)": the Python keyword on the command line; and a
    file given as --out was "not an earlier output (no manifest.json)"."""
    earlier, afile = tmp_path / "earlier", tmp_path / "afile"
    earlier.mkdir()
    (earlier / "manifest.json").write_text("{}")
    afile.write_text("mine")
    assert main(["data", command, "--out", str(earlier)]) == 2
    assert capsys.readouterr().err.strip() == f"alcn data {command}: error: {earlier} exists (--overwrite replaces it)"
    assert main(["data", command, "--out", str(afile), "--overwrite"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (
        f"alcn data {command}: error: {afile} is a file, not an output folder: not replaced; give another path"
    )
    assert (earlier / "manifest.json").read_text() == "{}" and afile.read_text() == "mine"


def test_preview_refuses_an_existing_sheet_and_names_a_missing_dataset(tmp_path, capsys, monkeypatch):
    """An existing --out PNG was replaced silently; a dataset that does not exist was "not a dataset"."""
    cv2.imwrite(str(tmp_path / "a.png"), np.full((32, 32, 3), 128, np.uint8))
    data = write_coco(tmp_path / "one.json", [{"id": 1, "file_name": "a.png", "width": 32, "height": 32}], [], [])
    sheet = tmp_path / "sheet.png"
    sheet.write_bytes(b"mine")
    with monkeypatch.context() as m:  # refused before the dataset is read
        m.setattr(preview, "_coco", lambda *a, **k: pytest.fail("read the dataset"))
        assert main(["data", "preview", str(data), "--out", str(sheet)]) == 2
        assert capsys.readouterr().err.strip() == f"alcn data preview: error: {sheet} exists (--overwrite replaces it)"
        assert main(["data", "preview", str(data), "--out", str(tmp_path), "--overwrite"]) == 2
        assert f"cannot write the contact sheet to {tmp_path}: a folder" in capsys.readouterr().err
    assert sheet.read_bytes() == b"mine"
    assert main(["data", "preview", str(data), "--out", str(sheet), "--overwrite"]) == 0
    assert sheet.read_bytes().startswith(b"\x89PNG")
    assert main(["data", "preview", str(tmp_path / "nope"), "--out", str(tmp_path / "n.png")]) == 2
    assert capsys.readouterr().err.strip() == f"alcn data preview: error: {tmp_path / 'nope'}: no such file or folder"
