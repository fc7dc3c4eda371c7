"""The fuzzer's oracles: the slow reference decoder written from FORMAT.md (tools/refdecode.py)
reproduces the golden fixtures' recorded hashes by itself, decodes the ASTC conformance
vectors, refuses what FORMAT.md forbids, and the fuzzer's comparisons catch a wrong decode."""
import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from formats.container import build_container
from formats.lfcfile import open_lfc
from formats.registry import open_decoder
from tools.fuzz import check_js, check_reference, decode_everything, split_file
from tools.refdecode import RANGES, RefError, bise_decode, covers, ref_decode, ref_levels

ROOT = Path(__file__).resolve().parents[2]
GOLDEN = ROOT / "tests" / "data" / "golden"
RECORD = json.loads((GOLDEN / "golden.json").read_text())


@pytest.mark.parametrize("name", [n for n in RECORD if n.startswith(("rlfc_bise", "rlfc_dcp"))])
def test_reference_reproduces_golden_hashes(name):
    blob = (GOLDEN / f"{name}.lfc").read_bytes()
    want = RECORD[name]["levels"]
    assert ref_levels(blob) + 1 == len(want)
    for level, sha in want.items():
        got = ref_decode(blob, int(level))
        assert hashlib.sha256(np.ascontiguousarray(got).tobytes()).hexdigest() == sha, (name, level)


def test_reference_lfn_within_one_level():
    blob = (GOLDEN / "lfn_tiny_rgba8.lfc").read_bytes()
    d = open_decoder(open_lfc(blob))
    for level in range(int(d.levels) + 1):
        diff = np.abs(ref_decode(blob, level).astype(int) - d.decode_all(level))
        assert diff.max() <= 1 and (diff > 0).mean() < 1e-3


def test_bise_matches_astc_conformance_vectors():
    vec = json.loads((ROOT / "tests" / "data" / "bise_vectors_subset.json").read_text())
    assert len(vec["cases"]) >= 60
    for case in vec["cases"]:
        assert case["range"] in RANGES
        got = bise_decode(bytes.fromhex(case["encoded_hex"]), case["range"], case["count"])
        assert got == case["values"], case["id"]


def test_reference_refuses_what_the_format_forbids():
    meta, secs = split_file((GOLDEN / "rlfc_bise_lossy_rgb8.lfc").read_bytes())
    blocks = dict(secs)["rlfc.blocks"]
    idx = np.frombuffer(dict(secs)["rlfc.index"], "<u4")
    loc = int(np.flatnonzero(np.diff(idx.astype(np.int64)))[-1])    # the last non-empty run
    bad = bytearray(blocks)
    bad[idx[loc]:idx[loc] + meta["config"]["layout"]["bitmap_bytes"]] = b"\xff" * meta["config"]["layout"]["bitmap_bytes"]
    secs = [(n, bytes(bad) if n == "rlfc.blocks" else b) for n, b in secs]
    blob = b"".join(bytes(p) for p in build_container(json.dumps(meta).encode(), secs))
    with pytest.raises(RefError, match="bitmap|headers"):
        ref_decode(blob, 0)
    with pytest.raises(RefError, match="magic"):
        ref_decode(b"not an lfc file at all, but long enough", 0)
    assert not covers(b"junk")


def test_fuzz_comparison_catches_a_wrong_decode(tmp_path):
    blob = (GOLDEN / "rlfc_dcp_lossy_rgb8.lfc").read_bytes()
    path = tmp_path / "f.lfc"
    path.write_bytes(blob)
    out = decode_everything(blob, str(path), 0)
    assert check_reference(blob, out)
    out["levels"][1] = out["levels"][1].copy()
    out["levels"][1][0, 0, 5, 5, 1] ^= 1
    with pytest.raises(AssertionError, match="level 1: 1 samples"):
        check_reference(blob, out)


@pytest.mark.skipif(shutil.which("node") is None, reason="Node.js is not installed (apt-get install nodejs)")
def test_fuzz_javascript_reference_catches_a_wrong_decode(tmp_path):
    blob = (GOLDEN / "rlfc_tx2_lossy_rgba8.lfc").read_bytes()
    path = tmp_path / "f.lfc"
    path.write_bytes(blob)
    out = decode_everything(blob, str(path), 0)
    assert out["tx_version"] == 2 and sorted(out["planes"]) == [0, 1]
    assert check_js(blob, out["planes"], str(tmp_path)) == ("referenced", "")
    out["planes"][1][3, 2, 2, 0] += 1
    outcome, why = check_js(blob, out["planes"], str(tmp_path))
    assert outcome == "mismatch" and "level 1 view 3" in why
