"""The torch device a caller names, checked once for every package (numpy-only code never
imports this module, so torch is imported only where a device is asked for)."""
from __future__ import annotations

from .errors import ParameterError


def torch_device(device: str | None = None):
    """``torch.device(device)`` (None: CUDA when present, else the CPU), checked by placing a
    tensor there: a ParameterError where torch does not know the name or cannot use it (a CUDA
    device without CUDA)."""
    import torch

    try:
        dev = torch.device(("cuda" if torch.cuda.is_available() else "cpu") if device is None else device)
        torch.zeros(1, device=dev)
    except (RuntimeError, AssertionError, ValueError, TypeError) as e:
        raise ParameterError(f"device {device!r} is not usable here ({str(e).splitlines()[0][:120]})") from None
    return dev
