"""Stream format of a nested-width network: base network + one delta per width step.

Codec version 3 (what :func:`stream_sections` writes): ``lfn.base``, ``lfn.occ``, then every
step in one section ``lfn.steps`` (step j's bytes at the offset the config implies,
:func:`step_offsets`; checksummed in chunks of :data:`STEP_CHUNK` bytes), so that the header
holds 4 section entries instead of one per neuron and a byte prefix ending past a step's last
chunk is a complete network. Version 2 stored each step as its own section:

- ``lfn.base``: the network at min_neurons m, little-endian floats (fp16 by default), in order:
  for each hidden layer i: W_i[:m, :k_i] (row-major; k_0 = 6, else m), b_i[:m], γ_i[:m], β_i[:m];
  then W_out[:, :m], b_out.
- ``lfn.occ``: the occupancy net (if any): its Linear weights and biases in order.
- ``lfn.step.NNNN`` for each added neuron j = m … M-1 (NNNN = j - m): for layer 0:
  W_0[j, :6], b_0[j], γ_0[j], β_0[j]; for each hidden layer i >= 1: the new row W_i[j, :j+1],
  the new column W_i[:j, j], b_i[j], γ_i[j], β_i[j]; then the output layer's new column W_out[:, j].
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from formats.errors import FormatError

from .config import LfnConfig

if TYPE_CHECKING:        # (torch loads where a network is built: reading a file's shape needs none)
    from .model import NestedLFN, OccupancyNet

DTYPES = {"fp16": "<f2", "fp32": "<f4"}
#: checksum granularity of ``lfn.steps`` (bytes): a prefix is usable up to its last whole chunk
STEP_CHUNK = 2048
#: largest weight magnitude a file may hold (fp16's range, for fp32 files too: float32
#: arithmetic then cannot overflow in a network of the sizes the config allows)
MAX_WEIGHT = 65504.0


def step_name(j: int) -> str:
    return f"lfn.step.{j:04d}"


def _np(p) -> np.ndarray:
    return p.detach().cpu().double().numpy()


def pack_network(model: NestedLFN, occ: OccupancyNet | None, dtype: str = "fp16") -> list[tuple[str, bytes]]:
    """(name, bytes) sections of a trained network."""
    cfg, dt = model.cfg, DTYPES[dtype]
    m = cfg.min_neurons
    W = [_np(w) for w in model.weights]
    b, g, be = [_np(x) for x in model.biases], [_np(x) for x in model.gammas], [_np(x) for x in model.betas]
    ow, ob = _np(model.out_w), _np(model.out_b)
    base = []
    for i in range(cfg.depth):
        k = cfg.in_features if i == 0 else m
        base += [W[i][:m, :k].ravel(), b[i][:m], g[i][:m], be[i][:m]]
    base += [ow[:, :m].ravel(), ob]
    out = [("lfn.base", np.concatenate(base).astype(dt).tobytes())]
    if occ is not None:
        out.append(("lfn.occ", np.concatenate([_np(p).ravel() for p in occ.parameters()]).astype(dt).tobytes()))
    for j in range(m, cfg.max_neurons):
        parts = [W[0][j, :cfg.in_features], b[0][j:j + 1], g[0][j:j + 1], be[0][j:j + 1]]
        for i in range(1, cfg.depth):
            parts += [W[i][j, :j + 1], W[i][:j, j], b[i][j:j + 1], g[i][j:j + 1], be[i][j:j + 1]]
        parts.append(ow[:, j])
        out.append((step_name(j - m), np.concatenate(parts).astype(dt).tobytes()))
    return out


def steps_chunk(cfg: LfnConfig, dtype: str = "fp16") -> int:
    """Checksum chunk size of ``lfn.steps`` (bytes): :data:`STEP_CHUNK`, doubled while it is
    under half the largest step, so a large step spans two or three chunks and the header's CRC
    array (4 bytes a chunk, read before any network) stays small: 455 CRCs (1 820 bytes) for a
    depth-8, 256-neuron network at 2 KiB chunks, 228 at 4 KiB."""
    big, c = step_bytes(cfg, cfg.max_neurons - 1, dtype) if cfg.max_neurons > cfg.min_neurons else 0, STEP_CHUNK
    while 2 * c < big:
        c *= 2
    return c


def stream_sections(model: NestedLFN, occ: OccupancyNet | None, dtype: str = "fp16") -> list[tuple]:
    """Codec version 3 sections: ``lfn.base``, ``lfn.occ`` (if any), then ``lfn.steps`` (all
    steps in order, with :func:`steps_chunk`-byte checksum chunks)."""
    secs = pack_network(model, occ, dtype)
    steps = [d for n, d in secs if n.startswith("lfn.step.")]
    return [s for s in secs if not s[0].startswith("lfn.step.")] + [
        ("lfn.steps", b"".join(steps), steps_chunk(model.cfg, dtype))]


def step_offsets(cfg: LfnConfig, dtype: str = "fp16") -> np.ndarray:
    """(max_neurons − min_neurons + 1,) int64 byte offsets of the steps in ``lfn.steps``: step
    s (adding neuron min_neurons + s) is bytes [off[s], off[s + 1])."""
    sizes = [step_bytes(cfg, j, dtype) for j in range(cfg.min_neurons, cfg.max_neurons)]
    return np.concatenate([[0], np.cumsum(sizes, dtype=np.int64)]).astype(np.int64)


def step_bytes(cfg: LfnConfig, j: int, dtype: str = "fp16") -> int:
    """Size of the delta that adds neuron j."""
    n = cfg.in_features + 3 + (cfg.depth - 1) * (2 * j + 1 + 3) + cfg.out_features
    return n * np.dtype(DTYPES[dtype]).itemsize


def base_values(cfg: LfnConfig) -> int:
    """Values in ``lfn.base``: the min_neurons network (weights, biases, LayerNorm gains and
    offsets of every layer, then the output layer)."""
    m = cfg.min_neurons
    return (m * cfg.in_features + 3 * m + (cfg.depth - 1) * (m * m + 3 * m)
            + cfg.out_features * m + cfg.out_features)


def occ_values(cfg: LfnConfig) -> int:
    """Values in ``lfn.occ``: the occupancy MLP (in → n → n → 1, with biases)."""
    n = cfg.occupancy_neurons
    return cfg.in_features * n + n + n * n + n + n + 1


def unpack_network(cfg: LfnConfig, base: bytes, steps: list[bytes], occ: bytes | None = None,
                   dtype: str = "fp16") -> tuple[NestedLFN, OccupancyNet | None]:
    """Rebuild the network of width min_neurons + len(steps) (a smaller cfg) from sections."""
    import torch

    from .model import NestedLFN, OccupancyNet

    (W, b, g, be, ow, ob), occ_vals = unpack_arrays(cfg, base, steps, occ, dtype)
    model = NestedLFN(LfnConfig(**{**cfg.to_dict(), "max_neurons": cfg.min_neurons + len(steps)}))
    with torch.no_grad():
        for i in range(cfg.depth):
            model.weights[i].copy_(torch.from_numpy(W[i]).float())
            model.biases[i].copy_(torch.from_numpy(b[i]).float())
            model.gammas[i].copy_(torch.from_numpy(g[i]).float())
            model.betas[i].copy_(torch.from_numpy(be[i]).float())
        model.out_w.copy_(torch.from_numpy(ow).float())
        model.out_b.copy_(torch.from_numpy(ob).float())
    occ_net = None
    if occ_vals is not None:
        occ_net = OccupancyNet(cfg.occupancy_neurons, cfg.in_features)
        pos = 0
        with torch.no_grad():
            for p in occ_net.parameters():
                p.copy_(torch.from_numpy(occ_vals[pos:pos + p.numel()].reshape(p.shape)).float())
                pos += p.numel()
    return model, occ_net


def unpack_arrays(cfg: LfnConfig, base: bytes, steps: list[bytes], occ: bytes | None = None, dtype: str = "fp16"):
    """The weights of the network of width min_neurons + len(steps), read from its sections and
    checked (numpy only): ((W_i (depth, each (width, k_i)), b, γ, β (depth, width), W_out, b_out),
    the occupancy net's values in its parameters' order or None).

    Raises:
        FormatError: a section of the wrong length, or weights that are NaN, infinite or beyond
            ±MAX_WEIGHT.
    """
    dt = DTYPES[dtype]
    width = cfg.min_neurons + len(steps)
    m = cfg.min_neurons
    vals = np.frombuffer(base, dtype=dt).astype(np.float64)
    pos = 0

    def take(n):
        nonlocal pos
        if pos + n > vals.size:
            raise FormatError("lfn network section is shorter than its configuration needs")
        out = vals[pos:pos + n]
        pos += n
        return out

    W = [np.zeros((width, cfg.in_features if i == 0 else width)) for i in range(cfg.depth)]
    b, g, be = (np.zeros((cfg.depth, width)) for _ in range(3))
    ow = np.zeros((cfg.out_features, width))
    for i in range(cfg.depth):
        k = cfg.in_features if i == 0 else m
        W[i][:m, :k] = take(m * k).reshape(m, k)
        b[i, :m], g[i, :m], be[i, :m] = take(m), take(m), take(m)
    ow[:, :m] = take(cfg.out_features * m).reshape(cfg.out_features, m)
    ob = take(cfg.out_features)
    if pos != vals.size:
        raise FormatError("lfn.base has trailing data")
    for s, data in enumerate(steps):
        j = m + s
        vals, pos = np.frombuffer(data, dtype=dt).astype(np.float64), 0
        W[0][j, :cfg.in_features] = take(cfg.in_features)
        b[0, j], g[0, j], be[0, j] = take(1)[0], take(1)[0], take(1)[0]
        for i in range(1, cfg.depth):
            W[i][j, :j + 1] = take(j + 1)
            W[i][:j, j] = take(j)
            b[i, j], g[i, j], be[i, j] = take(1)[0], take(1)[0], take(1)[0]
        ow[:, j] = take(cfg.out_features)
        if pos != vals.size:
            raise FormatError(f"{step_name(s)} has {vals.size} values, expected {pos}")
    if not all((np.abs(a) <= MAX_WEIGHT).all() for a in (*W, b, g, be, ow, ob)):     # NaN fails too
        raise FormatError(f"lfn network weights hold NaN, infinite or values beyond ±{MAX_WEIGHT:g}")
    occ_vals = None
    if occ is not None and cfg.occupancy_neurons:
        vals, pos = np.frombuffer(occ, dtype=dt).astype(np.float64), 0
        occ_vals = take(occ_values(cfg))
        if pos != vals.size or not (np.abs(vals) <= MAX_WEIGHT).all():
            raise FormatError(f"lfn.occ has trailing data or NaN, infinite or values beyond ±{MAX_WEIGHT:g}")
    return (W, b, g, be, ow, ob), occ_vals
