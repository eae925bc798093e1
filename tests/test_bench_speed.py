"""``alcn bench speed``: the report is written and well formed (no timing assertions)."""

import dataclasses
import json

import numpy as np
import pytest

from alcn_cv import InputError
from alcn_cv.bench import speed

METHODS = [
    "none",
    "clahe",
    "alcn",
    "alcn exact",
    "alcn grid16 pyramid",
    "alcn lite",
    "alcn lite exact",
    "alcn torch cpu",
    "alcn gain-lite",
]


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("speed")
    result = speed.main(out, dataclasses.replace(speed.CONFS["quick"], methods=METHODS, video_frames=2))
    return out, result


def test_files_are_written(report):
    out, result = report
    assert json.loads((out / "speed.json").read_text()) == result
    assert (out / "speed.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    md = (out / "speed.md").read_text()
    assert "| x dog |" in md and "## Accuracy" in md and "## Memory over a video" in md
    for label in METHODS + ["dog"]:
        assert f"| {label} |" in md
    assert not result["errors"]
    assert "load_average_1_5_15" in result["machine_before"]


def test_every_case_has_every_method_and_its_ratio_to_dog(report):
    _, result = report
    rows = result["rows"]
    cases = {(r["width"], r["height"], r["colour"]) for r in rows}
    assert cases == {(w, h, c) for w, h in speed.QUICK_SIZES for c in speed.COLOURS}
    for case in cases:
        in_case = {r["method"]: r for r in rows if (r["width"], r["height"], r["colour"]) == case}
        assert set(in_case) == set(METHODS) | {"dog"}
        assert in_case["dog"]["ratio_to_dog"] == 1.0
        for r in in_case.values():
            assert r["median_ms"] > 0 and r["iqr_ms"] >= 0 and r["repeats"] == 2
            np.testing.assert_allclose(r["ratio_to_dog"], r["median_ms"] / in_case["dog"]["median_ms"])
            np.testing.assert_allclose(r["fps"], 1e3 / r["median_ms"])
            assert r["traced_peak_mb"] >= 0
            assert ("network_ms" in r) == r["method"].startswith("alcn")


def test_accuracy_is_measured_against_the_exact_path(report):
    _, result = report
    acc = {(a["method"], a["width"]) for a in result["accuracy"]}
    others = (
        "alcn grid16 pyramid",
        "alcn lite",
        "alcn lite exact",
    )  # the paper family; the gain ones are their own method
    assert acc == {(m, w) for m in others for w, _ in speed.QUICK_SIZES}
    by_case = {(a["method"], a["width"]): a for a in result["accuracy"]}
    for a in result["accuracy"]:
        assert 0 <= a["mean_abs"] <= a["max_abs"] and np.isfinite(a["max_rel_range"])
    for w, _ in speed.QUICK_SIZES:
        # the pyramid adds its error to the distillation's
        assert by_case["alcn lite", w]["max_abs"] >= by_case["alcn lite exact", w]["max_abs"] - 1e-3


def test_video_memory_is_recorded(report):
    _, result = report
    videos = [v["method"] for v in result["video"]]
    assert videos[0] == "alcn" and len(videos) <= 2  # the default, and the fastest when another one
    for v in result["video"]:
        assert v["frames"] == 2 and len(v["rss_mb"]) == 2 and v["rss_max_mb"] >= v["rss_first_mb"] > 0


def test_time_calls_counts():
    calls = []
    times = speed.time_calls(lambda: calls.append(1), warmup=2, min_repeats=3, max_repeats=5, budget_s=0.0)
    assert len(times) == 3 and len(calls) == 5
    times = speed.time_calls(lambda: None, warmup=0, min_repeats=1, max_repeats=4, budget_s=60.0)
    assert len(times) == 4
    order = []
    rounds = speed._time_rounds({"a": lambda: order.append("a"), "b": lambda: order.append("b")}, 2, 3, 0.0)
    assert order == ["a", "b", "a", "b"] and [len(t) for t in rounds.values()] == [2, 2]  # in turns


def test_weight_files_given_replace_the_variants_shipped_models():
    """--weights / --lite-weights: every variant of the paper's family is built from the file given."""
    from alcn_cv.runtime import MODELS

    methods = speed.default_methods(weights=MODELS["paper"], lite_weights=MODELS["lite"], cuda=False)
    variants = [m for m in methods if m.label in speed.ALCN_VARIANTS]
    assert variants and all("model" not in m.params for m in variants)
    for method in variants:
        assert method.factory().weights_path in (MODELS["paper"], MODELS["lite"])


def test_bad_arguments(tmp_path):
    with pytest.raises(InputError, match="unknown method"):
        speed.main(tmp_path, dataclasses.replace(speed.CONFS["quick"], methods=["alcn turbo"]))
    with pytest.raises(InputError, match="colours"):
        speed.main(tmp_path, dataclasses.replace(speed.CONFS["quick"], colours=["rgba"]))
    # no timed run: a median of none (np.percentile's IndexError after the build of every method)
    with pytest.raises(InputError, match="min_repeats"):
        speed.main(tmp_path, dataclasses.replace(speed.CONFS["quick"], min_repeats=0))
    with pytest.raises(InputError, match="device_batches"):
        speed.main(tmp_path, dataclasses.replace(speed.CONFS["quick"], device="cpu", device_batches=[]))
    # a video method the run does not time: named up front, not a StopIteration after every timing
    quick = dataclasses.replace(speed.CONFS["quick"], methods=["none"], video_methods=["alcn lite"])
    with pytest.raises(InputError, match=r"video method\(s\) \['alcn lite'\]"):
        speed.main(tmp_path, quick)


def test_cli_is_registered(tmp_path):
    import argparse

    from alcn_cv.bench import cli

    parser = argparse.ArgumentParser()
    cli.add_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(
        ["bench", "speed", "--out", str(tmp_path), "--conf", "quick", "--sizes", "64x48", "--methods", "none"]
    )
    assert (
        args.func is cli._run_speed and args.conf == "quick" and args.sizes == [(64, 48)] and args.methods == ["none"]
    )


def test_report_states_machine_command_and_settings(report):
    out, result = report
    md = (out / "speed.md").read_text()
    assert "**Machine:**" in md and "**Settings:**" in md and f"`{result['command']}`" in md
    assert result["command"].startswith("alcn bench speed --out ") and "--sizes 64x48,96x72" in result["command"]


def test_targets_are_reported(report):
    out, result = report
    targets = result["targets"]
    # the default against 2 and 4 DoGs, its lite variant, the lite paper-family ALCN, the frame rate, the
    # torch-free backend, the torch backend on the CPU, DLCN, ..., fresh processes with and without kept memory, ...
    assert len(targets["summary"]) == 16
    for backend in ("torch-free backend", "torch backend on the CPU"):
        assert any(backend in r["target"] and r["measured"] > 0 for r in targets["summary"])
    for row in targets["summary"]:
        assert set(row) == {"target", "measured", "goal", "met", "note"}
    assert {r["method"] for r in targets["contract"]} == set(__import__("alcn_cv").available())
    assert [r["threads"] for r in targets["threads"]] == [1, None] and all(
        r["torch_threads_kept"] for r in targets["threads"]
    )
    assert {r["method"] for r in targets["memory"]} == {"alcn", "dog"}
    fresh = targets["fresh_processes"]
    assert set(fresh) == {"alcn glibc", "alcn kept", "dog glibc", "dog kept"}
    assert all(r["ms"] > 0 and r["page_faults_per_call"] >= 0 for r in fresh.values())
    assert targets["video"]["frames"] >= 2 and targets["video"]["normalize_s"] > 0
    # the float16 network (autocast) against float32: its features and head in float32 (4e-4 on a photograph)
    assert "cpu" in targets["batched"] and targets["batched"]["cpu"]["half_max_abs"] < 1e-3
    assert {"network_ms", "mixture_ms", "contract_ms", "apply_ms"} <= set(targets["stages"]["alcn"]) and targets[
        "profile"
    ]
    md = (out / "speed.md").read_text()
    assert md.index("## Targets") < md.index("## Time") and "Where the time goes" in md


def test_device_run_measures_the_batched_path_beside_kornia(tmp_path):
    """``--device cpu`` runs here what ``--device cuda`` runs on a GPU: every method at every batch size, written."""
    pytest.importorskip("kornia")
    settings = dataclasses.replace(speed.CONFS["quick"], device="cpu", device_batches=[1, 2], target_size=(64, 48))
    result = speed.main(tmp_path, settings)
    rows = json.loads((tmp_path / "speed.json").read_text())["device"]["rows"]
    assert [r["batch"] for r in rows] == [1, 2] and rows == result["rows"]
    for row in rows:
        for name in ("end to end", "on device", "kornia dog", "kornia clahe"):
            assert row[f"{name} fps"] > 0
    assert "--device cpu" in result["command"] and "kornia clahe fps" in (tmp_path / "speed.md").read_text()
    if _cuda():
        pytest.skip("a GPU is present")
    with pytest.raises(InputError, match="--device"):  # overwrite: the device is what is refused, not the report above
        speed.main(tmp_path, dataclasses.replace(settings, device="cuda:7"), overwrite=True)


def _cuda() -> bool:
    import torch

    return torch.cuda.is_available()


def test_each_target_is_met_exactly_when_its_measured_value_reaches_its_goal(report):
    _, result = report
    checked = 0
    for row in result["targets"]["summary"]:
        if row["met"] is None:
            continue
        op, bound = row["goal"].split()[:2]
        if op == "about":  # "about 1": within 10 %
            op, bound = "<=", "1.1"
        bound = float(bound.rstrip(":"))
        measured = row["measured"]
        assert row["met"] == {"<=": measured <= bound, ">=": measured >= bound, "<": measured < bound}[op], row
        checked += 1
    assert checked >= 13


def test_the_targets_ratios_are_those_of_the_times_measured(report):
    _, result = report
    t = result["targets"]["times_ms"]
    measured = {row["target"]: row["measured"] for row in result["targets"]["summary"]}

    def of(start):
        (value,) = [v for name, v in measured.items() if name.startswith(start)]
        return value

    assert of("default ALCN (the gain Normalizer) / raw DoG") == pytest.approx(t["alcn gray"] / t["dog raw"])
    assert of("its lite variant") == pytest.approx(t["alcn gain-lite gray"] / t["dog raw"])
    assert of("lite paper-family ALCN") == pytest.approx(t["alcn lite gray"] / t["dog raw"])
    assert of("default ALCN fps") == pytest.approx(1e3 / t["alcn gray small"])
    assert of("torch-free backend") == pytest.approx(t["alcn gray"] / t["alcn fast gray"])
    assert of("torch backend on the CPU") == pytest.approx(t["alcn torch gray"] / t["alcn gray"])
    assert of("default ALCN / DLCN") == pytest.approx(t["alcn gray"] / t["dlcn gray"])
    assert of("BGR / gray") == pytest.approx(t["alcn bgr"] / t["alcn gray"])
