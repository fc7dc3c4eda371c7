"""Format compatibility: committed .lfc fixtures (tests/data/golden, written once by
tools/make_golden.py) decode to the same pixels for ever, through every decoder."""
import hashlib
import json

import numpy as np
import pytest

from formats import open_lfc
from formats.registry import open_decoder
from tests.conftest import ROOT

GOLDEN = ROOT / "tests" / "data" / "golden"
INDEX = json.loads((GOLDEN / "golden.json").read_text())
RLFC = sorted(k for k in INDEX if k.startswith("rlfc_"))
LFN = sorted(k for k in INDEX if k.startswith("lfn"))


def _sha(a):
    return hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()


@pytest.mark.parametrize("name", RLFC)
def test_rlfc_fixture_decodes_bit_exactly(name):
    g = INDEX[name]
    with open_lfc(GOLDEN / g["file"]) as f:
        f.container.verify_all()
        d = open_decoder(f)
        assert sorted(g["levels"]) == [str(lv) for lv in range(d.levels + 1)]
        for level, want in g["levels"].items():
            full = d.decode_all(int(level))
            assert list(full.shape) == g["shape"] and _sha(full) == want, (name, level)
            # every block, batched, and a spread of single blocks give the same pixels
            B, n = d.block_size, d.rows * d.cols
            v = np.repeat(np.arange(n), d.nby * d.nbx)
            by = np.tile(np.repeat(np.arange(d.nby), d.nbx), n)
            bx = np.tile(np.arange(d.nbx), n * d.nby)
            blocks = d.decode_blocks(v, by, bx, int(level))
            img = blocks.reshape(d.rows, d.cols, d.nby, d.nbx, B, B, -1).transpose(0, 1, 2, 4, 3, 5, 6)
            img = img.reshape(d.rows, d.cols, d.nby * B, d.nbx * B, -1)[:, :, :d.height, :d.width]
            assert (img == full).all()
            for i in range(0, len(v), max(1, len(v) // 17)):
                r, c = divmod(int(v[i]), d.cols)
                one = d.decode_block(r, c, int(by[i]), int(bx[i]), int(level))
                assert (one == full[r, c, by[i] * B:(by[i] + 1) * B, bx[i] * B:(bx[i] + 1) * B]).all()


@pytest.mark.parametrize("name", LFN)
def test_lfn_fixture_renders_within_one_level(name):
    """Every LFN codec version kept here (1: a section per step, cameras in meta; 3: one
    lfn.steps section, cameras in meta.more) renders its stored views; the float64 reference
    decoder (tools/reflfn.py, from FORMAT.md) agrees within one level."""
    from lfn_stream import LfnRenderer
    from tools.refdecode import ref_decode

    g = INDEX[name]
    want = np.load(GOLDEN / g["expected"], allow_pickle=False)
    blob = (GOLDEN / g["file"]).read_bytes()
    with open_lfc(GOLDEN / g["file"]) as f:
        f.container.verify_all()
        assert f.meta["codec_version"] == g.get("version", 1)
        r = LfnRenderer(f, device="cpu")
        # stored by network size (neurons); level 0 is the full network, level L has L fewer
        got = np.stack([r.decode_view(*g["view"], r.neurons - n) for n in g["neurons"]])
        full = r.decode_all(0)
    assert got.shape == want.shape and np.abs(got.astype(int) - want.astype(int)).max() <= 1
    assert np.abs(ref_decode(blob, 0).astype(int) - full).max() <= 1
