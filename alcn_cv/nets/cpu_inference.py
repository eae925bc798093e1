"""Inference on the CPU: where the Normalizers take faster kernels than torch's own.

Both paths give torch's values to float rounding (about 2e-7), and only where nothing is recorded (no gradient, no
trace, no ONNX export, no ``torch.compile``, no ``torch.func`` transform), so training, exports and compiled graphs
keep torch's operations.
:func:`cpu_eager` admits autograd as well, for a kernel that comes with its own backward.
"""

from __future__ import annotations

import torch

from alcn_cv.filters.equalization import tanh

__all__ = ["cpu_eager", "cpu_inference", "tanh_", "transformed"]


#: torch's private test for a tensor of a torch.func transform, resolved once: None on a torch without it.
_IS_WRAPPED = getattr(getattr(torch._C, "_functorch", None), "is_functorch_wrapped_tensor", None)


def transformed(x: torch.Tensor) -> bool:
    """Whether ``x`` is a tensor of a ``torch.func`` transform (``vmap``, ``grad``), whose values cannot be read (on
    a torch without the private check this asks, whether its data pointer cannot be read)."""
    if _IS_WRAPPED is not None:
        return bool(_IS_WRAPPED(x))
    try:
        x.data_ptr()
    except RuntimeError:
        return True
    return False


def cpu_eager(x: torch.Tensor) -> bool:
    """Whether ``x`` is float32 on the CPU and no trace, export, compilation or ``torch.func`` transform records what
    is done to it (autograd may: a kernel run here needs a backward of its own)."""
    return not (
        x.device.type != "cpu"
        or x.dtype != torch.float32
        or torch.jit.is_tracing()
        or torch.onnx.is_in_onnx_export()
        or torch.compiler.is_compiling()
        or transformed(x)
    )


def cpu_inference(x: torch.Tensor) -> bool:
    """Whether ``x`` is float32 on the CPU and no gradient, trace, export, compilation or ``torch.func`` transform
    records what is done to it."""
    return not torch.is_grad_enabled() and cpu_eager(x)


def tanh_(x: torch.Tensor) -> torch.Tensor:
    """``tanh`` in place on a CPU tensor, returned: a contiguous float32 one by the OpenCV runtimes' own
    :func:`~alcn_cv.filters.equalization.tanh` (faster than torch's on the CPU), another (float16 under autocast,
    the channels-last output of a channels-last module's layer) by torch.

    Example:
        >>> tanh_(torch.zeros(2)).tolist()
        [0.0, 0.0]
    """
    if x.dtype != torch.float32 or not x.is_contiguous():
        return x.tanh_()
    array = x.numpy()
    tanh(array, out=array)
    return x
