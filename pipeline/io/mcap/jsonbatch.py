"""JSON messages decoded many at a time, for the common case of a logger writing the same
message shape over and over with only the numbers changing (``{"value": 0.25}``, ``{"stamp":
{"sec": .., "nsec": ..}, "gauges": [..]}``).

The payloads of a chunk are scanned with numpy: a number token starts with ``-`` or a digit
right after ``:``, ``[``, ``,`` or white space and runs over ``0-9 + - . e E``. When every
message has the same number of tokens and the same bytes between them (its *skeleton*), the
messages differ only in their numbers: the first message with token k replaced by the
integer ``1000000 + k`` is parsed by :func:`json.loads` once, which tells which token (or run
of tokens, for an array) a field path names, and that token's text is converted for every
message at once. Otherwise :class:`Unsupported` is raised and the caller parses the messages
with :func:`json.loads`.

Number text to float64 is exact (the same double as Python's ``float`` of the text, which is
what ``json.loads`` gives): a mantissa of up to 19 significant digits M and a decimal exponent
e are read; ``M * 10**e`` is one correctly rounded float64 operation when M <= 2**53 and |e|
<= 22, else one correctly rounded operation in 64-bit-mantissa long double (|e| <= 27), whose
rounding to float64 is exact unless it lands exactly on a midpoint between two doubles; the
remaining tokens (longer mantissas, larger exponents, midpoints, a platform without x87 long
double) go through Python's ``float``. A JSON integer becomes ``float(int)`` (so ``-0`` is
+0.0, as ``json.loads`` gives 0).
"""

from __future__ import annotations

import json

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from .cdr import Unsupported

__all__ = ["JsonBatch", "parse_numbers"]

_LUT_NUM = np.zeros(256, dtype=bool)
_LUT_NUM[list(b"0123456789+-.eE")] = True
_LUT_START = np.zeros(256, dtype=bool)
_LUT_START[list(b"0123456789-")] = True
_LUT_DELIM = np.zeros(256, dtype=bool)
_LUT_DELIM[list(b":[, \t\r\n")] = True

_P10 = 10.0 ** np.arange(23)
_EXTENDED = np.finfo(np.longdouble).nmant >= 63
_P10L = np.array([10 ** k for k in range(28)], dtype=np.longdouble) if _EXTENDED else None
_PROBE = 1_000_000


def _matrix(buf: np.ndarray, start: np.ndarray, length: np.ndarray) -> np.ndarray:
    """(n, max length) uint8 of the byte strings buf[start:start+length], zero-padded."""
    w = int(length.max()) if length.size else 0
    out = np.zeros((start.size, w), dtype=np.uint8)
    if w == 0:
        return out
    whole = start + w <= buf.size
    out[whole] = sliding_window_view(buf, w)[start[whole]]
    for i in np.flatnonzero(~whole):  # near the end of the buffer
        part = buf[start[i]:start[i] + w]
        out[i, :part.size] = part
    out[np.arange(w) >= length[:, None]] = 0
    return out


def parse_numbers(mat: np.ndarray, length: np.ndarray):
    """JSON number texts to float64, exactly as ``json.loads`` then ``float``.

    Parameters
    ----------
    mat : ndarray of uint8, shape (n, w)
        One number text per row, zero-padded.
    length : ndarray of int64
        Text lengths [B].

    Returns
    -------
    values : ndarray of float64
    is_int : ndarray of bool
        The text is a JSON integer (no fraction, no exponent).
    mantissa : ndarray of uint64
        The digits as an integer (the magnitude of an integer text).

    Raises
    ------
    Unsupported
        A text that is not a JSON number (the caller parses the messages one by one, and
        :func:`json.loads` names the problem).
    """
    n, w = mat.shape
    if w == 0 or np.any(length <= 0):
        raise Unsupported("an empty number")
    col = np.arange(w)
    inside = col < length[:, None]
    digit = (np.subtract(mat, 48, dtype=np.uint8) < 10) & inside
    dot, ech = mat == ord("."), (mat == ord("e")) | (mat == ord("E"))
    sign = (mat == ord("-")) | (mat == ord("+"))
    if np.count_nonzero(digit | dot | ech | sign | ~inside) != digit.size:
        raise Unsupported("a token is not a JSON number")
    n_dot, n_e, n_sign = (np.count_nonzero(x, axis=1) for x in (dot, ech, sign))
    has_dot, has_e = n_dot == 1, n_e == 1
    epos = np.where(has_e, ech.argmax(axis=1), length)
    dpos = np.where(has_dot, dot.argmax(axis=1), epos)
    neg = mat[:, 0] == ord("-")
    i0 = neg.astype(np.int64)
    exp_sign = has_e & (epos + 1 < length) & sign[np.arange(n), np.minimum(epos + 1, w - 1)]
    first = mat[np.arange(n), np.minimum(i0, w - 1)]
    second = mat[np.arange(n), np.minimum(i0 + 1, w - 1)]
    ok = ((n_dot <= 1) & (n_e <= 1) & (n_sign == i0 + exp_sign) & (mat[:, 0] != ord("+"))
          & (dpos > i0)                                      # an integer part
          & ((first != ord("0")) | (dpos == i0 + 1) | (second == ord("."))
             | (second == ord("e")) | (second == ord("E")) | (i0 + 1 >= length))  # no leading zero
          & (~has_dot | (dpos + 1 < epos))                   # digits after the dot
          & (~has_e | (epos + 1 + exp_sign < length)))       # digits in the exponent
    if not ok.all():
        raise Unsupported("a token is not a JSON number")
    mant = digit & (col < epos[:, None])
    # significant digits: from the first non-zero one
    nz = np.logical_or.accumulate(mant & (mat != ord("0")), axis=1)
    sig = np.count_nonzero(mant & nz, axis=1)
    frac = np.count_nonzero(mant & (col > dpos[:, None]), axis=1)
    d = np.ascontiguousarray(np.subtract(mat, 48, dtype=np.uint8).T)
    mt = np.ascontiguousarray(mant.T)
    m = np.zeros(n, dtype=np.uint64)
    ten = np.uint64(10)
    for c in range(int(epos.max())):  # rows with more than 19 digits go through Python's float
        m = np.where(mt[c], m * ten + d[c], m)
    ex = np.zeros(n, dtype=np.int64)
    if has_e.any():
        n_exp = np.where(has_e, length - epos - 1 - exp_sign, 0)  # exponent digits, at the end
        if n_exp.max() > 6:
            raise Unsupported("an exponent of more than 6 digits")
        rows = np.arange(n)
        for k in range(int(n_exp.max())):
            at = k < n_exp
            ex += np.where(at, (mat[rows, np.maximum(length - 1 - k, 0)].astype(np.int64) - 48) * 10 ** k, 0)
    eneg = exp_sign & (mat[np.arange(n), np.minimum(epos + 1, w - 1)] == ord("-"))
    is_int = ~(has_dot | has_e)
    e10 = np.where(eneg, -ex, ex) - frac
    values = np.empty(n, dtype=np.float64)
    exact = sig <= 19
    zero = m == 0
    fast = exact & (zero | ((m <= np.uint64(2 ** 53)) & (np.abs(e10) <= 22)))
    mf = m.astype(np.float64)
    k = np.clip(np.abs(e10), 0, 22)
    values[:] = np.where(e10 >= 0, mf * _P10[k], mf / _P10[k])
    values[zero] = 0.0
    rest = ~fast
    if rest.any() and _EXTENDED:
        sel = rest & exact & (np.abs(e10) <= 27)
        if sel.any():
            ml = m[sel].astype(np.longdouble)
            es = e10[sel]
            pl = _P10L[np.abs(es)]
            ld = np.where(es >= 0, ml * pl, ml / pl)
            r = ld.astype(np.float64)
            up = (r.astype(np.longdouble) + np.nextafter(r, np.inf).astype(np.longdouble)) / 2
            down = (r.astype(np.longdouble) + np.nextafter(r, -np.inf).astype(np.longdouble)) / 2
            ok = (ld != up) & (ld != down)
            idx = np.flatnonzero(sel)
            values[idx[ok]] = r[ok]
            rest[idx[ok]] = False
    for i in np.flatnonzero(rest):
        text = mat[i, :length[i]].tobytes()
        if is_int[i]:
            if length[i] > 300:
                raise Unsupported("an integer too long for a float")
            values[i] = abs(float(int(text)))
        else:
            values[i] = abs(float(text))
    values = np.where(neg & ~(is_int & (values == 0)), -values, values)
    return values, is_int, m


def _number_chars(buf: np.ndarray) -> np.ndarray:
    """Mask of the bytes ``0-9 + - . e E`` (comparisons: faster than a table lookup)."""
    out = np.subtract(buf, 48, dtype=np.uint8) < 10
    for c in b"+-.eE":
        out |= buf == c
    return out


class JsonBatch:
    """The JSON payloads of a chunk's messages of one channel, tokenized together.

    Parameters
    ----------
    buf : ndarray of uint8
        The chunk's uncompressed records.
    start, length : ndarray of int64
        Offsets of the payloads in ``buf`` (ascending, not overlapping) and their lengths [B].

    Raises
    ------
    Unsupported
        The messages do not all have the first one's skeleton.
    """

    def __init__(self, buf: np.ndarray, start: np.ndarray, length: np.ndarray):
        n = start.size
        if n == 0 or np.any(length <= 0):
            raise Unsupported("empty payload")
        if start[0] == 0:
            raise Unsupported("payload at the start of the buffer")
        end = start + length
        # runs of number characters, broken where a payload starts
        pos = np.flatnonzero(_number_chars(buf))
        first_of = np.zeros(buf.size + 1, dtype=bool)
        first_of[start] = True
        brk = (np.diff(pos) != 1) | first_of[pos[1:]]
        rs = pos[np.concatenate(([True], brk))]
        re_ = pos[np.concatenate((brk, [True]))] + 1
        # a token: a run starting with - or a digit after a delimiter or at a payload's start
        tok = _LUT_START[buf[rs]] & (_LUT_DELIM[buf[rs - 1]] | first_of[rs])
        ts, te = rs[tok], re_[tok]
        msg = np.searchsorted(start, ts, side="right") - 1
        inside = (msg >= 0) & (ts < end[np.maximum(msg, 0)])
        ts, te, msg = ts[inside], te[inside], msg[inside]
        if np.any(te > end[msg]):
            raise Unsupported("a number runs past the end of its message")
        counts = np.bincount(msg, minlength=n)
        k = int(counts[0])
        if np.any(counts != k):
            raise Unsupported("messages with different numbers of numbers")
        ts, te = ts.reshape(n, k), te.reshape(n, k)
        # the skeleton: the bytes between the numbers, the same in every message
        seg_start = np.concatenate((start[:, None], te), axis=1)
        seg_len = np.concatenate((ts, end[:, None]), axis=1) - seg_start
        if np.any(seg_len != seg_len[0]):
            raise Unsupported("messages of different shapes")
        for j, size in enumerate(seg_len[0].tolist()):
            if size:
                rows = sliding_window_view(buf, size)[seg_start[:, j]]
                if np.count_nonzero(rows != rows[0]):
                    raise Unsupported("messages of different shapes")
        self.buf, self.n, self.k = buf, n, k
        self.tok_start, self.tok_len = ts, te - ts
        first = bytearray()
        pos = int(start[0])
        for j in range(k):
            first += buf[pos:ts[0, j]].tobytes() + str(_PROBE + j).encode()
            pos = int(te[0, j])
        first += buf[pos:end[0]].tobytes()
        try:
            self.probe = json.loads(first.decode("utf-8"))
        except (ValueError, UnicodeDecodeError):
            raise Unsupported("the first message is not JSON") from None

    def token(self, value) -> int | None:
        """The token index a probed value stands for (None: not a number token)."""
        if type(value) is int and _PROBE <= value < _PROBE + self.k:
            return value - _PROBE
        return None

    def numbers(self, j: int):
        """(values float64, is_int, mantissa) of token ``j`` of every message (:func:`parse_numbers`)."""
        return parse_numbers(_matrix(self.buf, self.tok_start[:, j], self.tok_len[:, j]), self.tok_len[:, j])
