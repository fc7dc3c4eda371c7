"""The fuzzer's own mutations (tools/fuzz.py) on inputs an earlier mutation already changed."""
import zlib

import numpy as np

from tools.fuzz import mutate_run


def test_a_run_mutation_skips_a_layout_without_bitmap_bytes():
    """A block run's mutation reads the run layout from the (possibly mutated) metadata: a
    bitmap of 0 (or fewer) bytes or a negative header size means no run to aim at (None), not a
    crash of the fuzzer (seed 144 stopped on ``rng.integers(0)``); a sane layout still mutates
    one byte of the run."""
    index = zlib.compress(np.array([40, 0, 24], "<u4").tobytes())
    blocks = bytes(range(64))
    for nbm, off in ((0, 2), (-3, 2), (2, -20)):
        meta = {"config": {"layout": {"bitmap_bytes": nbm, "off_bytes": off}, "planes": 3}}
        for seed in range(12):
            secs = [("rlfc.blocks", blocks), ("rlfc.index", index)]
            assert mutate_run(meta, secs, np.random.default_rng(seed)) is None
            assert secs[0][1] == blocks
    meta = {"config": {"layout": {"bitmap_bytes": 2, "off_bytes": 2}, "planes": 3}}
    for seed in range(12):
        secs = [("rlfc.blocks", blocks), ("rlfc.index", index)]
        what = mutate_run(meta, secs, np.random.default_rng(seed))
        assert what is not None and what.startswith("rlfc.blocks run ")
        assert len(secs[0][1]) == len(blocks)
