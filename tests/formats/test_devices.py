"""`--device auto` finds out whether a GPU is there without importing torch where none can be."""
import subprocess
import sys

import formats.devices as D


def _probe(trace: str) -> list[str]:
    """(answer, torch imported) in a fresh interpreter on "Linux" whose only GPU trace is ``trace``."""
    code = ("import sys; import formats.devices as D; "
            f"D._GPU_TRACES = ({trace!r},); sys.platform = 'linux'; "
            "print(D.cuda_available(), 'torch' in sys.modules)")
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()


def test_no_gpu_traces_no_torch_import():
    """Without any GPU driver file (Linux) the answer is False and torch is not imported (it costs
    ~1.6 s of a one-frame `lfcodec render`); with one, torch is imported and asked."""
    assert _probe("/nowhere/nvidiactl") == ["False", "False"]
    got = _probe(sys.executable)                               # (a file that exists: "a driver")
    assert got[1] == "True"
    import torch

    assert got[0] == str(torch.cuda.is_available())


def test_torch_already_imported_decides(monkeypatch):
    import torch

    class FakeCuda:
        @staticmethod
        def is_available():
            return True

    monkeypatch.setattr(torch, "cuda", FakeCuda)
    monkeypatch.setattr(D.os.path, "exists", lambda p: False)
    assert D.cuda_available() is True


def test_render_auto_on_a_cpu_box_is_numpy():
    from rlfc.render_ops import NumpyOps, make_ops

    if not D.cuda_available():
        assert isinstance(make_ops("auto"), NumpyOps)
