#!/usr/bin/env bash
# The GPU checks of issue 40 in one short run (about 5 minutes) on a bare GPU machine that has Python and torch:
#   kornia (and whatever else is missing) from wheels carried in .whl/, the CUDA tests, then
#   `alcn bench speed --device cuda` (end to end host uint8 -> host uint8, on the device, float16, against the CPU,
#   beside kornia's DoG and CLAHE). Reports go to $GPU_CHECK_OUT (default runs/gpu_check; on a GPU machine, the
#   folder that comes back), with speed_gpu.json: the bench's JSON as docs/reports will hold it (recorded as this
#   script's run, $GPU_CHECK_OUT written OUT). Where the folder came back, publish it with
#   `python experiments/keep_gpu_check.py FOLDER` (experiments/report.py renders it). Both steps run whatever the
#   first gives; the exit status is the first failure's (0 when both pass). DEVICE=cpu rehearses the script on a
#   machine without a GPU (the CUDA tests skip, the bench measures the CPU, speed_gpu.json is written and
#   keep_gpu_check.py refuses it), so that a short GPU slot is not spent on a fault of the script itself.
# Fill .whl/ beforehand where a registry is reachable, for the GPU machine's Python (3.12 there, 3.11 here: a wheel of
# this machine's Python does not install there), e.g.
#   python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
#     --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 \
#     -d .whl kornia==0.9.0 kornia_rs
# On a GPU machine that gives back one folder: GPU_CHECK_OUT=THAT_FOLDER bash experiments/gpu_check.sh
set -uo pipefail
cd "$(dirname "$0")/.."
# absolute: the report to publish writes this folder as OUT, which a relative path would not match
GPU_CHECK_OUT=$(realpath -m "${GPU_CHECK_OUT:-runs/gpu_check}")
DEVICE=${DEVICE:-cuda}
# the CPU's batches are slow: two small ones rehearse the path (BATCHES overrides either default)
BATCHES=${BATCHES:-$([ "$DEVICE" = cpu ] && echo 1,2)}
mkdir -p "$GPU_CHECK_OUT"
PY=${PYTHON:-python3}
SITE=/tmp/site
export PYTHONPATH="$PWD:$SITE${PYTHONPATH:+:$PYTHONPATH}"
# the wheels only where kornia is missing (a bare GPU machine; not a checkout's own environment): each import of it
# imports torch, seconds of the slot
if ! "$PY" -c "import kornia" 2> /dev/null; then
  # one wheel pip cannot install (another Python's, say) stops the whole install: said here, not minutes later
  if compgen -G ".whl/*.whl" > /dev/null && ! "$PY" -m pip install --quiet --no-index --no-deps --target "$SITE" .whl/*.whl; then
    echo "gpu_check: the wheels in .whl/ do not install with $("$PY" --version 2>&1) (see the recipe at the top)" >&2
    exit 2
  fi
  if ! "$PY" -c "import kornia" 2> /dev/null; then
    echo "gpu_check: kornia does not import with $("$PY" --version 2>&1): carry its wheels in .whl/ (the recipe at the top)" >&2
    exit 2
  fi
fi
# the `alcn` command's subcommands are entry points of an installed alcn-cv, which a bare machine running the
# checkout from PYTHONPATH has not: its metadata written into $SITE (nothing where alcn-cv is installed)
if ! "$PY" - "$SITE" <<'PY'
import sys

sys.path.insert(0, "experiments")
from _run import install_metadata

if (written := install_metadata(sys.argv[1])) is not None:
    print(f"gpu_check: alcn-cv is not installed here: its commands from {written}")
PY
then
  echo "gpu_check: alcn-cv's commands could not be set up (above)" >&2
  exit 2
fi
{
  nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv 2>&1
  "$PY" - <<'PY'
import importlib
for name in ("torch", "kornia", "cv2", "numpy", "tqdm", "pytest"):
    try:
        module = importlib.import_module(name)
        print(name, getattr(module, "__version__", "?"))
    except Exception as exc:  # a missing module is reported, and the steps that need it fail below
        print(name, "MISSING:", exc)
import torch
print("cuda", torch.cuda.is_available(), torch.version.cuda, torch.cuda.get_device_name(0) if torch.cuda.is_available() else "")
PY
} > "$GPU_CHECK_OUT/environment.txt" 2>&1
cat "$GPU_CHECK_OUT/environment.txt"

# The CUDA tests (they skip with a reason where torch sees no GPU; -rs lists the reasons); an earlier run's report is
# removed first, so that a run killed by the timeout leaves none to be read for it
rm -f "$GPU_CHECK_OUT/cuda_tests.xml"
timeout 150 "$PY" -m pytest -q -rs -p no:cacheprovider --junitxml="$GPU_CHECK_OUT/cuda_tests.xml" \
  tests/test_nn.py tests/test_speed_paths.py tests/test_cli_normalize.py -k "cuda" 2>&1 | tee "$GPU_CHECK_OUT/cuda_tests.txt" | tail -15
tests_status=${PIPESTATUS[0]}

# The measurement (writes speed.json and speed.md).
timeout 240 "$PY" -m alcn_cv.cli bench speed --device "$DEVICE" ${BATCHES:+--device-batches "$BATCHES"} \
  --out "$GPU_CHECK_OUT/speed_$DEVICE" --overwrite 2>&1 | tee "$GPU_CHECK_OUT/speed_$DEVICE.txt" | tail -25
bench_status=${PIPESTATUS[0]}
# The report to publish, into the folder that comes back; failing to write it fails the bench step.
if [ "$bench_status" -eq 0 ]; then
  "$PY" - "$GPU_CHECK_OUT/speed_$DEVICE/speed.json" "$GPU_CHECK_OUT" <<'PY' || bench_status=$?
import sys

sys.path.insert(0, "experiments")
from _run import write_for_keeping

write_for_keeping(sys.argv[1], "speed_gpu", sys.argv[2], script="experiments/gpu_check.sh")
PY
fi
echo "reports in $GPU_CHECK_OUT (CUDA tests: exit status $tests_status; bench: $bench_status)"
if [ "$tests_status" -ne 0 ]; then exit "$tests_status"; fi
exit "$bench_status"
