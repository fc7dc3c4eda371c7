import os
from pathlib import Path

import numpy as np
import pytest

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
