"""Publish the GPU report of experiments/gpu_check.sh: on the GPU machine the script writes, beside its other reports
in $GPU_CHECK_OUT (the folder that comes back), speed_gpu.json, its bench's report as published (recorded as the
shell script's run, the run folder written OUT); this copies it to docs/reports/speed_gpu.json (experiments/report.py
renders it). A report of another command than the published one's replaces it only with --keep; the CPU
rehearsal's (DEVICE=cpu) measured no GPU and is refused, as is a run whose CUDA tests failed (its cuda_tests.xml).

    python experiments/keep_gpu_check.py FOLDER          # FOLDER: the $GPU_CHECK_OUT that came back
"""

from __future__ import annotations

import json
from pathlib import Path
from xml.etree import ElementTree

from _run import command_line, publish

from alcn_cv.cli import run_script

NAME = "speed_gpu"


def main() -> None:
    parser = command_line(__doc__)
    parser.add_argument("folder", type=Path, help="the GPU run's $GPU_CHECK_OUT, as it came back")
    args = parser.parse_args()
    path = args.folder / f"{NAME}.json"
    if not path.is_file():
        parser.error(f"{path} not found: give the folder a GPU run of `bash experiments/gpu_check.sh` wrote")
    device = str(json.loads(path.read_text(encoding="utf-8")).get("device", {}).get("device"))
    if not device.startswith("cuda"):
        parser.error(f"{path} measured on {device}, not a GPU (the CPU rehearsal's report): not published")
    tests = args.folder / "cuda_tests.xml"  # the CUDA tests of the same run (pytest's JUnit XML)
    if not tests.is_file():
        parser.error(f"{tests} not found: the run's CUDA tests did not report; not published")
    try:
        root = ElementTree.parse(tests).getroot()
    except ElementTree.ParseError as exc:
        parser.error(f"{tests}: unreadable ({exc}): not published")
    suite = root if root.tag == "testsuite" else root.find("testsuite")
    if suite is None:
        parser.error(f"{tests}: no test suite in it: not published")
    counts = {key: int(suite.get(key, 0)) for key in ("tests", "skipped", "failures", "errors")}
    if counts["failures"] + counts["errors"]:
        parser.error(f"{tests}: {counts['failures'] + counts['errors']} CUDA test(s) failed: not published")
    if counts["tests"] - counts["skipped"] <= 0:  # every one skipped (no GPU seen), or none selected
        parser.error(f"{tests}: no CUDA test ran ({counts['skipped']} skipped): not published")
    publish(path, replace=args.keep)


if __name__ == "__main__":
    run_script(main)
