"""The ``tx`` encoder's rate-distortion quantizer and the exact reconstruction of 8×8 blocks
(:class:`RdoQuantizer`, a part of :class:`rlfc.txencode.TxEncoder`: it reads the encoder's
geometry, planes' weights and bypass flags, and parameters)."""
from __future__ import annotations

import numpy as np

from .transform import COEF_MAX, FORWARD_SCAN as _FWD_SCAN, UNZIG, inverse_float
from .txmodel import Model, _level_bits, _level_bits_at
from .txpredict import TB

#: the forward transform in float32, for the quantizer's decisions
_FWD_SCAN32 = _FWD_SCAN.astype(np.float32)
#: (128, 65) 0/1: [costs coded (T, 64) | costs dropped (T, 64)] @ _PREFIX = the cost of every last
#: position L = 0..64: Σ_{i<L} coded + Σ_{i>=L} dropped
_PREFIX = np.vstack([np.triu(np.ones((64, 65), np.float32), 1), np.tril(np.ones((64, 65), np.float32))])


def _dequantize_float(q: np.ndarray, step16: np.ndarray) -> np.ndarray:
    """:func:`rlfc.kernels.dequantize` of (T, p, 64) levels at steps ``step16`` (p,) (1/16),
    clipped to ±COEF_MAX, as float64 (the inverse transform's input): sign(q)·floor((|q|·q16 +
    8) / 16) in floats, exact (|q| < 2^22, q16 < 2^22: every value an integer below 2^53), about
    twice as fast as the int64 arithmetic and its cast."""
    f = q.astype(np.float64)
    a = np.abs(f)
    a *= step16.astype(np.float64)[None, :, None]
    a += 8.0
    a *= 1 / 16
    np.floor(a, out=a)
    np.copysign(a, f, out=a)
    return np.clip(a, -COEF_MAX, COEF_MAX, out=a)


class RdoQuantizer:
    """Tbs (8×8 blocks of P planes) to quantized levels by D + λ·R, and back to the decoder's
    integers."""

    def _tbs(self, img: np.ndarray) -> np.ndarray:
        """(Hp, Wp, P) → (nloc8, 8, 8, P) in raster tb order."""
        return img.reshape(self.nby8, TB, self.nbx8, TB, -1).transpose(0, 2, 1, 3, 4).reshape(-1, TB, TB, img.shape[-1])

    def _untbs(self, t: np.ndarray) -> np.ndarray:
        return t.reshape(self.nby8, self.nbx8, TB, TB, -1).transpose(0, 2, 1, 3, 4).reshape(self.Hp, self.Wp, -1)

    #: tbs quantized at once (the quantizer's float64 temporaries are ~70 bytes per coefficient;
    #: every tb's decisions are its own, so the chunks change no result)
    QUANT_TBS = 1024

    def _quantize(self, r: np.ndarray, step16: np.ndarray, lam: float, model: Model, key: int, mode_cls: int):
        """:meth:`_quantize_tbs` in chunks of QUANT_TBS tbs (bounded temporaries)."""
        T = r.shape[0]
        if T <= self.QUANT_TBS:
            return self._quantize_tbs(r, step16, lam, model, key, mode_cls)
        out = None                    # (each chunk's results written in place: no list of parts to join)
        for a in range(0, T, self.QUANT_TBS):
            part = self._quantize_tbs(r[a:a + self.QUANT_TBS], step16, lam, model, key, mode_cls)
            if out is None:
                out = tuple(np.empty((T,) + x.shape[1:], x.dtype) for x in part)
            for o, x in zip(out, part):
                o[a:a + x.shape[0]] = x
            del part
        return out

    def _quantize_tbs(self, r: np.ndarray, step16: np.ndarray, lam: float, model: Model, key: int, mode_cls: int):
        """RDO quantization of tbs' residuals r (T, 8, 8, P) → (levels (T, P, 64) scan order,
        cost J (T,), distortion-if-skipped D0 (T,), must_code (T,) bool, model bits R (T,)).

        Per coefficient the candidates are round-to-nearest, one less, and 0 (cost
        w·error² + λ·bits); per tb the last coded position is the argmin of the cumulative
        cost (coded below it, dropped above). Tbs none of whose coefficients round away from 0
        skip the search (its result is known: nothing coded).

        The costs are float32 (decisions only: the levels are integers and the reconstruction
        is exact whatever they are), and the 65 cumulative costs of a tb are one product with a
        fixed 0/1 matrix (:data:`_PREFIX`): a float32 GEMM is 2× faster than two float64
        cumulative sums along rows on this box."""
        T = r.shape[0]
        P = self.P
        levels = np.zeros((T, P, 64), np.int32)          # (|levels| < 2^22: coefficients < 2^21·8)
        J = np.zeros(T)
        D0 = np.zeros(T)
        must = np.zeros(T, bool)
        Rb = np.zeros(T)
        tr = np.flatnonzero(~self.bypass)
        if tr.size:                 # the analysis of every transformed plane: one GEMM, scan order out
            rt = np.empty((T, tr.size, 64), np.float32)      # (one cast copy: tb by tb, planes within)
            rv = r.reshape(T, 64, P).transpose(0, 2, 1)
            np.copyto(rt, rv if tr.size == P else rv[:, tr], casting="unsafe")
            Xall = (rt.reshape(-1, 64) @ _FWD_SCAN32).reshape(T, tr.size, 64)
        pos = np.arange(64)
        plain = "rdoq" in self.p.ablate                          # plain rounding (ablation)
        for p in range(P):
            pc = int(self.pcs[p])
            if self.bypass[p]:                                   # exact: levels are the residual samples
                rp = r[..., p].astype(np.float64)
                lv = np.rint(rp.reshape(T, 64) * 16 / step16[p]).astype(np.int64)
                levels[:, p] = lv
                nz = lv != 0
                must |= nz.any(axis=1)
                last = np.where(nz.any(1), 64 - np.argmax(nz[:, ::-1], axis=1), 0)
                bits = _level_bits(model, np.abs(lv), pc, key)
                inside = pos[None, :] < last[:, None]
                rb = (bits * inside).sum(1) + model.last[pc, mode_cls, key, last]
                J += lam * rb
                Rb += rb
                continue
            wgt = self.w[p]
            ip = int(np.searchsorted(tr, p))
            X = Xall[:, ip]
            X2 = X * X
            e = X2.sum(1).astype(np.float64)
            D0 += wgt * e
            if wgt == 0:
                continue
            d = step16[p] / 16.0
            lastb = model.last[pc, mode_cls, key]
            # tbs whose every coefficient rounds to 0 code nothing: J = their error + the bits of
            # "last = 0" (exactly what the search below finds for them), so only the rest search
            # (a comparison then any(): 3.6x faster than a row max on this box, the same tbs: X2 >= 0,
            # and the bound is compared in float32 either way)
            act = np.flatnonzero((X2 >= 0.25 * d * d).any(1))
            idle = np.ones(T, bool)
            idle[act] = False
            J[idle] += wgt * e[idle] + lam * lastb[0]
            Rb[idle] += lastb[0]
            if act.size == 0:
                continue
            Ta = act.size
            xa = X[act]
            ax = np.abs(xa)
            # A = [cost of each coefficient as chosen | cost past the last position (not coded)]
            A = np.empty((Ta, 128), np.float32)
            dz = A[:, 64:]
            np.multiply(X2[act], np.float32(wgt), out=dz)
            zero_bits, zcum = model.zero_bits(pc, key)
            np.add(dz, np.float32(lam) * zero_bits, out=A[:, :64])   # as a coded zero
            # the candidates are evaluated only where rounding gives a nonzero level: where it
            # gives 0 every candidate is 0 and costs exactly the coded zero, so the decisions
            # there are known
            t = ax * np.float32(1.0 / d)
            t += np.float32(0.5)
            nzi = np.flatnonzero(t >= 1.0)                        # flat (Ta·64) indices of ln > 0
            row, col = np.divmod(nzi, 64)
            fa = nzi + (row << 6)                                 # the same places in A
            ln = np.floor(t.ravel()[nzi]).astype(np.int64)
            lo = ln - 1
            a = ax.ravel()[nzi].astype(np.float64)
            b_ln = _level_bits_at(model, ln, col, pc, key)
            b_lo = _level_bits_at(model, lo, col, pc, key)
            j_ln = wgt * (a - ln * d) ** 2 + lam * b_ln
            if plain:
                use_lo, z = np.zeros(nzi.size, bool), np.zeros(nzi.size, bool)
                A.ravel()[fa] = j_ln
            else:
                j_lo = wgt * (a - lo * d) ** 2 + lam * b_lo
                use_lo = j_lo < j_ln
                jmin = np.minimum(j_lo, j_ln)
                j0 = A.ravel()[fa]
                z = j0 <= jmin
                # (a level of 0 costs exactly the coded zero whichever way it was reached)
                A.ravel()[fa] = np.minimum(j0, jmin)
            lvs = (ln - use_lo) * ~z                              # the levels at nzi (0 elsewhere)
            nz = lvs != 0
            # the last position L (coefficients >= L dropped): J(L) = Σ_{i<L} coded + Σ_{i>=L} dz + λ·bits(L),
            # L − 1 nonzero (or L = 0)
            JL = A @ _PREFIX
            JL += (lam * lastb).astype(np.float32)
            if plain:                                             # the last nonzero, whatever it costs
                L = np.zeros(Ta, np.int64)
                np.maximum.at(L, row[nz], col[nz] + 1)
            else:
                last_ok = np.full((Ta, 64), np.inf, np.float32)
                last_ok.ravel()[nzi[nz]] = 0.0
                JL[:, 1:] += last_ok
                L = JL.argmin(1)
            J[act] += JL[np.arange(Ta), L]
            keep = col < L[row]
            # bits of the kept coefficients: the coded zeros' prefix sum, plus the chosen levels'
            # difference from a coded zero
            delta = np.where(use_lo, b_lo, b_ln) - zero_bits[col]
            Rb[act] += zcum[L] + lastb[L] + np.bincount(row, weights=delta * (nz & keep), minlength=Ta)
            lvs = lvs * keep
            lvs *= 1 - 2 * (xa.ravel()[nzi] < 0)                  # the coefficients' signs (a where= ufunc: 4x slower)
            lp = np.zeros((Ta, 64), np.int32)
            lp.ravel()[nzi] = lvs
            levels[act, p] = lp
        return levels, J, D0, must, Rb

    #: tbs reconstructed at once (float64 temporaries of ~40 bytes per sample: 8 MiB at 3 planes;
    #: every tb is its own, so the chunks change no result)
    RECON_TBS = 1024

    def _reconstruct(self, base: np.ndarray, levels: np.ndarray, step16: np.ndarray) -> np.ndarray:
        """(T, 8, 8, P) clipped reconstruction of tbs from base predictions and levels (exact
        decoder integers: the clipped coefficients are below 2^40, so :func:`inverse_float`
        carries them in float64 exactly, and so does the sum with the prediction), in chunks of
        RECON_TBS tbs."""
        T = levels.shape[0]
        if T <= self.RECON_TBS:
            return self._reconstruct_tbs(base, levels, step16)
        out = np.empty(base.shape, np.int32)
        for a in range(0, T, self.RECON_TBS):
            out[a:a + self.RECON_TBS] = self._reconstruct_tbs(base[a:a + self.RECON_TBS],
                                                              levels[a:a + self.RECON_TBS], step16)
        return out

    def _reconstruct_tbs(self, base: np.ndarray, levels: np.ndarray, step16: np.ndarray) -> np.ndarray:
        T, P = levels.shape[0], self.P
        res = np.empty((T, TB, TB, P))
        for planes, tr in ((np.flatnonzero(~self.bypass), True), (np.flatnonzero(self.bypass), False)):
            if planes.size == 0:
                continue
            lv = levels if planes.size == P else levels[:, planes]
            blocks = _dequantize_float(lv[..., UNZIG] if tr else lv, step16[planes]).reshape(T, planes.size, TB, TB)
            if tr:
                blocks = inverse_float(blocks)
            if planes.size == P:
                res[...] = np.moveaxis(blocks, 1, -1)
            else:
                res[..., planes] = np.moveaxis(blocks, 1, -1)
        res += base
        flat = res.reshape(T, TB * TB * P)
        np.minimum(np.maximum(flat, self.lo_tb, out=flat), self.hi_tb, out=flat)
        return res.astype(np.int32)
