"""The invariance benchmark on photographs under several lights."""

from __future__ import annotations

import json
import shutil
import sys

import cv2
import numpy as np
import pytest

from alcn_cv.bench import invariance
from alcn_cv.cli import main as cli_main
from alcn_cv.data.scenes import load_photometric, mean_pairwise_ncc
from alcn_cv.errors import DatasetError, InputError


def test_agreement_and_detail_by_hand():
    mask = np.ones((4, 4), bool)
    a = np.arange(16, dtype=np.float32).reshape(4, 4)
    stack = np.stack([a, 2 * a + 1, -a])
    # pairs: (a, 2a+1) -> 1, (a, -a) -> -1, (2a+1, -a) -> -1
    assert mean_pairwise_ncc(stack, mask) == pytest.approx(-1 / 3)
    assert mean_pairwise_ncc(np.stack([a, np.zeros_like(a)]), mask) == 0.0  # constant image
    # gradient of a: 1 along x (12 pairs), 4 along y (12 pairs); std of 0..15 = sqrt(255/12)
    expected = np.sqrt((12 * 1 + 12 * 16) / 24) / np.sqrt(255 / 12)
    assert invariance.detail(a[None], mask) == pytest.approx(expected)
    assert invariance.detail(np.zeros((1, 4, 4)), mask) == 0.0


def _fake_set(root, n_lights=3):
    rng = np.random.default_rng(0)
    folder = root / "ball"
    folder.mkdir(parents=True)
    y, x = np.mgrid[0:40, 0:50]
    mask = (x - 25) ** 2 + (y - 20) ** 2 < 15**2
    albedo = 0.5 + 0.4 * (((x // 4) + (y // 4)) % 2)
    for i in range(n_lights):
        shading = 0.3 + 0.6 * (x / 50 if i % 2 else y / 40)
        img = np.where(mask, albedo * shading, 0.05) + 0.01 * rng.standard_normal(mask.shape)
        cv2.imwrite(str(folder / f"ball.{i}.png"), np.rint(np.clip(img, 0, 1) * 255).astype(np.uint8))
    cv2.imwrite(str(folder / "ball.mask.png"), mask.astype(np.uint8) * 255)
    (root / "notes").mkdir()  # folders that are not objects are skipped
    return root


def test_main_writes_table_json_and_figure(tmp_path):
    data = _fake_set(tmp_path / "psm")
    methods = ["none", "dlcn", "clahe", "dog:sigma2=3.0"]
    result = invariance.main(data, tmp_path / "out", methods, erode=2, progress=False)
    saved = json.loads((tmp_path / "out" / "invariance.json").read_text())
    assert saved["methods"].keys() == set(methods)
    assert result["methods"]["dog:sigma2=3.0"]["detail"] != pytest.approx(
        invariance.main(data, tmp_path / "dog", ["dog"], erode=2, progress=False)["methods"]["dog"]["detail"]
    )
    assert (tmp_path / "out" / "invariance_ball.png").is_file()
    assert "| dlcn |" in (tmp_path / "out" / "invariance.md").read_text()
    for row in result["methods"].values():
        assert -1 <= row["agreement"] <= 1 and row["detail"] > 0
    # a checkerboard albedo under two gradient directions: DLCN removes the shading, raw does not
    assert result["methods"]["dlcn"]["agreement"] > result["methods"]["none"]["agreement"]


def test_bad_input(tmp_path):
    with pytest.raises(DatasetError):
        load_photometric(tmp_path)
    data = _fake_set(tmp_path / "psm")
    with pytest.raises(InputError):
        invariance.main(data, tmp_path / "o", ["nonexistent"])
    with pytest.raises(InputError):
        invariance.main(data, tmp_path / "o", ["none"], figure_object="cat")
    assert cli_main(["bench", "invariance", "--data", str(tmp_path / "missing"), "--out", str(tmp_path / "o")]) == 2
    # degenerate sets: an erosion that leaves no pixel (the mask's radius is 15 px), one wider than the 40x50
    # photographs, a negative one, an object under one light (NaN agreements)
    with pytest.raises(InputError, match="ball holds no pixel once eroded by 16 px: give a smaller --erode"):
        invariance.main(data, tmp_path / "o", ["none"], erode=16, progress=False)
    with pytest.raises(InputError, match=r"--erode 20 removes a disc wider than the photographs \(40 px"):
        invariance.main(data, tmp_path / "o", ["none"], erode=20, progress=False)
    with pytest.raises(InputError, match="erode must be >= 0"):
        invariance.main(data, tmp_path / "o", ["none"], erode=-1, progress=False)
    assert not (tmp_path / "o").exists()
    one = _fake_set(tmp_path / "one", n_lights=1)
    with pytest.raises(DatasetError, match="one photograph"):
        load_photometric(one)
    with pytest.raises(InputError, match="no method to compare"):  # `--methods ''` wrote an empty table
        invariance.main(data, tmp_path / "o", [], progress=False)


def test_a_mask_of_ones_and_an_object_without_a_mask_are_said(tmp_path, caplog):
    """A 0/1 mask (read as inside above 127) was refused as emptied by the erosion, "give a smaller erode", even at
    `--erode 0`; an object folder without a mask was skipped at DEBUG, its object missing from the table unsaid."""
    data = _fake_set(tmp_path / "psm")
    mask = cv2.imread(str(data / "ball" / "ball.mask.png"), cv2.IMREAD_GRAYSCALE)
    shutil.copytree(data / "ball", data / "cube")
    for path in (data / "cube").iterdir():
        path.rename(path.with_name(path.name.replace("ball.", "cube.")))
    (data / "cube" / "cube.mask.png").unlink()
    cv2.imwrite(str(data / "ball" / "ball.mask.png"), (mask > 0).astype(np.uint8))
    with pytest.raises(DatasetError, match=r"ball.mask.png: no pixel above 127; a mask is white \(255\)"):
        load_photometric(data)
    cv2.imwrite(str(data / "ball" / "ball.mask.png"), mask)
    assert [o.name for o in load_photometric(data)] == ["ball"]
    assert "skipping" in caplog.text and "cube: its images have no mask cube.mask.png" in caplog.text


def test_a_bad_weight_file_is_one_line_before_any_work(tmp_path, capsys, monkeypatch):
    data = _fake_set(tmp_path / "psm")
    monkeypatch.setattr(invariance, "load_photometric", lambda *a: pytest.fail("the benchmark started"))
    out = tmp_path / "o"
    argv = ["bench", "invariance", "--data", str(data), "--out", str(out)]
    assert cli_main([*argv, "--methods", "none,alcn:weights=some/detector.pt"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (
        "alcn bench invariance: error: method 'alcn:weights=some/detector.pt': weight file not found: some/detector.pt"
    )
    assert not out.exists()


def test_a_failing_run_is_reported_without_a_traceback(tmp_path, monkeypatch, caplog):
    from alcn_cv.enhance.registry import create

    def broken(self, gray):
        raise RuntimeError("boom")

    monkeypatch.setattr(type(create("dog")), "normalize", broken)
    data = _fake_set(tmp_path / "psm")
    result = invariance.main(data, tmp_path / "o", ["none", "dog"], erode=2, progress=False)
    assert result["methods"]["dog"]["error"] == "RuntimeError: boom" and "error" not in result["methods"]["none"]
    (record,) = [r for r in caplog.records if "dog" in r.getMessage()]
    assert not record.exc_info and record.getMessage() == "method dog failed: RuntimeError: boom"


def test_earlier_figures_go_and_long_labels_fit(tmp_path, monkeypatch):
    import shutil

    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from alcn_cv.enhance.alcn import ALCN

    data = _fake_set(tmp_path / "psm")
    out = tmp_path / "o"
    out.mkdir()
    (out / "invariance_cat.png").write_bytes(b"")  # an earlier run's figure, of another data set
    weights = tmp_path / "out" / "train1" / "alcn_normalizer.npz"
    weights.parent.mkdir(parents=True)
    shutil.copy(ALCN().weights_path, weights)
    spec = f"alcn:weights={weights}"
    figures = []
    real_save = invariance.save_figure
    monkeypatch.setattr(
        invariance, "save_figure", lambda plt, fig, path, **kw: figures.append(fig) or real_save(plt, fig, path, **kw)
    )
    invariance.main(data, out, ["none", spec], erode=2, progress=False)
    assert sorted(p.name for p in out.glob("invariance_*.png")) == ["invariance_ball.png"]
    (fig,) = figures
    label = next(ax for ax in fig.axes if ax.get_ylabel().startswith("alcn")).yaxis.label
    assert label.get_text().replace("\n", "") == spec  # the whole spec, on lines
    canvas = FigureCanvasAgg(fig)  # the figure is saved and closed: drawn again to lay its labels out
    canvas.draw()
    assert label.get_window_extent(canvas.get_renderer()).x0 >= 0  # inside the figure


@pytest.mark.shared_data
def test_real_photographs(shared_data, tmp_path):
    result = invariance.main(shared_data / "psm", tmp_path, ["none", "dog"], scale=0.25, progress=False)
    assert set(result["methods"]["none"]["objects"]) == {"buddha", "cat", "horse", "owl"}
    assert result["settings"]["lights"]["cat"] == 12
    assert result["methods"]["dog"]["detail"] > result["methods"]["none"]["detail"]


def test_report_states_machine_command_and_settings(tmp_path):
    _fake_set(tmp_path / "data")
    invariance.main(tmp_path / "data", tmp_path / "out", methods=["none", "dog:sigma2=2"], progress=False)
    md = (tmp_path / "out" / "invariance.md").read_text()
    assert "**Machine:**" in md and "**Settings:**" in md
    assert "alcn bench invariance --data" in md and "--methods none,dog:sigma2=2" in md


def test_an_interrupted_report_leaves_the_earlier_one_whole(tmp_path, monkeypatch):
    """The earlier run's figures were removed first, then the new table written, then the figures drawn: an interrupt
    between left a report without figures, or the new tables beside none. The report's files are replaced together."""
    data = _fake_set(tmp_path / "psm")
    out = tmp_path / "out"
    invariance.main(data, out, ["none", "dog"], erode=2, progress=False)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert set(before) == {"invariance.json", "invariance.md", "invariance_ball.png"}

    def interrupted(*args):
        raise KeyboardInterrupt

    monkeypatch.setattr(invariance, "_figure", interrupted)
    with pytest.raises(KeyboardInterrupt):
        invariance.main(data, out, ["none"], erode=2, progress=False, overwrite=True)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_twelve_bit_photographs_are_said_to_keep_few_grey_levels(tmp_path, caplog):
    """12-bit values in 16-bit PNGs kept 16 grey levels as 8 bits without a word, where `alcn bench relight` warns."""
    data = _fake_set(tmp_path / "psm")
    for path in (data / "ball").glob("ball.[0-9].png"):
        cv2.imwrite(str(path), cv2.imread(str(path), cv2.IMREAD_GRAYSCALE).astype(np.uint16) * 16)  # 12 bits
    with caplog.at_level("WARNING"):
        invariance.main(data, tmp_path / "out", ["none"], erode=2, progress=False)
    assert "object 'ball' (its brightest photograph" in caplog.text and "12-bit data in a 16-bit file?" in caplog.text


def test_without_matplotlib_the_tables_are_written_and_the_figure_said_missing(tmp_path, monkeypatch, caplog):
    """The README promises `alcn bench invariance` on the light install, which has no matplotlib: it failed on its
    figure, after the work, with nothing written."""
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # an import of it fails, find_spec finds none
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "invariance_ball.png").write_bytes(b"an earlier run's")
    invariance.main(_fake_set(tmp_path / "psm"), tmp_path / "out", ["none", "dlcn"], erode=2, progress=False)
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["invariance.json", "invariance.md"]
    assert "alcn bench invariance: matplotlib is not installed, so the report has no figure" in caplog.text
