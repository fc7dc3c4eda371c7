"""Device check of rlfc.txparse_torch: random streams (the syntax tests' generator) and mutated
and truncated streams, parsed on a device by torch steps and by the Triton kernel, against the
numpy parser: each must give numpy's integers or, where numpy refuses the stream, a FormatError.

Usage (on a lent GPU): python -m tools.gpu_parse_check [DEVICE] [SEEDS]   (default cuda 200)
Prints the disagreements per kernel and ``PARSE CHECK OK`` when there are none (exit code 0).
"""
from __future__ import annotations

import sys

import numpy as np
import torch

from formats.errors import FormatError
from rlfc import txparse as tp, txsyntax as tx
from rlfc.txparse_torch import pair_words, parse_lanes_torch
from tests.rlfc.test_txsyntax import _encode, _packed, _random_blocks


def agrees(dev, streams, tables, nt, pcs, kind, key, triton) -> bool:
    """The device parse equals the numpy parse, or both refuse the streams."""
    buf, starts = _packed(streams)
    try:
        ref = tp.parse_lanes(buf, starts[:-1], starts[1:], tables, nt, pcs, kind, key)
    except FormatError:
        ref = None
    t = [torch.as_tensor(np.asarray(a, np.int64), device=dev) for a in (starts[:-1], starts[1:], kind, key)]
    tb = torch.as_tensor(buf.copy(), device=dev)
    try:
        m, i, v = parse_lanes_torch(tb, pair_words(tb), t[0], t[1], tables, nt, pcs, t[2], t[3], triton=triton)
    except FormatError:
        return ref is None
    return ref is not None and all(np.array_equal(a.cpu().numpy(), b)
                                   for a, b in ((m, ref.modes), (i, ref.index), (v, ref.values)))


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    dev = argv[0] if argv else "cuda"
    n = int(argv[1]) if len(argv) > 1 else 200
    bad = 0
    for triton in (False, True):
        for seed in range(n):
            rng = np.random.default_rng(seed)
            S, nt, P = int(rng.integers(1, 300)), int(rng.choice([1, 4])), int(rng.choice([1, 2, 3, 4]))
            modes, levels = _random_blocks(rng, S, nt, P, rng.random(), bool(rng.random() < 0.3))
            kind, key, pcs = rng.integers(0, 2, S), rng.integers(0, 2, S), tx.plane_classes(P)
            streams, tables = _encode(modes, levels, kind, key, pcs)
            mutated = list(streams)
            for k in rng.integers(0, S, 3).tolist():
                b = bytearray(mutated[k])
                b[int(rng.integers(0, len(b)))] ^= int(rng.integers(1, 256))
                mutated[k] = bytes(b)
            truncated = [b[:-1] if len(b) > 3 else b for b in streams]
            for ss in (streams, mutated, truncated):
                bad += not agrees(dev, ss, tables, nt, pcs, kind, key, triton)
        print(f"triton={triton}: {3 * n} stream sets, {bad} disagreements so far", flush=True)
    print("PARSE CHECK", "OK" if bad == 0 else f"FAILED {bad}")
    return 0 if bad == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
