"""Export the Normalizer to ONNX, for the torch-free OpenCV runtime (:mod:`alcn_cv.nets.opencv_runtime`).

For the paper's and the lite Normalizers the exported graph is the fully-convolutional part
(Sec. 3.3): it maps an image that is *already padded* by reflect-101 to the mixture weights on
its grid of stride ``s`` (4 for the paper's Normalizer, 8 for the lite one)::

    input  "image":   (B, 1, s * (gh - 1) + 48, s * (gw - 1) + 48) float32, intensities in [0, 1]
    output "weights": (B, N, gh, gw) float32

The lite Normalizer's graph takes that padded image cut into 4x4 blocks
(:func:`alcn_cv.nets.opencv_runtime.image_blocks`), its first convolution (4x4, stride 4) turned into a 1x1
one over the blocks' 16 pixels: input ``"blocks"``, ``(B, 16, (s * (gh - 1) + 48) / 4, (s * (gw - 1) + 48) / 4)``.

Grid point ``(i, j)`` is the window of the *unpadded* image centred on pixel ``(s*i, s*j)``,
exactly as :meth:`alcn_cv.nets.Normalizer.dense_grid`, which pads by 24 pixels on the top and
left and ``s * (gh - 1) + 24 - H`` on the bottom (the same on the right); the padding stays
outside the graph so that the graph has no data-dependent indexing and every ONNX runtime
(``cv2.dnn`` included) runs it.

The gain Normalizer (:class:`~alcn_cv.nets.gain.GainNormalizer`, ``architecture: "gain"``)
computes its features on its grid of stride ``s`` (8) in the runtime
(:class:`alcn_cv.nets.opencv_runtime.GainFeatures`: its only full-resolution part, the cell moments, and
the grid's blurs), so that the graph is :meth:`~alcn_cv.nets.gain.GainNormalizer.maps_from_features`, the
grid's convolutions::

    input  "features": (B, 4, gh, gw) float32, GainNormalizer.features of the image
    output "weights":  (B, N, gh, gw) float32, the maps F_k

with ``gh = ceil((H-1)/s)+1`` (``gw`` the same) for an ``H x W`` image at the working scale (1). Its
reflect-101 borders are ONNX ``Pad`` nodes (mode ``reflect``) whose pads are constants: torch writes each as
a chain of nodes that computes them (a ``Slice`` of step -1 that its constant folding leaves), which OpenCV 4's
ONNX importer cannot read (:func:`_constant_reflect_pads`). OpenCV 5's ``cv2.dnn`` also applies a pad that
exceeds a small grid (the ONNX standard leaves that case undefined; OpenCV 4 refuses it, see
:meth:`alcn_cv.nets.opencv_runtime.OpenCVNormalizer.dense_grid`).

The runtime tells the three kinds apart by their input's name. Both spatial sizes are dynamic.

The weight file's header (sigmas, working scale, output range, trained) is stored in the ONNX
model's ``metadata_props`` under the key ``alcn_cv``, so the ``.onnx`` describes itself.
"""

from __future__ import annotations

import contextlib
import copy
import io
import json
import logging
import threading
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import torch
from torch import nn
from torch.onnx import symbolic_helper

from alcn_cv.errors import InputError
from alcn_cv.io import atomic_write, output_path
from alcn_cv.nets.lite import LiteNormalizer, normalizer_from_file
from alcn_cv.nets.normalizer import WINDOW
from alcn_cv.nets.opencv_runtime import (
    BLOCKS_INPUT,
    FEATURES_INPUT,
    IMAGE_INPUT,
    LITE_BLOCK,
    image_blocks,
)
from alcn_cv.runtime import resolve_weights
from alcn_cv.weight_file import ONNX_METADATA_KEY, load_normalizer_file

__all__ = ["OPSET", "export_onnx"]

logger = logging.getLogger(__name__)

#: ONNX opset of the export (read by OpenCV 4.x and 5.x).
OPSET = 17


class _DenseGrid(nn.Module):
    """The Normalizer's grid of weights as the export's graph (see the module docstring): from a padded
    image for the paper's and the lite Normalizers, from the features for the gain one."""

    def __init__(self, net: nn.Module, from_features: bool) -> None:
        super().__init__()
        self.net = net
        self.from_features = from_features

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net.maps_from_features(x) if self.from_features else self.net._weights(x)


def export_onnx(out: str | Path, weights: str | Path | None = None) -> Path:
    """Write the Normalizer of a weight file as an ONNX model (atomically).

    Args:
        out: the ``.onnx`` path to write.
        weights: a Normalizer weight file (``.npz``); default: the default model's (``createALCN()``'s).

    Returns:
        The written path.

    Raises:
        WeightFileError: missing or corrupt weight file.
        InputError: ``out`` is not a ``.onnx`` path, or cannot be written.
    """
    out = output_path(out, ".onnx", "an ONNX export")
    weight_file = load_normalizer_file(resolve_weights(None, weights))
    net = normalizer_from_file(weight_file).eval()
    from_features = weight_file.meta.get("architecture") == "gain"
    if from_features:  # a grid larger than every pad of the graph (cv2.dnn takes any size)
        example, input_name = torch.randn(1, 4, WINDOW, WINDOW + 8), FEATURES_INPUT
    else:
        example, input_name = torch.rand(1, 1, WINDOW + net.stride * 3, WINDOW + net.stride * 5), IMAGE_INPUT
        if isinstance(net, LiteNormalizer):
            net, input_name = _on_blocks(net), BLOCKS_INPUT
            example = torch.from_numpy(image_blocks(example[0, 0].numpy()))
    buffer = io.BytesIO()
    with torch.no_grad(), warnings.catch_warnings(), _constant_reflect_pads():
        # dynamo=False: the TorchScript exporter needs no onnxscript and handles this plain
        # convolutional graph; torch deprecates it in favour of the dynamo exporter.
        warnings.simplefilter("ignore", DeprecationWarning)
        # The shape checks of the Python code are constants of the trace, as they should be.
        warnings.simplefilter("ignore", torch.jit.TracerWarning)
        torch.onnx.export(
            _DenseGrid(net, from_features),
            (example,),
            buffer,
            input_names=[input_name],
            output_names=["weights"],
            dynamic_axes={
                input_name: {0: "batch", 2: "height", 3: "width"},
                "weights": {0: "batch", 2: "grid_height", 3: "grid_width"},
            },
            opset_version=OPSET,
            dynamo=False,
        )
    data = with_metadata(buffer.getvalue(), weight_file.meta)
    atomic_write(out, data)
    logger.info("Normalizer exported to %s (%d kB)", out, len(data) // 1024)
    return out


@symbolic_helper.parse_args("v", "is", "s", "none")
def _reflect_pad(g: Any, x: torch._C.Value, padding: list[int], mode: str, value: None) -> torch._C.Value:
    """``aten::pad`` (``F.pad``, the Normalizers' only pads, all reflect-101) as one ONNX ``Pad`` of constant
    pads."""
    rank = x.type().dim()
    if mode != "reflect" or rank is None:
        # an invariant of the Normalizers, not of the user's input
        raise RuntimeError(f"the export writes reflect pads of tensors of a known rank, got mode {mode!r}, rank {rank}")
    # torch's pads: (begin, end) of the last dimension, then of the one before...; ONNX's: every begin, then every end
    pairs = [(0, 0)] * (rank - len(padding) // 2) + [padding[i : i + 2] for i in range(0, len(padding), 2)][::-1]
    pads = g.op("Constant", value_t=torch.tensor([p[0] for p in pairs] + [p[1] for p in pairs], dtype=torch.int64))
    return g.op("Pad", x, pads, mode_s="reflect")


@contextlib.contextmanager
def _constant_reflect_pads() -> Iterator[None]:
    """Within: torch's reflect pads exported by :func:`_reflect_pad`, ONNX ``Pad`` nodes whose pads are one
    ``Constant`` (opset :data:`OPSET`). torch's own symbolic computes them from the pad list in a chain of nodes
    (``ConstantOfShape``, ``Concat``, ``Reshape``, ``Slice`` of step -1, ``Transpose``, ``Reshape``, ``Cast``)
    that its constant folding leaves (it folds no ``Slice`` of negative step), and OpenCV 4's ONNX importer fails
    on that chain's ``Reshape``: with constant pads the gain Normalizers' exports run on OpenCV 4 (from 4.8) as on 5.

    The registration is torch's process-wide one: an export runs one at a time (:data:`_EXPORTING`), and a custom
    ``aten::pad`` symbolic registered by the caller for the same opset is replaced by torch's own at the end."""
    with _EXPORTING:
        torch.onnx.register_custom_op_symbolic("aten::pad", _reflect_pad, OPSET)
        try:
            yield
        finally:  # torch's own symbolic again
            torch.onnx.unregister_custom_op_symbolic("aten::pad", OPSET)


#: One export at a time: :func:`_constant_reflect_pads` changes torch's process-wide symbolic registry.
_EXPORTING = threading.Lock()


def _on_blocks(net: LiteNormalizer) -> LiteNormalizer:
    """A copy of the lite Normalizer on :func:`~alcn_cv.nets.opencv_runtime.image_blocks`: its first
    convolution (4x4, stride 4) as the same sums over the blocks' channels (1x1)."""
    first = net.features[0]
    if first.kernel_size != (LITE_BLOCK, LITE_BLOCK) or first.stride != (LITE_BLOCK, LITE_BLOCK):
        raise InputError(
            f"the lite Normalizer's first convolution must be {LITE_BLOCK}x{LITE_BLOCK} with stride {LITE_BLOCK}"
        )
    on_blocks = copy.deepcopy(net)
    on_blocks.features[0] = nn.Conv2d(LITE_BLOCK * LITE_BLOCK, first.out_channels, 1)
    with torch.no_grad():
        on_blocks.features[0].weight.copy_(first.weight.reshape(first.out_channels, LITE_BLOCK * LITE_BLOCK, 1, 1))
        on_blocks.features[0].bias.copy_(first.bias)
    return on_blocks


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
    entry.key, entry.value = ONNX_METADATA_KEY, json.dumps(header)
    onnx.checker.check_model(model)
    return model.SerializeToString()
