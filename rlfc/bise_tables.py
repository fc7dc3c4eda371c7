"""Tables of ASTC's Bounded Integer Sequence Encoding (BISE / integer sequence encoding).

Sources: Khronos Data Format Specification 1.3, section "Integer Sequence Encoding", and
ARM-software/astc-encoder ``Source/astcenc_integer_sequence.cpp``. On-wire values: do not
reorder any table.
"""
from __future__ import annotations

import numpy as np

# ASTC quantization ranges in quant-method order (index = ASTC quant method; do not reorder).
# Each row: (range N, plain bits n, trits, quints), N = 2^n, 3·2^n or 5·2^n.
RANGES = (
    (2, 1, 0, 0),     # QUANT_2
    (3, 0, 1, 0),     # QUANT_3
    (4, 2, 0, 0),     # QUANT_4
    (5, 0, 0, 1),     # QUANT_5
    (6, 1, 1, 0),     # QUANT_6
    (8, 3, 0, 0),     # QUANT_8
    (10, 1, 0, 1),    # QUANT_10
    (12, 2, 1, 0),    # QUANT_12
    (16, 4, 0, 0),    # QUANT_16
    (20, 2, 0, 1),    # QUANT_20
    (24, 3, 1, 0),    # QUANT_24
    (32, 5, 0, 0),    # QUANT_32
    (40, 3, 0, 1),    # QUANT_40
    (48, 4, 1, 0),    # QUANT_48
    (64, 6, 0, 0),    # QUANT_64
    (80, 4, 0, 1),    # QUANT_80
    (96, 5, 1, 0),    # QUANT_96
    (128, 7, 0, 0),   # QUANT_128
    (160, 5, 0, 1),   # QUANT_160
    (192, 6, 1, 0),   # QUANT_192
    (256, 8, 0, 0),   # QUANT_256
)
RANGE_VALUES = tuple(r[0] for r in RANGES)
RANGE_INDEX = {r[0]: i for i, r in enumerate(RANGES)}

# Bit layout of one trit group (5 values): fields in stream order, LSB first.
# ('m', k) = the n low bits of value k; ('T', lo, width) = bits lo..lo+width-1 of the 8-bit trit code.
TRIT_LAYOUT = (("m", 0), ("T", 0, 2), ("m", 1), ("T", 2, 2), ("m", 2), ("T", 4, 1),
               ("m", 3), ("T", 5, 2), ("m", 4), ("T", 7, 1))
# One quint group (3 values) with the 7-bit quint code Q.
QUINT_LAYOUT = (("m", 0), ("T", 0, 3), ("m", 1), ("T", 3, 2), ("m", 2), ("T", 5, 2))


def _bit(x: int, i: int) -> int:
    return (x >> i) & 1


def _bits(x: int, hi: int, lo: int) -> int:
    return (x >> lo) & ((1 << (hi - lo + 1)) - 1)


def decode_trit_code(t: int) -> tuple[int, int, int, int, int]:
    """The five trits of an 8-bit packed trit code (Khronos decode procedure)."""
    if _bits(t, 4, 2) == 0b111:
        c = (_bits(t, 7, 5) << 2) | _bits(t, 1, 0)
        t4 = t3 = 2
    else:
        c = _bits(t, 4, 0)
        if _bits(t, 6, 5) == 0b11:
            t4, t3 = 2, _bit(t, 7)
        else:
            t4, t3 = _bit(t, 7), _bits(t, 6, 5)
    if _bits(c, 1, 0) == 0b11:
        t2, t1 = 2, _bit(c, 4)
        t0 = (_bit(c, 3) << 1) | (_bit(c, 2) & (1 - _bit(c, 3)))
    elif _bits(c, 3, 2) == 0b11:
        t2, t1, t0 = 2, 2, _bits(c, 1, 0)
    else:
        t2, t1 = _bit(c, 4), _bits(c, 3, 2)
        t0 = (_bit(c, 1) << 1) | (_bit(c, 0) & (1 - _bit(c, 1)))
    return t0, t1, t2, t3, t4


def decode_quint_code(q: int) -> tuple[int, int, int]:
    """The three quints of a 7-bit packed quint code (Khronos decode procedure)."""
    if _bits(q, 2, 1) == 0b11 and _bits(q, 6, 5) == 0b00:
        q2 = (_bit(q, 0) << 2) | ((_bit(q, 4) & (1 - _bit(q, 0))) << 1) | (_bit(q, 3) & (1 - _bit(q, 0)))
        q1 = q0 = 4
    else:
        if _bits(q, 2, 1) == 0b11:
            q2 = 4
            c = (_bits(q, 4, 3) << 3) | ((3 - _bits(q, 6, 5)) << 1) | _bit(q, 0)
        else:
            q2 = _bits(q, 6, 5)
            c = _bits(q, 4, 0)
        if _bits(c, 2, 0) == 0b101:
            q1, q0 = 4, _bits(c, 4, 3)
        else:
            q1, q0 = _bits(c, 4, 3), _bits(c, 2, 0)
    return q0, q1, q2


def _build():
    trit_digits = np.array([decode_trit_code(t) for t in range(256)], dtype=np.uint8)      # (256, 5)
    quint_digits = np.array([decode_quint_code(q) for q in range(128)], dtype=np.uint8)    # (128, 3)
    # Encoder tables: digits -> code. Several codes decode to the same digits; like
    # astc-encoder we write the numerically largest one (iterate upwards, last wins).
    trit_code = np.full(243, -1, dtype=np.int16)
    for code, d in enumerate(trit_digits):
        trit_code[int(d[0]) + 3 * int(d[1]) + 9 * int(d[2]) + 27 * int(d[3]) + 81 * int(d[4])] = code
    quint_code = np.full(125, -1, dtype=np.int16)
    for code, d in enumerate(quint_digits):
        quint_code[int(d[0]) + 5 * int(d[1]) + 25 * int(d[2])] = code
    assert (trit_code >= 0).all() and (quint_code >= 0).all()
    return trit_digits, quint_digits, trit_code.astype(np.uint8), quint_code.astype(np.uint8)


TRIT_DIGITS, QUINT_DIGITS, TRIT_CODE, QUINT_CODE = _build()
for _t in (TRIT_DIGITS, QUINT_DIGITS, TRIT_CODE, QUINT_CODE):
    _t.setflags(write=False)
