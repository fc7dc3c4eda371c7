"""The torch device a caller names, checked once for every package (numpy-only code never
imports this module, so torch is imported only where a device is asked for)."""
from __future__ import annotations

import os
import sys

from .errors import ParameterError

#: device nodes and driver files of which at least one exists where torch can see a GPU on Linux:
#: NVIDIA's driver, WSL2's GPU paravirtualization, AMD's ROCm (torch.cuda serves it)
_GPU_TRACES = ("/dev/nvidiactl", "/dev/nvidia0", "/proc/driver/nvidia", "/dev/dxg", "/dev/kfd")


def cuda_available() -> bool:
    """``torch.cuda.is_available()``, without importing torch (about 1.6 s) where no GPU driver
    can be there: on Linux without any of :data:`_GPU_TRACES`, and on macOS (no CUDA). Where torch
    is already imported, or elsewhere, torch is asked."""
    if "torch" not in sys.modules:
        if sys.platform == "darwin":
            return False
        if sys.platform.startswith("linux") and not any(os.path.exists(p) for p in _GPU_TRACES):
            return False
    import torch

    return bool(torch.cuda.is_available())


def torch_device(device: str | None = None):
    """``torch.device(device)`` (None: CUDA when present, else the CPU), checked by placing a
    tensor there: a ParameterError where torch does not know the name or cannot use it (a CUDA
    device without CUDA)."""
    import torch

    try:
        dev = torch.device(("cuda" if torch.cuda.is_available() else "cpu") if device is None else device)
        torch.zeros(1, device=dev)
    except (RuntimeError, AssertionError, ValueError, TypeError) as e:
        why = str(e).splitlines()[0] if str(e) else type(e).__name__
        if why.startswith("Expected one of"):         # torch lists every device type it knows: too long to help
            why = "not a torch device type"
        raise ParameterError(f"device {device!r} is not usable here ({why[:120]}); a torch device is "
                             f"cpu, cuda or cuda:N") from None
    return dev
