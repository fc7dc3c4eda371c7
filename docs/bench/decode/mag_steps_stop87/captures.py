"""The stop-87 measurement scripts' capture hooks: `magnitudes(caps)` records every
rlfc.txparse._magnitudes call (inputs, outputs, lane states after) into the list caps;
`parse_streams()` records every Residuals._parse_streams call and returns the list it fills."""
import numpy as np


def magnitudes(caps: list) -> None:
    import rlfc.txparse as tp
    orig = tp._magnitudes

    def wrap(dec, tables, S, per_lane, lane_start, j, ctx1):
        caps.append(dict(x=dec.x.copy(), ptr=dec.ptr.copy(), buf=dec.buf, top=dec.top, tables=tables, S=S,
                         per_lane=per_lane, lane_start=lane_start, j=j, ctx1=ctx1))
        r = orig(dec, tables, S, per_lane, lane_start, j, ctx1)
        caps[-1].update(out=r, x_after=dec.x.copy(), ptr_after=dec.ptr.copy())
        return r
    tp._magnitudes = wrap


def parse_streams() -> list:
    import rlfc.profiles.tx_residual as trm
    captured = []
    orig = trm.Residuals._parse_streams

    def ps(self, buf, s2, e2, nt, kind, key):
        captured.append((self, buf, s2.copy(), e2.copy(), nt, np.asarray(kind).copy(), np.asarray(key).copy()))
        return orig(self, buf, s2, e2, nt, kind, key)
    trm.Residuals._parse_streams = ps
    return captured
