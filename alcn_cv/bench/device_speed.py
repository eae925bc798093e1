"""``alcn bench speed --device DEV``: the batched torch path of ALCN on one device, beside kornia's DoG and CLAHE.

For each batch size, frames per second of:

* ``end to end``: :meth:`ALCN.apply_batch <alcn_cv.enhance.alcn.ALCN.apply_batch>`, host uint8 in and host uint8
  out (the upload, the conversion on the device, the output cast there, the download);
* ``on device``: the same computation on a uint8 batch already on the device, its uint8 output left there
  (:class:`alcn_cv.nn.ALCN2d`), in float32 and in float16;
* kornia's DoG (``gaussian_blur2d``, sigmas 1 and 2) and CLAHE (``equalize_clahe``) on the same device-resident
  float batch.

And the largest differences: the float16 module against the float32 one on the same image (the float16 one's
intensities), the float32 module's output of the image cast to float16 against that of the image, and the device
against the CPU (float32).
Timings are medians of rounds in which every method runs once in turn (they see the same load).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from alcn_cv.report import markdown_table

__all__ = ["device_markdown", "device_speed"]


def _median_ms(calls: dict[str, Callable[[], Any]], rounds: int, sync: Callable[[], None]) -> dict[str, float]:
    times: dict[str, list[float]] = {name: [] for name in calls}
    for call in calls.values():  # warm-up: kernels, caches, cuDNN's choices
        call()
    sync()
    for _ in range(rounds):
        for name, call in calls.items():
            start = time.perf_counter()
            call()
            sync()
            times[name].append(time.perf_counter() - start)
    return {name: 1e3 * float(np.median(t)) for name, t in times.items()}


def device_speed(device: str, frame: np.ndarray, batches: list[int], rounds: int) -> dict[str, Any]:
    """Measure the batched path on ``device`` with ``frame`` (``(H, W)`` uint8) repeated into batches.

    Returns:
        ``{"device", "size", "rows": [{"batch", "<method> fps", ...}], "half_max_abs", "half_image_max_abs",
        "device_vs_cpu_max_abs"}``.
    """
    import torch
    from kornia.enhance import equalize_clahe
    from kornia.filters import gaussian_blur2d

    from alcn_cv.enhance.alcn import ALCN
    from alcn_cv.nets.device import torch_device
    from alcn_cv.nn import ALCN2d

    dev = torch_device(device, "--device")
    sync = (lambda: torch.cuda.synchronize(dev)) if dev.type == "cuda" else (lambda: None)  # the device timed
    alcn = ALCN(backend="torch", device=str(dev), threads=None)
    module = ALCN2d().eval().to(dev)
    half = ALCN2d().eval().to(dev, torch.float16) if dev.type == "cuda" else None

    def on_device(net: torch.nn.Module, x: torch.Tensor, dtype: torch.dtype) -> torch.Tensor:
        unit = net(x.to(dtype) * (1.0 / 255))
        return torch.round(unit * 255).to(torch.uint8)

    def dog(x: torch.Tensor) -> torch.Tensor:
        return gaussian_blur2d(x, (7, 7), (1.0, 1.0)) - gaussian_blur2d(x, (13, 13), (2.0, 2.0))

    rows = []
    with torch.inference_mode():
        for batch in batches:
            host = np.repeat(frame[None], batch, axis=0)
            x = torch.from_numpy(host)[:, None].to(dev)
            unit = x.float() * (1.0 / 255)
            calls = {
                "end to end": lambda host=host: alcn.apply_batch(host),
                "on device": lambda x=x: on_device(module, x, torch.float32),
                "kornia dog": lambda unit=unit: dog(unit),
                "kornia clahe": lambda unit=unit: equalize_clahe(unit),
            }
            if half is not None:
                calls["on device float16"] = lambda x=x: on_device(half, x, torch.float16)
            ms = _median_ms(calls, rounds, sync)
            rows.append({"batch": batch, **{f"{name} fps": 1e3 * batch / t for name, t in ms.items()}})
        x = torch.from_numpy(frame)[None, None].float() * (1.0 / 255)
        full = module(x.to(dev)).float().cpu()
        cpu = ALCN2d().eval()(x)
        result = {
            "device": str(dev),
            "size": [frame.shape[1], frame.shape[0]],
            "rows": rows,
            "device_vs_cpu_max_abs": float((full - cpu).abs().max()) if dev.type != "cpu" else None,
            "half_max_abs": None,
            "half_image_max_abs": None,
        }
        if half is not None:
            x16 = x.to(dev, torch.float16)
            full16 = module(x16.float()).cpu()  # the float32 output of the intensities float16 holds
            result["half_max_abs"] = float((half(x16).float().cpu() - full16).abs().max())
            result["half_image_max_abs"] = float((full16 - full).abs().max())
    if dev.type == "cuda":
        result["gpu"] = torch.cuda.get_device_name(dev)
    return result


def device_markdown(result: dict[str, Any]) -> list[str]:
    """The device section of ``speed.md``."""
    names = [k for k in result["rows"][0] if k != "batch"]
    w, h = result["size"]
    gpu = f" ({result['gpu']})" if result.get("gpu") else ""
    lines = [
        f"## ALCN batched on {result['device']}{gpu}, {w}x{h} gray, frames per second",
        "",
        markdown_table(["batch", *names], [[r["batch"], *(r[n] for n in names)] for r in result["rows"]], digits=1),
        "",
        (
            f"Largest difference float16 / float32 on the device, on the same image: {result['half_max_abs']} "
            f"(the image cast to float16, in float32: {result['half_image_max_abs']}); "
            f"device / CPU (float32): {result['device_vs_cpu_max_abs']}."
        ),
    ]
    return lines
