"""Training a nested-width light field network with continuous levels of detail.

Each step trains the full width on full-resolution targets plus random fractional widths
(``lod_levels`` of them, one from each equal slice of the width range, each on its share of a
second batch of rays), each width w against the summed-area-table box filter of the image at
w's exact scale (1/8 at min_neurons … 1 at max_neurons; a box of fractional side, see
:mod:`lfn_stream.sat`). Rays are drawn by :class:`~lfn_stream.sampling.RaySampler`. An
occupancy net learns which rays hit the object (alpha > 0) when the scene has alpha.
Checkpoints hold raw arrays (``.npz`` without pickle) and training resumes from them.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from formats.errors import ParameterError
from formats.imageio import check_parent_folder
from formats.lightfield import LightField

from .config import LfnConfig
from .model import NestedLFN, OccupancyNet
from .rays import normalization, view_rays
from .sampling import RaySampler, TorchRaySampler
from .sat import box_mean_frac_torch, summed_area_table


@dataclass
class TrainOptions:
    """Training settings (not stored in the stream).

    Attributes:
        steps: optimizer steps; batch: rays per step (each of the two terms).
        lr: Adam learning rate (cosine decay to lr/20 over ``steps``, or over ``time_limit_s``
            seconds where that ends the run first).
        holdout: every k-th view is held out for evaluation (0 = none); ``train_views`` overrides.
        device: "cpu" or "cuda"; seed: RNG seed; checkpoint: path of a .npz to save/resume.
        checkpoint_every: steps between checkpoints.
        lod_weight: weight of the random-level term.
        lod_levels: the random-level term's rays are split into this many groups, each at its
            own level drawn from one of as many equal slices of the width range (stratified), so
            that every step trains levels across the whole range.
        lod_one_pass: run the random-level term as one pass with a size per ray
            (:meth:`NestedLFN.forward_lod`, targets boxed per ray) instead of one pass per group:
            the same loss up to float rounding, fewer and larger kernels (what a GPU wants; on
            the CPU the per-group passes do fewer multiply-adds). None = on CUDA devices only.
    """

    steps: int = 2000
    batch: int = 4096
    lr: float = 3e-3
    holdout: int = 4
    device: str = "cpu"
    seed: int = 0
    checkpoint: str | None = None
    checkpoint_every: int = 500
    lod_weight: float = 1.0
    lod_levels: int = 8
    train_views: list | None = None
    lod_one_pass: bool | None = None
    time_limit_s: float | None = None
    history: list = field(default_factory=list)

    def __post_init__(self):
        for k, lo, hi in (("steps", 1, 10 ** 8), ("batch", 1, 1 << 22), ("holdout", 0, 1 << 16),
                          ("checkpoint_every", 1, 10 ** 8), ("lod_levels", 1, 64)):
            v = getattr(self, k)
            if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
                raise ParameterError(f"--{k.replace('_', '-')} must be an integer within {lo}..{hi}, got {v!r}")
        if not (isinstance(self.lr, (int, float)) and 0 < self.lr <= 1):
            raise ParameterError(f"--lr must be within (0, 1], got {self.lr!r}")
        if self.time_limit_s is not None and not self.time_limit_s > 0:
            raise ParameterError(f"time limit must be > 0 s, got {self.time_limit_s!r}")
        try:
            dev = torch.device(self.device)
        except (RuntimeError, TypeError):
            raise ParameterError(f"--device must be cpu or cuda (or cuda:N), got {self.device!r}") from None
        if dev.type not in ("cpu", "cuda"):
            raise ParameterError(f"--device must be cpu or cuda (or cuda:N), got {self.device!r}")
        if dev.type == "cuda" and not torch.cuda.is_available():
            raise ParameterError("--device cuda: this torch has no usable CUDA GPU (the README installs the CPU "
                                 "wheel; install a CUDA build of torch on a machine with a GPU)")
        if self.checkpoint is not None:           # checked now, not at the first save after minutes of training
            ck = Path(self.checkpoint)
            if ck.is_dir():
                raise ParameterError(f"{ck}: --checkpoint is a folder; name a .npz file")
            check_parent_folder(ck)


def split_views(lf: LightField, holdout: int) -> tuple[np.ndarray, np.ndarray]:
    """(train, held-out) flat view indices: every ``holdout``-th view is held out."""
    n = lf.rows * lf.cols
    idx = np.arange(n)
    if holdout and n > 1:
        test = idx[(idx % holdout) == holdout // 2]
        return np.setdiff1d(idx, test), test
    return idx, np.zeros(0, np.int64)


def targets_of(views: np.ndarray, has_alpha: bool) -> np.ndarray:
    """(N, H, W, C) uint → (N, H, W, 4) targets in the views' integer units: RGB premultiplied
    by alpha (as integers scaled by peak), and alpha; opaque scenes get alpha = peak."""
    peak = np.iinfo(views.dtype).max
    v = views.astype(np.int64)
    c = views.shape[-1]
    rgb = v[..., :3] if c >= 3 else np.repeat(v[..., :1], 3, -1)
    a = v[..., -1:] if has_alpha else np.full(v.shape[:-1] + (1,), peak, np.int64)
    if has_alpha:
        rgb = (rgb * a + peak // 2) // peak
    return np.concatenate([rgb, a], -1)


def _save(path: Path, model, occ, opt, step: int) -> None:
    arrays = {f"m.{k}": v.detach().cpu().numpy() for k, v in model.state_dict().items()}
    if occ is not None:
        arrays.update({f"o.{k}": v.detach().cpu().numpy() for k, v in occ.state_dict().items()})
    st = opt.state_dict()
    for pid, s in st["state"].items():
        for k, v in s.items():
            arrays[f"opt.{pid}.{k}"] = v.detach().cpu().numpy() if torch.is_tensor(v) else np.asarray(v)
    arrays["step"] = np.asarray(step)
    tmp = path.with_name(path.name + ".tmp.npz")
    try:
        np.savez(tmp, **arrays)
        tmp.replace(path)
    except OSError as e:                          # (a full disk, a folder removed while training)
        tmp.unlink(missing_ok=True)
        raise ParameterError(f"{path}: could not write the checkpoint ({e.strerror or e})") from None


def _load(path: Path, model, occ, opt) -> int:
    """Resume from a checkpoint; anything that is not a checkpoint of this network is a
    ParameterError naming the file."""
    try:
        return _load_unchecked(path, model, occ, opt)
    except (ValueError, OSError, KeyError, RuntimeError, TypeError, EOFError) as e:
        raise ParameterError(f"{path}: not a checkpoint of this network ({str(e).splitlines()[0][:120]}); "
                             f"remove it or give another --checkpoint") from None


def _load_unchecked(path: Path, model, occ, opt) -> int:
    with np.load(path, allow_pickle=False) as z:
        model.load_state_dict({k[2:]: torch.from_numpy(z[k]) for k in z.files if k.startswith("m.")})
        if occ is not None:
            occ.load_state_dict({k[2:]: torch.from_numpy(z[k]) for k in z.files if k.startswith("o.")})
        st = opt.state_dict()
        for k in z.files:
            if k.startswith("opt."):
                _, pid, name = k.split(".", 2)
                st["state"].setdefault(int(pid), {})[name] = torch.from_numpy(z[k]).to(
                    next(model.parameters()).device) if name != "step" else torch.tensor(float(z[k]))
        opt.load_state_dict(st)
        return int(z["step"])


def train(lf: LightField, cfg: LfnConfig, opts: TrainOptions, progress=None):
    """Train; returns (model, occupancy net or None, info dict with norm, views, history)."""
    if lf.views.dtype not in (np.uint8, np.uint16):
        raise ParameterError("LFN training needs 8- or 16-bit views")
    torch.manual_seed(opts.seed)
    rng = np.random.default_rng(opts.seed)
    dev = torch.device(opts.device)
    train_v, test_v = split_views(lf, opts.holdout)
    if opts.train_views is not None:
        train_v = np.asarray(opts.train_views)
    flat = lf.views.reshape(-1, lf.height, lf.width, lf.channels)[train_v]
    peak = float(np.iinfo(lf.views.dtype).max)
    tg = targets_of(flat, lf.has_alpha)                                    # (N, H, W, 4) int64
    sat = summed_area_table(tg)
    alpha = tg[..., 3] / peak if lf.has_alpha else None
    sampler = RaySampler(flat, alpha)
    centre, radius = normalization(lf, train_v)
    rays = torch.from_numpy(np.stack([view_rays(lf, int(v), 1.0, centre, radius) for v in train_v])).to(dev)
    model = NestedLFN(cfg).to(dev)
    occ = OccupancyNet(cfg.occupancy_neurons).to(dev) if (lf.has_alpha and cfg.occupancy_neurons) else None
    params = list(model.parameters()) + (list(occ.parameters()) if occ is not None else [])
    opt = torch.optim.Adam(params, lr=opts.lr)
    start = 0
    ck = Path(opts.checkpoint) if opts.checkpoint else None
    if ck is not None and ck.exists():
        start = _load(ck, model, occ, opt)
    # everything a step touches lives on the device: targets, SAT (float64 holds the exact
    # integer sums), sampler tables; no host round trip inside the loop
    tsampler = TorchRaySampler(sampler, dev)
    tgt_all = torch.from_numpy(tg).to(dev, torch.float32) / peak                  # (N, H, W, 4)
    sat_t = torch.from_numpy(sat.astype(np.float64)).to(dev)
    gen = torch.Generator(device=dev)
    gen.manual_seed(opts.seed)
    one_pass = dev.type == "cuda" if opts.lod_one_pass is None else bool(opts.lod_one_pass)
    group = torch.arange(opts.batch, device=dev) % opts.lod_levels      # row r of the level term: group r mod K
    t0 = time.perf_counter()
    step = start
    for step in range(start, opts.steps):
        # cosine decay over the run: by steps, or by time where a time limit ends the run sooner
        done = step / max(opts.steps, 1)
        if opts.time_limit_s:
            done = max(done, min((time.perf_counter() - t0) / opts.time_limit_s, 1.0))
        lr = opts.lr * (0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * done)))
        for gr in opt.param_groups:
            gr["lr"] = lr
        v, y, x = tsampler.sample(opts.batch, gen)
        tgt = tgt_all[v, y, x]
        xr = rays[v, y, x]
        loss = ((model(xr) - tgt) ** 2).mean()
        # random fractional levels against the box-filtered target at each one's scale (the box's
        # side is the exact reciprocal of the level's scale: a fractional box, so targets change
        # continuously with the level, as the widths do); K levels, one per K-th of the range
        K = opts.lod_levels
        u = (np.arange(K) + rng.uniform(size=K)) / K
        v2, y2, x2 = tsampler.sample(opts.batch, gen)
        wlevs = [float(cfg.min_neurons + u[k] * (cfg.max_neurons - cfg.min_neurons)) for k in range(K)]
        if one_pass:            # group k = rows k::K, as below, each row at its group's size
            lv_host = np.array([[w, 1.0 / cfg.scale_of(w)] for w in wlevs])
            lv_dev = torch.from_numpy(lv_host).to(dev, non_blocking=False)[group]      # (batch, 2)
            tgt2 = (box_mean_frac_torch(sat_t, v2, y2, x2, lv_dev[:, 1]) / peak).float()
            wr = lv_dev[:, 0].float()
            sq = ((model.forward_lod(rays[v2, y2, x2], wr) - tgt2) ** 2).sum()
        else:
            sq = 0.0
            for k in range(K):  # strided groups: the sampler returns foreground rays first, then background
                vk, yk, xk = v2[k::K], y2[k::K], x2[k::K]
                tgt2 = (box_mean_frac_torch(sat_t, vk, yk, xk, 1.0 / cfg.scale_of(wlevs[k])) / peak).float()
                sq = sq + ((model(rays[vk, yk, xk], wlevs[k]) - tgt2) ** 2).sum()
        loss = loss + opts.lod_weight * sq / (opts.batch * cfg.out_features)
        if occ is not None:
            lab = (tgt[:, 3] > 0).float()
            loss = loss + 0.1 * torch.nn.functional.binary_cross_entropy_with_logits(occ(xr), lab)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        if step % 50 == 0 or step == opts.steps - 1:
            lv = loss.item()
            opts.history.append((step, lv))
            if progress:
                progress(step, lv)
        if ck is not None and (step + 1) % opts.checkpoint_every == 0:
            _save(ck, model, occ, opt, step + 1)
        if opts.time_limit_s and time.perf_counter() - t0 > opts.time_limit_s:
            break
    if ck is not None:
        _save(ck, model, occ, opt, step + 1)
    info = {"norm": {"centre": centre, "radius": radius}, "train_views": train_v.tolist(),
            "test_views": test_v.tolist(), "steps": step + 1, "train_s": time.perf_counter() - t0,
            "lr_end": opt.param_groups[0]["lr"]}
    return model.cpu(), (occ.cpu() if occ is not None else None), info
