import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

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
