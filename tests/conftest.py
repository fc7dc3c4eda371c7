import os

if os.environ.get("PYTEST_XDIST_WORKER"):
    # One thread per worker for the math libraries (read when they load, so before numpy/torch do):
    # `-n 2` on two cores with each worker's torch and OpenBLAS taking both cores runs 5-10x slower.
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    os.environ.setdefault("MKL_NUM_THREADS", "1")

from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from hypothesis import settings  # noqa: E402

# deterministic property tests: the same examples on every run and machine, no example database
settings.register_profile("lfcodec", derandomize=True, database=None, deadline=None)
settings.load_profile("lfcodec")

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("LFC_SHARED", ROOT.parent / "shared"))
DATA = SHARED / "data"


def shared_scene(name: str) -> Path:
    p = DATA / name
    if not p.exists():
        pytest.skip(f"shared scene {name} not available at {p}")
    return p


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


@pytest.fixture
def failing_write(monkeypatch):
    """``failing_write(module, name, why)``: that module's ``write_image`` raises a SceneError
    (with ``why``) for files called ``name`` and writes every other file."""
    from formats.errors import SceneError

    def install(module, name: str, why: str = "test"):
        real = module.write_image

        def write(path, px):
            if path.name == name:
                raise SceneError(f"{path}: cannot write ({why})")
            real(path, px)

        monkeypatch.setattr(module, "write_image", write)

    return install
