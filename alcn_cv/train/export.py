"""Export the Normalizer to ONNX, for the torch-free OpenCV runtime (:mod:`alcn_cv.nets.opencv_runtime`).

For the paper's and the lite Normalizers the exported graph is the fully-convolutional part
(Sec. 3.3): it maps an image that is *already padded* by reflect-101 to the mixture weights on
its grid of stride ``s`` (4 for the paper's Normalizer, 8 for the lite one)::

    input  "image":   (B, 1, s * (gh - 1) + 48, s * (gw - 1) + 48) float32, intensities in [0, 1]
    output "weights": (B, N, gh, gw) float32

Grid point ``(i, j)`` is the window of the *unpadded* image centred on pixel ``(s*i, s*j)``,
exactly as :meth:`alcn_cv.nets.Normalizer.dense_grid`, which pads by 24 pixels on the top and
left and ``s * (gh - 1) + 24 - H`` on the bottom (the same on the right); the padding stays
outside the graph so that the graph has no data-dependent indexing and every ONNX runtime
(``cv2.dnn`` included) runs it.

The gain Normalizer (:class:`~alcn_cv.nets.gain.GainNormalizer`, ``architecture: "gain"``)
computes its cell statistics from the image itself, so its graph is the whole
:meth:`~alcn_cv.nets.gain.GainNormalizer.dense_grid` at its own stride ``s`` (8), on the raw
image at the working scale (1)::

    input  "image":   (B, 1, H, W) float32, intensities in [0, 1]
    output "weights": (B, N, ceil((H-1)/s)+1, ceil((W-1)/s)+1) float32, the maps F_k

The runtime tells the two kinds apart by running them (a 48-pixel input gives one grid point to
a padded-input graph, several to the gain graph). Both spatial sizes are dynamic.

The weight file's header (sigmas, working scale, output range, trained) is stored in the ONNX
model's ``metadata_props`` under the key ``alcn_cv``, so the ``.onnx`` describes itself.
"""

from __future__ import annotations

import io
import json
import logging
import warnings
from pathlib import Path

import torch
from torch import nn

from alcn_cv.errors import InputError
from alcn_cv.io import atomic_write
from alcn_cv.nets.lite import normalizer_from_file
from alcn_cv.nets.normalizer import WINDOW
from alcn_cv.nets.opencv_runtime import DEFAULT_ONNX
from alcn_cv.weight_file import load_normalizer_file

__all__ = ["DEFAULT_ONNX", "OPSET", "export_onnx"]

logger = logging.getLogger(__name__)

#: ONNX opset of the export (read by OpenCV 4.x and 5.x).
OPSET = 17
METADATA_KEY = "alcn_cv"


class _DenseGrid(nn.Module):
    """The Normalizer's grid of weights as the export's graph (see the module docstring): on a
    padded image for the paper's and the lite Normalizers, on the image for the gain one."""

    def __init__(self, net: nn.Module, raw_image: bool) -> None:
        super().__init__()
        self.net = net
        self.raw_image = raw_image

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        return self.net.dense_grid(image) if self.raw_image else self.net._weights(image)


def export_onnx(out: str | Path, weights: str | Path | None = None) -> Path:
    """Write the Normalizer of a weight file as an ONNX model (atomically).

    Args:
        out: the ``.onnx`` path to write.
        weights: a Normalizer weight file (``.npz``); default: the one shipped in the package.

    Returns:
        The written path.

    Raises:
        WeightFileError: missing or corrupt weight file.
        InputError: ``out`` is not a ``.onnx`` path.
    """
    out = Path(out)
    if out.suffix != ".onnx":
        raise InputError(f"the ONNX output must end in .onnx, got {out}")
    weight_file = load_normalizer_file(weights)
    net = normalizer_from_file(weight_file).eval()
    raw_image = weight_file.meta.get("architecture") == "gain"
    example = torch.rand(1, 1, WINDOW + net.stride * 3, WINDOW + net.stride * 5)
    buffer = io.BytesIO()
    with torch.no_grad(), warnings.catch_warnings():
        # dynamo=False: the TorchScript exporter needs no onnxscript and handles this plain
        # convolutional graph; torch deprecates it in favour of the dynamo exporter.
        warnings.simplefilter("ignore", DeprecationWarning)
        # The shape checks of the Python code are constants of the trace, as they should be.
        warnings.simplefilter("ignore", torch.jit.TracerWarning)
        # The gain graph's index arithmetic has slices the exporter leaves unfolded (harmless).
        warnings.filterwarnings("ignore", message="Constant folding", category=UserWarning)
        torch.onnx.export(
            _DenseGrid(net, raw_image), (example,), buffer, input_names=["image"], output_names=["weights"],
            dynamic_axes={"image": {0: "batch", 2: "height", 3: "width"},
                          "weights": {0: "batch", 2: "grid_height", 3: "grid_width"}},
            opset_version=OPSET, dynamo=False,
        )
    data = with_metadata(buffer.getvalue(), weight_file.meta)
    atomic_write(out, data)
    logger.info("Normalizer exported to %s (%d kB)", out, len(data) // 1024)
    return out


def with_metadata(model_bytes: bytes, meta: dict) -> bytes:
    """Add the weight file's header to the model's ``metadata_props`` (needs the ``onnx`` package)."""
    try:
        import onnx
    except ImportError:
        logger.warning("the onnx package is not installed: the ONNX file holds no alcn_cv metadata")
        return model_bytes
    model = onnx.load_from_string(model_bytes)
    header = {k: v for k, v in meta.items() if k != "training"}
    entry = model.metadata_props.add()
    entry.key, entry.value = METADATA_KEY, json.dumps(header)
    onnx.checker.check_model(model)
    return model.SerializeToString()

