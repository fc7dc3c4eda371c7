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
        why = str(e).splitlines()[0] if str(e) else type(e).__name__
        if why.startswith("Expected one of"):         # torch lists every device type it knows: too long to help
            why = "not a torch device type"
        raise ParameterError(f"device {device!r} is not usable here ({why[:120]}); a torch device is "
                             f"cpu, cuda or cuda:N") from None
    return dev
