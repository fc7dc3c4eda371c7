"""Fuzz: RLFC sections with random byte changes and *valid* checksums (a crafted file). Every
decoder either decodes or raises an LfcError; nothing else escapes (no IndexError, no hang)."""
import numpy as np
import pytest

from formats.container import build_container
from formats.errors import LfcError
from formats.lfcfile import encode_meta, open_lfc
from rlfc import RlfcDecoder, RlfcParams, encode_with_params
from rlfc.torch_decode import TorchBlockDecoder
from tests.rlfc.helpers import smooth_lf


@pytest.fixture(scope="module")
def encoded():
    lf = smooth_lf(rows=3, cols=3, h=16, w=16)
    cfg, secs, _ = encode_with_params(lf, RlfcParams(block_size=4, quant=3))
    return lf, cfg, dict(secs)


@pytest.mark.parametrize("section", ["rlfc.blocks", "rlfc.index", "rlfc.top"])
def test_mutated_sections_give_typed_errors(encoded, section):
    lf, cfg, secs = encoded
    rng = np.random.default_rng(sum(map(ord, section)))
    outcomes = {"ok": 0, "LfcError": 0}
    for _ in range(60):
        s = {k: bytearray(v) for k, v in secs.items()}
        for _ in range(int(rng.integers(1, 4))):
            s[section][int(rng.integers(0, len(s[section])))] = int(rng.integers(0, 256))
        blob = b"".join(bytes(p) for p in build_container(encode_meta("rlfc", 1, cfg, lf.geometry()), list(s.items())))
        try:
            d = RlfcDecoder(open_lfc(blob))
            d.decode_all()
            d.decode_blocks(np.arange(9), np.arange(9) % 4, np.arange(9) % 4)
            d.decode_block(1, 1, 2, 2)
            TorchBlockDecoder(d, "cpu").decode_blocks(np.arange(9), np.arange(9) % 4, np.arange(9) % 4)
            outcomes["ok"] += 1
        except LfcError:
            outcomes["LfcError"] += 1
    assert sum(outcomes.values()) == 60


@pytest.mark.parametrize("patch", [
    {"blocks": [1000000, 1000000]}, {"padded": [-4, 16]}, {"tree": {"parents": [[0, 0, 7]], "sizes": [3, 1]}},
    {"q16": "x"}, {"top": []}, {"layout": {"off_bytes": 2}}, {"dtype": "float64"}, {"block_size": 0},
])
def test_hostile_config_values(encoded, patch):
    lf, cfg, secs = encoded
    bad = {**cfg, **patch}
    blob = b"".join(bytes(p) for p in build_container(encode_meta("rlfc", 1, bad, lf.geometry()), list(secs.items())))
    with pytest.raises(LfcError):
        d = RlfcDecoder(open_lfc(blob))
        d.decode_all()
