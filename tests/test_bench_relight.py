"""The benchmark on real changes of light: protocols, tuning, report."""

from __future__ import annotations

import json
import sys

import cv2
import numpy as np
import pytest

from alcn_cv.bench import relight, relight_settings
from alcn_cv.cli import build_parser
from alcn_cv.cli import main as cli_main
from alcn_cv.data.scenes import Scene
from alcn_cv.errors import InputError
from scene_sets import lit, make_sets, texture, write_scene

SMALL = relight_settings.Settings(patch=16, patches=40, gallery=2, max_pairs=4, keypoints=300)


def test_protocols_on_identical_frames():
    frame = lit(texture())[0]
    scene = Scene("same", "test", np.stack([frame] * 3), ("a", "b", "c"))
    plan = relight.plan_pairs(scene, 0, SMALL)
    assert len(plan.gallery) == 2 and len(plan.pairs) == 4 and all(g != f for g, f in plan.pairs)
    locations = plan.locations[plan.gallery[0]]
    assert len(locations) == 40 and len(np.unique(locations, axis=0)) == 40
    assert (locations >= 0).all() and (locations[:, 0] <= 120 - 16).all() and (locations[:, 1] <= 160 - 16).all()
    # identity normalization on identical frames: every protocol is perfect
    result = relight.evaluate_scene(relight.build_method("none"), scene, [plan], SMALL)
    m = result["metrics"]
    assert m["identification"] == [100.0] and m["pose_orb"] == [100.0] and m["pose_sift"] == [100.0]
    assert m["matching_sift"][0] > 80 and m["matching_orb"][0] > 80
    # the count of correct matches is the matching score's numerator (identical frames: equal keypoint counts)
    n_sift = len(cv2.SIFT_create(nfeatures=SMALL.keypoints).detect(frame, None))
    assert m["correct_sift"][0] == pytest.approx(m["matching_sift"][0] / 100 * n_sift)
    assert relight.identification(frame / 255.0, np.zeros_like(frame, float), locations, 16) < 0.1
    # the same seed draws the same plan; another seed another one
    again = relight.plan_pairs(scene, 0, SMALL)
    assert again.pairs == plan.pairs and all((again.locations[g] == plan.locations[g]).all() for g in plan.gallery)


def test_identification_registers_a_pair_to_the_pixel():
    """The frames of a fixed webcam are 1-3 px apart: a pair is registered by the one move, within shift_px, that
    best aligns its patches (a smooth output, which tolerates the shift, was rewarded over a sharp one); a registered
    pair keeps its score, and a patch's impostors get no moves of their own."""
    rng = np.random.default_rng(0)
    gallery = cv2.GaussianBlur(rng.random((128, 160), dtype=np.float32), (0, 0), 0.5)
    locations = np.array([(y, x) for y in range(8, 96, 16) for x in range(8, 128, 16)])
    moved = np.roll(gallery, (2, -1), axis=(0, 1))  # the camera moved by 2 px down, 1 left
    assert relight.identification(gallery, moved, locations, 32) < 0.1
    assert relight.identification(gallery, moved, locations, 32, shift=2) == 1.0
    noisy = gallery + rng.normal(0, 2.0, gallery.shape).astype(np.float32)
    plain = relight.identification(gallery, noisy, locations, 32)
    assert 0 < plain < 1 and relight.identification(gallery, noisy, locations, 32, shift=2) == plain
    with pytest.raises(InputError, match="shift_px"):
        relight_settings.Settings(shift_px=-1).check()


def test_a_keypoint_is_matched_once():
    """Two keypoints of the first frame nearest to the same one of the second (ORB finds one corner at several
    pyramid levels) count once, by the nearer: the matching score is a fraction of the keypoints."""
    d2 = np.array([[0, 0, 0, 0], [100, 100, 100, 100], [200, 0, 200, 0]], np.float32)
    d1 = np.array([[1, 0, 0, 0], [0, 3, 0, 0], [101, 100, 100, 100], [50, 50, 50, 50]], np.float32)
    pairs = relight.one_to_one_matches(d1, d2, cv2.NORM_L2, 0.8)
    assert pairs.tolist() == [[0, 0], [2, 1]]  # d1[1] is also nearest to d2[0], farther; d1[3] fails the ratio test
    points = np.zeros((4, 2), np.float32)
    score, _, correct = relight.keypoint_scores((points, d1), (points[:3], d2), cv2.NORM_L2, (8, 8), SMALL)
    assert correct == 2 and score == pytest.approx(2 / 3)
    assert relight.one_to_one_matches(None, d2, cv2.NORM_L2, 0.8).shape == (0, 2)


def test_a_flat_gallery_frame_is_named():
    """No textured patch: identification of none was argmax's ValueError (of one, a trivial 100%)."""
    from alcn_cv.errors import DatasetError

    frames = np.stack([np.full((64, 64), 90, np.uint8), lit(texture(64, 64))[0]])
    scene = Scene("dim", "test", frames, ("night.png", "day.png"))
    with pytest.raises(DatasetError, match="'dim': frame night.png has 0 textured 16x16"):
        relight.plan_pairs(scene, 0, relight_settings.Settings(patch=16, gallery=2))


def test_textured_locations_avoid_flat_regions():
    frame = np.zeros((64, 128), np.uint8)
    frame[:, 64:] = np.rint(texture(64, 64) * 255)
    locs = relight.patch_locations(frame, 16, 100, np.random.default_rng(0))
    assert (locs[:, 1] >= 64 - 16).all()  # only patches overlapping the texture


def test_local_standardization_composite():
    norm = relight.build_method("dog:sigma2=3.0+lstd")
    assert isinstance(norm, relight.LocallyStandardized) and norm.inner.sigma2 == 3.0
    out = norm.apply(lit(texture())[2], out_dtype=np.float32)
    assert out.dtype == np.float32 and out.min() >= 0 and out.max() <= 1
    with pytest.raises(InputError):
        relight.build_method("nonexistent+lstd")


def test_main_writes_the_report(tmp_path):
    root = make_sets(tmp_path / "data")
    result = relight.main(
        tmp_path / "out",
        [root / "webcam", root / "psm"],
        ["none", "dog", "dog+lstd"],
        train_scenes=["square"],
        test_scenes=["street", "psm"],
        seeds=[0, 1],
        settings=SMALL,
        tune_frames=3,
        progress=False,
    )
    saved = json.loads((tmp_path / "out" / "relight.json").read_text())
    assert set(saved["methods"]) == {"none", "dog", "dog+lstd", "dog (tuned)", "dog+lstd (tuned)"}
    assert saved["split"] == {"mode": "train/test", "train": ["square"], "test": ["street", "ball"]}
    chosen = result["tuning"]["dog"]["all"]["chosen"]
    assert chosen in saved["settings"]["tuning_grids"]["dog"] and len(result["tuning"]["dog"]["all"]["scores"]) == 8
    row = result["methods"]["dog"]
    assert set(row["scenes"]) == {"street", "ball", "square"}
    assert len(row["mean_test"]["identification"]["seeds"]) == 2
    for metric in relight.METRICS:
        assert 0 <= row["mean_test"][metric]["mean"] <= (1e9 if metric in relight.COUNT_METRICS else 100)
    # gains and a gradient on a fine texture: a band-pass identifies better than the raw frames
    assert (
        row["mean_test"]["identification"]["mean"] >= result["methods"]["none"]["mean_test"]["identification"]["mean"]
    )
    text = (tmp_path / "out" / "relight.md").read_text()
    assert "| dog (tuned) |" in text and "Patch identification" in text and "± " in text
    assert (tmp_path / "out" / "relight.png").stat().st_size > 0
    # every row after the first against the first, paired by seed: in the JSON and as a table of the Markdown
    paired = saved["paired_differences"]
    assert paired["reference"] == "none" and list(paired["methods"]) == list(saved["methods"])[1:]
    diff = paired["methods"]["dog"]["identification"]
    seeds = {m: saved["methods"][m]["mean_test"]["identification"]["seeds"] for m in ("none", "dog")}
    assert diff["seeds"] == pytest.approx(np.subtract(seeds["dog"], seeds["none"]).tolist())
    section = text.split("## Difference from `none` (paired by seed, on the means over the test scenes)\n")[1]
    table = section.split("\n## ")[0]
    assert "seeds [0, 1] ± their sample standard deviation" in table
    assert f"| dog | {diff['mean']:+.1f} ± {diff['std']:.1f} |" in table


def test_the_report_says_what_small_frames_held_of_the_sampling_asked(tmp_path, caplog):
    """On frames too small or too few for the patches and gallery frames asked, relight.md gave the counts asked and
    their chance level (0.67% where 5 locations of 64x64 frames made it 20%)."""
    from dataclasses import replace

    root = make_sets(tmp_path / "data")
    asked = replace(SMALL, patches=100_000, gallery=50)
    result = relight.main(
        tmp_path / "out",
        [root / "psm"],
        ["none"],
        test_scenes=["psm"],
        seeds=[0],
        settings=asked,
        tuning=False,
        progress=False,
    )
    scene = result["scenes"]["ball"]
    assert scene["fewest_patches"] < asked.patches and scene["fewest_gallery_frames"] == scene["frames"] < asked.gallery
    text = (tmp_path / "out" / "relight.md").read_text()
    chance = 100 / scene["fewest_patches"]
    assert f"as few as {scene['fewest_patches']} patch locations, chance {chance:.1f}%; " in text
    assert f"{scene['fewest_gallery_frames']} gallery frames)" in text and "scene ball: as few as" in caplog.text


def test_paired_differences_by_hand():
    """Each row after the first minus the first, seed by seed; a row or metric without test means is left out."""
    methods = {
        "alcn": {"mean_test": {"identification": {"seeds": [80.0, 90.0, 85.0]}, "pose_sift": {"seeds": [50, 60, 70]}}},
        "failed": {"errors": {"street": "boom"}},
        "dog": {"mean_test": {"identification": {"seeds": [70.0, 85.0, 86.0]}, "pose_sift": {"seeds": [40, 65, 70]}}},
        "no pose": {"mean_test": {"identification": {"seeds": [80.0, 90.0, 85.0]}}},
    }
    paired = relight.paired_differences(methods)
    assert paired["reference"] == "alcn" and list(paired["methods"]) == ["dog", "no pose"]
    dog = paired["methods"]["dog"]
    # identification: -10, -5, +1: mean -14/3, squared deviations (16 + 1 + 289) / 9, over n - 1 = 2
    assert dog["identification"]["seeds"] == [-10, -5, 1]
    assert (dog["identification"]["mean"], dog["identification"]["std"]) == pytest.approx((-14 / 3, (91 / 3) ** 0.5))
    # pose: -10, +5, 0: mean -5/3, squared deviations (625 + 400 + 25) / 9, over 2
    assert dog["pose_sift"]["seeds"] == [-10, 5, 0]
    assert (dog["pose_sift"]["mean"], dog["pose_sift"]["std"]) == pytest.approx((-5 / 3, (175 / 3) ** 0.5))
    assert paired["methods"]["no pose"] == {"identification": {"seeds": [0.0, 0.0, 0.0], "mean": 0.0, "std": 0.0}}
    # one seed: the difference alone; no reference or nothing to compare: none
    one = relight.paired_differences({"a": {"mean_test": {"pose_orb": {"seeds": [40.0]}}}, "b": methods["no pose"]})
    assert one["methods"] == {"b": {}}
    one = relight.paired_differences(
        {m: {"mean_test": {"pose_orb": {"seeds": [s]}}} for m, s in (("a", 40), ("b", 45))}
    )
    assert one["methods"] == {"b": {"pose_orb": {"seeds": [5.0], "mean": 5.0, "std": 0.0}}}
    assert relight.paired_differences({"failed": methods["failed"], "dog": methods["dog"]}) == {}
    assert relight.paired_differences({"alcn": methods["alcn"]}) == {}


def test_leave_one_out_and_cli(tmp_path):
    root = make_sets(tmp_path / "data")
    args = [
        "bench",
        "relight",
        "--out",
        str(tmp_path / "loo"),
        "--data",
        str(root / "webcam"),
        str(root / "psm"),
        "--methods",
        "none,slcn",
        "--leave-one-out",
        "street",
        "square",
        "ball",
        "--seeds",
        "3",
        "--patch",
        "16",
        "--patches",
        "30",
        "--max-pairs",
        "3",
        "--no-keypoints",
        "--tune-frames",
        "3",
    ]
    assert cli_main(args) == 0
    saved = json.loads((tmp_path / "loo" / "relight.json").read_text())
    assert saved["split"]["mode"] == "leave-one-out" and saved["split"]["train"] == []
    assert set(saved["tuning"]["slcn"]) == {"street", "square", "ball"}  # one fold per held-out scene
    tuned = saved["methods"]["slcn (tuned)"]
    assert {n: tuned["specs"][n] for n in tuned["specs"]} == {
        n: saved["tuning"]["slcn"][n]["chosen"] for n in tuned["specs"]
    }
    assert "matching_orb" not in tuned["mean_test"]
    assert (
        cli_main(
            [
                "bench",
                "relight",
                "--out",
                str(tmp_path / "x"),
                "--data",
                str(root / "webcam"),
                "--test-scenes",
                "mexico",
            ]
        )
        == 2
    )


@pytest.mark.shared_data
def test_real_photometric_stereo(shared_data, tmp_path):
    settings = relight_settings.Settings(patches=60, gallery=1, max_pairs=3, keypoints=300)
    result = relight.main(
        tmp_path,
        [shared_data / "psm"],
        ["none", "dog"],
        train_scenes=["cat"],
        test_scenes=["owl"],
        seeds=[0],
        settings=settings,
        max_frames=4,
        tuning=False,
        progress=False,
    )
    assert result["scenes"]["owl"]["frames"] == 4 and result["scenes"]["owl"]["size"] == [512, 340]
    for label in ("none", "dog"):
        assert 100 / 60 < result["methods"][label]["mean_test"]["identification"]["mean"] <= 100  # above chance
    assert (tmp_path / "relight.md").is_file() and (tmp_path / "relight.png").is_file()


@pytest.mark.parametrize("method", list(relight.TUNING_GRIDS))
def test_tuning_grids_have_one_size_and_start_at_the_default(method):
    grid = relight.TUNING_GRIDS[method]
    assert len(grid) == 8 and len({tuple(p.items()) for p in grid}) == 8
    first, default = relight.build_method(relight._spec(method, grid[0])), relight.build_method(method)

    def public(n: object) -> dict:  # the parameters, not the OpenCV objects built from them
        return {k: v for k, v in vars(n.inner if method.endswith("+lstd") else n).items() if not k.startswith("_")}

    assert public(first) == public(default)


@pytest.mark.parametrize("method", ["clahe", "sqi"])
def test_clahe_and_sqi_are_tuned_with_the_others(method, tmp_path):
    grid = relight.TUNING_GRIDS[method]
    if method == "clahe":
        assert {"clipLimit": 4.0, "tileGridSize": (8, 8)} in grid  # Jenicek & Chum, ICCV 2019
    assert set(relight.DEFAULT_METHODS) - set(relight.TUNING_GRIDS) == {"none", "alcn", "alcn:model=lite"}
    root = make_sets(tmp_path / "data")
    result = relight.main(
        tmp_path / "out",
        [root / "webcam", root / "psm"],
        ["none", method],
        train_scenes=["square"],
        test_scenes=["street"],
        seeds=[0],
        settings=relight_settings.Settings(
            patch=16, patches=40, gallery=1, max_pairs=2, keypoints=200, keypoint_protocols=False
        ),
        tune_frames=3,
        progress=False,
    )
    tuning = result["tuning"][method]["all"]
    assert len(tuning["scores"]) == 8 and tuning["chosen"] in tuning["scores"]
    assert tuning["chosen"] in {relight._spec(method, p) for p in grid}
    chosen = relight.build_method(tuning["chosen"])
    if method == "clahe":
        assert [chosen.clipLimit, *chosen.tileGridSize] in [[p["clipLimit"], *p["tileGridSize"]] for p in grid]
    else:
        assert {"sigmas": chosen.sigmas, "eps": chosen.eps} in grid
    row = result["methods"][f"{method} (tuned)"]
    assert row["tuned"] and 0 < row["mean_test"]["identification"]["mean"] <= 100


def test_each_method_is_built_once_per_run(tmp_path, monkeypatch):
    """A method keeps nothing from one scene to the next: the run builds each spec once (a tuned one at its first
    scene, after the tuning built it), not once per scene, so an ALCN's weight file is not read again per scene."""
    builds: list[str] = []
    build_method = relight.build_method

    def counted(spec: str):
        builds.append(spec)
        return build_method(spec)

    monkeypatch.setattr(relight, "build_method", counted)
    root = make_sets(tmp_path / "data")
    result = relight.main(
        tmp_path / "out",
        [root / "webcam", root / "psm"],
        ["none", "alcn:model=gain-lite", "dog"],
        train_scenes=["square"],
        test_scenes=["street", "psm"],
        seeds=[0],
        settings=relight_settings.Settings(patch=16, patches=20, gallery=1, max_pairs=2, keypoint_protocols=False),
        tune_frames=3,
        progress=False,
    )
    assert len(result["methods"]["none"]["scenes"]) == 3  # street, ball and square
    assert builds.count("none") == builds.count("alcn:model=gain-lite") == builds.count("dog") == 1
    assert builds.count(result["tuning"]["dog"]["all"]["chosen"]) == 2  # its tuning's, then the run's


def test_one_seed_prints_bare_numbers_and_each_alcn_backend(tmp_path):
    root = make_sets(tmp_path / "data")
    result = relight.main(
        tmp_path / "out",
        [root / "webcam"],
        ["none", "alcn", "alcn:model=lite+lstd"],
        train_scenes=["square"],
        test_scenes=["street"],
        seeds=[0],
        settings=relight_settings.Settings(patch=16, patches=30, gallery=1, max_pairs=2, keypoint_protocols=False),
        tuning=False,
        progress=False,
    )
    text = (tmp_path / "out" / "relight.md").read_text()
    # one seed: no "± 0.0", which reads as a measured zero spread, in the tables nor in the paired differences
    assert "±" not in text.split("Cells:", 1)[1] and "one seed (0), so no spread" in text
    identification = result["methods"]["none"]["mean_test"]["identification"]["mean"]
    assert f"| none | {identification:.1f} |" in text
    difference = result["methods"]["alcn"]["mean_test"]["identification"]["mean"] - identification
    assert f"| alcn | {difference:+.1f} |" in text.split("## Difference from `none`")[1]
    # the time of an ALCN method depends on what ran it: recorded and shown beside its ms/frame
    saved = json.loads((tmp_path / "out" / "relight.json").read_text())
    backends = {label: r.get("backend") for label, r in saved["methods"].items()}
    assert backends == {"none": None, "alcn": "opencv", "alcn:model=lite+lstd": "opencv"}
    summary = text.split("## Summary")[1].split("\n## ")[0]
    rows = {line.split(" | ")[0]: line for line in summary.splitlines() if line.startswith("| ")}
    assert rows["| method"].endswith("| ms/frame | backend |")
    assert rows["| alcn"].endswith("| opencv |") and rows["| none"].endswith("| - |")


@pytest.mark.parametrize(
    ("tuning", "said"),
    [
        (True, "No tuning: none of the methods listed has a tuning grid (default parameters only)."),
        (False, "No tuning asked (`--no-tune`: default parameters only)."),
    ],
)
def test_the_report_says_what_was_tuned_when_nothing_was(tuning, said, tmp_path):
    """Tuning asked of methods without a grid tunes none: the JSON's ``settings.tuning`` says so, as the Markdown."""
    root = make_sets(tmp_path / "data")
    settings = relight_settings.Settings(patch=16, patches=20, gallery=1, max_pairs=2, keypoint_protocols=False)
    out = tmp_path / "out"
    webcam = [root / "webcam"]
    relight.main(out, webcam, ["none", "he"], ["square"], ["street"], seeds=[0], settings=settings, tuning=tuning)
    saved = json.loads((out / "relight.json").read_text())
    assert saved["settings"]["tuning"] is False and saved["settings"]["tuning_requested"] is tuning
    assert saved["tuning"] == {} and saved["settings"]["tuning_grids"] == {}
    text = (out / "relight.md").read_text()
    assert said in text and "; train square." in text  # a training scene evaluated, not tuned on


@pytest.mark.parametrize(
    ("methods", "message"),
    [
        (["dog:sigma1=-1", "none"], "method 'dog:sigma1=-1': sigma1 must be positive"),
        (["unet:weights=missing.npz", "none"], "method 'unet:weights=missing.npz': weight file not found"),
        (["none", "dog", "none"], "method 'none' is listed twice"),
    ],
)
def test_a_bad_method_is_named_before_any_data_is_read(methods, message, tmp_path):
    with pytest.raises(InputError, match=message) as error:
        relight.main(tmp_path / "out", [tmp_path / "no data"], methods)
    assert len(str(error.value).splitlines()) == 1


def test_seeds_must_be_distinct(tmp_path):
    # a repeated seed would count its draw twice in the spread; refused before any data is read
    with pytest.raises(InputError, match="distinct"):
        relight.main(tmp_path / "out", [tmp_path / "no data"], seeds=[0, 0])


@pytest.mark.parametrize("given", [["0", "1", "2"], ["0,1,2"], ["0,1", "2"]])
def test_seeds_take_spaces_and_commas(given):
    parsed = build_parser().parse_args(["bench", "relight", "--out", "o", "--seeds", *given])
    assert parsed.seeds == [0, 1, 2]


def test_a_seed_that_is_no_integer_is_one_clear_error(capsys):
    with pytest.raises(SystemExit) as exit_:
        build_parser().parse_args(["bench", "relight", "--out", "o", "--seeds", "0", "1.5"])
    assert exit_.value.code == 2
    assert (
        capsys.readouterr()
        .err.splitlines()[-1]
        .endswith("argument --seeds: a seed is an integer (e.g. --seeds 0 1 2 or 0,1,2), got '1.5'")
    )


def test_quick_preset_and_the_options_that_override_it(tmp_path):
    root = make_sets(tmp_path / "data")
    common = ["bench", "relight", "--data", str(root / "webcam"), "--train-scenes", "square", "--test-scenes"]
    common += ["street", "--methods", "none", "--seeds", "0", "--patch", "16", "--no-keypoints", "--no-tune"]
    args = ["--out", str(tmp_path / "q"), "--conf", "quick", "--patches", "30", "--n-features", "300", "--no-progress"]
    assert cli_main([*common, *args]) == 0
    settings = json.loads((tmp_path / "q" / "relight.json").read_text())["settings"]
    assert settings["keypoints"] == 300  # --n-features, as the pose commands name it
    quick = relight_settings.CONFS["quick"]
    # the preset's sampling sizes, but an option given with it wins
    assert (settings["max_frames"], settings["max_pairs"], settings["patches"]) == (
        quick.max_frames,
        quick.max_pairs,
        30,
    )
    parsed = build_parser().parse_args(["bench", "relight", "--out", "o"])
    assert parsed.conf == "default" and parsed.max_frames is None  # the preset applies in the handler


def _distinct(n):
    return np.eye(n, dtype=np.float32) * 100  # keypoint i of one frame matches keypoint i of the other


def test_identification_counts_a_flat_patch_as_not_identified():
    gallery = np.zeros((16, 32), np.float32)
    gallery[:, 16:] = np.random.default_rng(0).random((16, 16), dtype=np.float32)
    locations = np.array([[0, 0], [0, 16]])
    # the flat patch correlates 0 with every patch: argmax picks index 0, its own, which must not count
    assert relight.identification(gallery, gallery, locations, 16) == 0.5


def test_a_match_is_correct_within_match_px_of_its_keypoint():
    settings = relight_settings.Settings()
    assert settings.match_px == 3.0  # the protocol's threshold (README / report)
    src = np.array([[10, 10], [40, 10], [10, 40], [40, 40], [70, 70]], np.float32)
    dst = src + np.array([[3, 0], [0, 3], [3.5, 0], [0, 3.5], [2, 2]], np.float32)  # 3, 3, 3.5, 3.5, 2.83 px
    score, _, correct = relight.keypoint_scores(
        (src, _distinct(5)), (dst, _distinct(5)), cv2.NORM_L2, (100, 100), settings
    )
    assert correct == 3 and score == pytest.approx(3 / 5)


def test_pose_succeeds_only_when_every_corner_moves_less_than_pose_px():
    settings = relight_settings.Settings()
    assert settings.pose_px == 5.0
    grid = np.stack(np.meshgrid(np.arange(0, 400, 50), np.arange(0, 100, 25)), -1).reshape(-1, 2).astype(np.float32)

    def pose(scale):
        pair = (grid, _distinct(len(grid))), (grid * np.float32(scale), _distinct(len(grid)))
        return relight.keypoint_scores(*pair, cv2.NORM_L2, (100, 400), settings)[1]

    # scaled about the corner (0, 0): the far corner (399, 99) moves 411 * (scale - 1) px
    assert pose(1.01) == 1.0  # 4.1 px at most
    assert pose(1.02) == 0.0  # 8.2 px at the far corner (4.5 px on average over the four)


def test_without_matplotlib_the_report_is_written_without_its_figure(tmp_path, monkeypatch, caplog):
    """`alcn bench relight` needs no extra (the README): without matplotlib it ran the whole benchmark and then failed
    on its figure, writing nothing. It says so before the work and writes the tables."""
    root = make_sets(tmp_path / "data")
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    args = dict(test_scenes=["street"], seeds=[0], settings=SMALL, tuning=False, progress=False)
    relight.main(tmp_path / "out", [root / "webcam"], ["none", "dog"], **args)
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["relight.json", "relight.md"]
    assert "alcn bench relight: matplotlib is not installed, so the report has no figure" in caplog.text


def test_textured_locations_are_the_more_textured_half():
    """Of the grid's candidates, only those of at least the median gradient energy are drawn: on a frame half weakly
    and half strongly textured, every location touches the strong half (or the edge between them). Keeping every
    candidate with some energy (the median dropped) drew patches of the weak half, where a method's identification
    is mostly noise."""
    frame = np.zeros((64, 128), np.uint8)
    frame[:, :64] = np.rint(texture(64, 64, seed=1) * 40)
    frame[:, 64:] = np.rint(texture(64, 64) * 255)
    locs = relight.patch_locations(frame, 16, 200, np.random.default_rng(0))
    # 7 x 15 candidates of stride 8: the upper half is 53 of 105; a patch at x = 48 ends on the edge at x = 64
    assert len(locs) == 53 and (locs[:, 1] >= 48).all()


def test_tuning_chooses_the_best_scoring_setting_and_the_first_of_equals(tmp_path, monkeypatch):
    """``tune`` keeps the setting of the highest mean identification, the first (the default) among equals. A
    minimum for a maximum (or the last of equals) still named a setting of the grid, which the run's test checked."""
    scenes = []
    for i in range(2):
        folder = write_scene(tmp_path / f"s{i}", frames=3, seed=i, noise=0.3)
        files = sorted(folder.glob("*.png"))
        frames = np.stack([cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in files])
        scenes.append(Scene(f"s{i}", "train", frames, tuple(p.name for p in files)))
    tuned = relight.tune("dog", scenes, SMALL, frames=3)
    scores = tuned["scores"]
    assert max(scores.values()) - min(scores.values()) > 20  # the grid's settings score apart on these scenes
    assert scores[tuned["chosen"]] == max(scores.values())
    # every setting scoring the same: the first, the default
    monkeypatch.setattr(relight, "evaluate_scene", lambda *args: {"metrics": {"identification": [50.0]}})
    default = relight._spec("dog", relight.TUNING_GRIDS["dog"][0])
    assert relight.tune("dog", scenes, SMALL, frames=3)["chosen"] == default


def test_pose_succeeds_only_strictly_below_pose_px():
    """ "Less than pose_px", as the report says: a homography moving every corner by exactly ``pose_px`` is a failure.
    A translation by (3, 4) moves each corner 5 px; the threshold is set to the distance the benchmark's own
    homography gives (cv2.findHomography, as in keypoint_scores), so rounding cannot decide the case."""
    grid = np.stack(np.meshgrid(np.arange(0, 400, 50), np.arange(0, 100, 25)), -1).reshape(-1, 2).astype(np.float32)
    moved = grid + np.float32([3, 4])
    homography, _ = cv2.findHomography(grid, moved, cv2.RANSAC, relight_settings.Settings().ransac_px)
    corners = np.array([[[0, 0]], [[399, 0]], [[399, 99]], [[0, 99]]], np.float64)
    largest = float(np.linalg.norm(cv2.perspectiveTransform(corners, homography) - corners, axis=2).max())
    assert largest == pytest.approx(5.0, abs=1e-9)

    def pose(pose_px: float) -> float:
        settings = relight_settings.Settings(pose_px=pose_px, match_px=6.0)
        pair = (grid, _distinct(len(grid))), (moved, _distinct(len(grid)))
        return relight.keypoint_scores(*pair, cv2.NORM_L2, (100, 400), settings)[1]

    assert pose(largest) == 0.0 and pose(np.nextafter(largest, np.inf)) == 1.0


def test_matches_pass_lowes_ratio_test_of_the_settings():
    """A match is kept only when its nearest descriptor is nearer than ``ratio`` times the second nearest. Comparing
    the two distances alone (the ratio ignored) kept every match but ties, so ``--ratio`` changed nothing."""
    d2 = np.array([[0, 0, 0, 0], [10, 0, 0, 0], [0, 100, 0, 0]], np.float32)
    d1 = np.array([[4.5, 0, 0, 0], [0, 99, 0, 0]], np.float32)  # d1[0]: 4.5 and 5.5 away (ratio 0.82); d1[1]: 1, 99
    assert relight.one_to_one_matches(d1, d2, cv2.NORM_L2, 0.8).tolist() == [[1, 2]]
    assert relight.one_to_one_matches(d1, d2, cv2.NORM_L2, 0.85).tolist() == [[0, 0], [1, 2]]
