"""Doubles as Python writes them (``repr``), for many at once: the CSV's number formatting.

``repr(float)`` writes the shortest decimal that reads back to the same double (the one nearest
to it among the shortest), positional for decimal exponents from -4 to 15 (``0.0001``,
``123.0``), else scientific with a signed two-digit exponent at least (``1e-05``, ``1e+16``),
``nan``, ``inf``, ``-inf``, ``-0.0``. :func:`csv_bytes` writes the same text with Ryu's
shortest-digit algorithm (Ulf Adams, PLDI 2018: the digits from one 64 x 128-bit product with a
power of five and the interval of the double), compiled. test/test_trajectory_csv.py holds it to
``repr`` on millions of random bit patterns and the edge cases.

Cost, the four-bar's trajectory (10 001 rows x 25 doubles, rk4, exact closure) on a 2-core
AMD EPYC VM at 2.45 GHz with other work running, best of 36 passes, in one process with the
writer before: about 29 ns per value into a kept buffer (:func:`csv_into`), 30 ns for
:func:`csv_bytes` (57 ns before), 7.5 ms for the CSV of a 10 s run at 1 kHz, without holding
the GIL. Ryu's digits take some 17 ns of it: the power of five, the shift and the decimal
exponent are looked up by the double's exponent (:data:`EXP_MUL`, :data:`EXP_INT`; computing
them put a chain of products before the first multiplication), and one 64 x 128-bit product
gives the value and both ends of its interval (Ryu's ``mulShiftAll64``; three products
before). The text takes some 10 ns (about 35 before, with a fresh buffer per batch): the
shortest digits left-aligned to 17, made into two 8-digit words of ASCII at once by
multiplications, stored whole, and placed by the position of the point, every byte stored
through an unsigned index (no check for a negative one).
"""

from __future__ import annotations

import numpy as np

from vjm_ros.jit import HAVE_NUMBA, jit

COMPILED = HAVE_NUMBA
"""Whether :func:`csv_bytes` runs compiled (the CSV falls back to ``repr`` otherwise)."""

_POW5_BITCOUNT = 125
_POW5_INV_BITCOUNT = 125
_MASK64 = (1 << 64) - 1


def _tables() -> tuple[np.ndarray, np.ndarray]:
    """Ryu's tables: ``5^i`` and ``2^k / 5^q`` as 125-bit fixed point, (low, high) 64-bit words."""
    pow5 = np.zeros((326, 2), dtype=np.uint64)
    inv = np.zeros((342, 2), dtype=np.uint64)
    for i in range(len(pow5)):
        p = 5**i
        shift = p.bit_length() - _POW5_BITCOUNT
        v = p >> shift if shift >= 0 else p << -shift
        pow5[i] = (v & _MASK64, v >> 64)
    for q in range(len(inv)):
        p = 5**q
        v = (1 << (p.bit_length() - 1 + _POW5_INV_BITCOUNT)) // p + 1
        inv[q] = (v & _MASK64, v >> 64)
    return pow5, inv


POW5_SPLIT, POW5_INV_SPLIT = _tables()


def _by_exponent() -> tuple[np.ndarray, np.ndarray]:
    """Ryu's factor and shift for each biased exponent of a double, looked up rather than
    computed: the power of five (``2^k / 5^q`` for ``e2 >= 0``, else ``5^i``) as (low, high)
    words, shape (2047, 2); the shift ``j``, the decimal exponent and ``q``, shape (2047, 3).
    The digits' first product then waits for one load, not for a chain of products."""
    mul = np.zeros((2047, 2), dtype=np.uint64)
    ints = np.zeros((2047, 3), dtype=np.int16)
    for exponent in range(2047):
        e2 = max(exponent, 1) - 1023 - 52 - 2
        if e2 >= 0:
            q = ((e2 * 78913) >> 18) - (1 if e2 > 3 else 0)
            k = _POW5_INV_BITCOUNT + ((q * 1217359) >> 19)
            mul[exponent] = POW5_INV_SPLIT[q]
            ints[exponent] = (-e2 + q + k, q, q)
        else:
            q = ((-e2 * 732923) >> 20) - (1 if -e2 > 1 else 0)
            i = -e2 - q
            k = ((i * 1217359) >> 19) + 1 - _POW5_BITCOUNT
            mul[exponent] = POW5_SPLIT[i]
            ints[exponent] = (q - k, q + e2, q)
    return mul, ints


EXP_MUL, EXP_INT = _by_exponent()
POW10 = np.array([10**k for k in range(20)], dtype=np.uint64)

_U32 = np.uint64(0xFFFFFFFF)
_S32 = np.uint64(32)
_ZERO = np.uint64(0)
_ONE = np.uint64(1)
_TWO = np.uint64(2)
_FIVE = np.uint64(5)
_TEN = np.uint64(10)
_HUNDRED = np.uint64(100)
_E8 = np.uint64(10**8)
_MANTISSA = np.uint64((1 << 52) - 1)
_ABS = np.uint64((1 << 63) - 1)
_SIGN = np.uint64(63)


@jit(allocates=False, inline="always")
def _umul128(a, b):
    """``a * b`` of two uint64 as (high, low) words."""
    a_lo, a_hi, b_lo, b_hi = a & _U32, a >> _S32, b & _U32, b >> _S32
    b00 = a_lo * b_lo
    mid1 = a_hi * b_lo + (b00 >> _S32)
    mid2 = a_lo * b_hi + (mid1 & _U32)
    high = a_hi * b_hi + (mid1 >> _S32) + (mid2 >> _S32)
    return high, ((mid2 & _U32) << _S32) | (b00 & _U32)


@jit(allocates=False, inline="always")
def _shift_right(low, high, dist):
    """Bits ``dist`` .. ``dist + 63`` of ``high 2^64 + low`` (0 < ``dist`` < 64)."""
    return (high << (np.uint64(64) - dist)) | (low >> dist)


@jit(allocates=False, inline="always")
def _mul_shift_all(m2, lo, hi, j, mm_shift):
    """Ryu's ``mulShiftAll64``: ``(4 m2 + d) (hi 2^64 + lo) >> j`` for d = 0, 2 and
    -1 - ``mm_shift``, from two 64 x 64-bit products (``m2`` < 2^53, 64 < ``j`` - 2 < 128)."""
    m = m2 << _ONE
    tmp, low = _umul128(m, lo)
    high, mid_lo = _umul128(m, hi)
    mid = tmp + mid_lo
    if mid < tmp:
        high += _ONE
    low2 = low + lo
    mid2 = mid + hi + (_ONE if low2 < low else _ZERO)
    high2 = high + (_ONE if mid2 < mid else _ZERO)
    dist = np.uint64(j - 65)
    vp = _shift_right(mid2, high2, dist)
    if mm_shift:
        low3 = low - lo
        mid3 = mid - hi - (_ONE if low3 > low else _ZERO)
        high3 = high - (_ONE if mid3 > mid else _ZERO)
        vm = _shift_right(mid3, high3, dist)
    else:
        low3 = low + low
        mid3 = mid + mid + (_ONE if low3 < low else _ZERO)
        high3 = high + high + (_ONE if mid3 < mid else _ZERO)
        low4 = low3 - lo
        mid4 = mid3 - hi - (_ONE if low4 > low3 else _ZERO)
        high4 = high3 - (_ONE if mid4 > mid3 else _ZERO)
        vm = _shift_right(mid4, high4, dist + _ONE)
    return _shift_right(mid, high, dist), vp, vm


@jit(allocates=False, inline="always")
def _pow5_factor(value):
    """How many times 5 divides ``value`` (uint64 > 0)."""
    count = 0
    while value > 0 and value % _FIVE == 0:
        value //= _FIVE
        count += 1
    return count


@jit(allocates=False, inline="always")
def _shortest(mantissa, exponent):
    """Ryu's ``d2d``: shortest digits (uint64) and decimal exponent of a positive finite double
    from its stored mantissa and biased exponent."""
    if exponent == 0:
        e2 = 1 - 1023 - 52 - 2
        m2 = mantissa
    else:
        e2 = exponent - 1023 - 52 - 2
        m2 = (_ONE << np.uint64(52)) | mantissa
    accept_bounds = (m2 & _ONE) == 0
    mv = np.uint64(4) * m2
    mm_shift = mantissa != 0 or exponent <= 1
    vm_trailing, vr_trailing = False, False
    vr, vp, vm = _mul_shift_all(m2, EXP_MUL[exponent, 0], EXP_MUL[exponent, 1],
                                np.int64(EXP_INT[exponent, 0]), mm_shift)
    e10, q = np.int64(EXP_INT[exponent, 1]), np.int64(EXP_INT[exponent, 2])
    if e2 >= 0:
        if q <= 21:
            if mv % _FIVE == 0:
                vr_trailing = _pow5_factor(mv) >= q
            elif accept_bounds:
                vm_trailing = _pow5_factor(mv - _ONE - (_ONE if mm_shift else _ZERO)) >= q
            elif _pow5_factor(mv + _TWO) >= q:
                vp -= _ONE
    elif q <= 1:
        vr_trailing = True
        if accept_bounds:
            vm_trailing = mm_shift
        else:
            vp -= _ONE
    elif q < 63:
        vr_trailing = (mv & ((_ONE << np.uint64(q)) - _ONE)) == 0
    removed, last = 0, _ZERO
    if vm_trailing or vr_trailing:
        while vp // _TEN > vm // _TEN:
            vm_trailing = vm_trailing and vm % _TEN == 0
            vr_trailing = vr_trailing and last == 0
            last = vr % _TEN
            vr, vp, vm = vr // _TEN, vp // _TEN, vm // _TEN
            removed += 1
        if vm_trailing:
            while vm % _TEN == 0:
                vr_trailing = vr_trailing and last == 0
                last = vr % _TEN
                vr, vp, vm = vr // _TEN, vp // _TEN, vm // _TEN
                removed += 1
        if vr_trailing and last == _FIVE and vr % _TWO == 0:
            last = np.uint64(4)  # round half to even
        up = (vr == vm and (not accept_bounds or not vm_trailing)) or last >= _FIVE
    else:
        up = False
        vp100, vm100 = vp // _HUNDRED, vm // _HUNDRED
        if vp100 > vm100:  # two digits at once (the common case)
            vr100 = vr // _HUNDRED
            up = vr - _HUNDRED * vr100 >= np.uint64(50)
            vr, vp, vm = vr100, vp100, vm100
            removed += 2
        while True:
            vp10, vm10 = vp // _TEN, vm // _TEN
            if vp10 <= vm10:
                break
            vr10 = vr // _TEN
            up = vr - _TEN * vr10 >= _FIVE
            vr, vp, vm = vr10, vp10, vm10
            removed += 1
        up = up or vr == vm
    return vr + (_ONE if up else _ZERO), e10 + removed


@jit(allocates=False, inline="always")
def _put(buf, pos, byte):
    """``buf[pos] = byte`` through an unsigned index: no check for a negative one (some 10 of
    them per value otherwise)."""
    buf[np.uint64(pos)] = byte


@jit(allocates=False, inline="always")
def _eight(x):
    """The 8 decimal digits of ``x`` (uint64 < 10^8) as ASCII bytes in one uint64, the first
    digit in the lowest byte (two 4-digit halves, then 2-digit and 1-digit lanes at once)."""
    hi = x // np.uint64(10000)
    merged = hi | ((x - hi * np.uint64(10000)) << _S32)
    top = ((merged * np.uint64(10486)) >> np.uint64(20)) & np.uint64(0x7F0000007F)
    hundreds = ((merged - _HUNDRED * top) << np.uint64(16)) + top
    tens = ((hundreds * np.uint64(103)) >> np.uint64(10)) & np.uint64(0x000F000F000F000F)
    tens += (hundreds - _TEN * tens) << np.uint64(8)
    return tens | np.uint64(0x3030303030303030)


@jit(allocates=False, inline="always")
def _store8(buf, pos, word):
    """Write the 8 bytes of ``word`` at ``buf[pos:]``, lowest byte first."""
    at = np.uint64(pos)  # an unsigned index: no check for negative ones, and one 8-byte store
    for k in range(8):
        buf[at + np.uint64(k)] = np.uint8((word >> np.uint64(8 * k)) & np.uint64(0xFF))


@jit(allocates=False, inline="always")
def _put17(buf, pos, v):
    """Write the 17 digits of ``v`` (< 10^17, leading zeros included) at ``buf[pos:]``."""
    hi = v // _E8
    top = hi // _E8
    _put(buf, pos, np.uint8(48 + top))
    _store8(buf, pos + 1, _eight(hi - top * _E8))
    _store8(buf, pos + 9, _eight(v - hi * _E8))


@jit(allocates=False, inline="always")
def _decimal_length(v):
    """Digits of ``v`` (1 <= ``v`` < 10^17)."""
    if v >= POW10[14]:  # without a branch on 15, 16 or 17 digits
        return 15 + np.int64(v >= POW10[15]) + np.int64(v >= POW10[16])
    count = 14
    while v < POW10[count - 1]:
        count -= 1
    return count


@jit(allocates=False, inline="always")
def _put_float(buf, pos, bits):
    """Write the double of IEEE ``bits`` as ``repr`` does at ``buf[pos:]``; the end position.
    Writes up to 24 bytes past ``pos`` (digits past the end position included)."""
    if bits >> _SIGN:
        _put(buf, pos, 45)  # "-"
        pos += 1
    magnitude = bits & _ABS
    if magnitude == 0:
        _put(buf, pos, 48)  # "0.0"
        _put(buf, pos + 1, 46)
        _put(buf, pos + 2, 48)
        return pos + 3
    exponent = np.int64(magnitude >> np.uint64(52))
    mantissa = magnitude & _MANTISSA
    if exponent == 0x7FF:
        if mantissa != 0:
            pos -= np.int64(bits >> _SIGN)  # no sign
            _put(buf, pos, 110)  # "nan"
            _put(buf, pos + 1, 97)
            _put(buf, pos + 2, 110)
        else:
            _put(buf, pos, 105)  # "inf"
            _put(buf, pos + 1, 110)
            _put(buf, pos + 2, 102)
        return pos + 3
    digits, e10 = _shortest(mantissa, exponent)
    count = _decimal_length(digits)
    point = e10 + count  # the value is 0.d1 d2 ... x 10^point
    aligned = digits * POW10[17 - count]  # the digits, then zeros: 17 of them
    if point <= -4 or point > 16:  # scientific: d.ddde-XX
        _put17(buf, pos + 1, aligned)
        _put(buf, pos, buf[np.uint64(pos + 1)])
        _put(buf, pos + 1, 46)  # "."
        pos += count + 1 if count > 1 else 1
        exp10 = point - 1
        _put(buf, pos, 101)  # "e"
        _put(buf, pos + 1, 45 if exp10 < 0 else 43)  # "-" or "+"
        e = -exp10 if exp10 < 0 else exp10
        if e >= 100:
            _put(buf, pos + 2, 48 + e // 100)
            pos += 1
            e %= 100
        _put(buf, pos + 2, 48 + e // 10)
        _put(buf, pos + 3, 48 + e % 10)
        return pos + 4
    if point <= 0:  # 0.000ddd
        _put(buf, pos, 48)
        _put(buf, pos + 1, 46)
        _put(buf, pos + 2, 48)
        _put(buf, pos + 3, 48)
        _put(buf, pos + 4, 48)
        pos += 2 - point
        _put17(buf, pos, aligned)
        return pos + count
    if point >= count:  # an integer: the digits, zeros up to the point, ".0"
        _put17(buf, pos, aligned)
        _put(buf, pos + point, 46)
        _put(buf, pos + point + 1, 48)
        return pos + point + 2
    _put17(buf, pos + 1, aligned)  # then the integer part moves left by one
    for k in range(point):
        _put(buf, pos + k, buf[np.uint64(pos + k + 1)])
    _put(buf, pos + point, 46)
    return pos + count + 1


VALUE_BYTES = 25
"""Bytes a value and the comma after it take at most (``-2.2250738585072014e-308,``); the
writer also stays within them when it writes digits past a value's end."""


def buffer_size(rows: int, columns: int) -> int:
    """Bytes of the buffer :func:`csv_into` needs for a table of ``rows`` x ``columns``.

    Parameters
    ----------
    rows, columns : int

    Returns
    -------
    int
        :data:`VALUE_BYTES` per value and two more per row (``\\r\\n``).
    """
    return rows * (columns * VALUE_BYTES + 2)


@jit(allocates=False)
def _csv(bits, buf):
    """Write the CSV rows of the doubles of IEEE ``bits`` (uint64, shape (rows, columns)) at the
    start of ``buf`` (uint8, at least :func:`buffer_size` bytes); the bytes written, -1 (and
    nothing written) when ``buf`` is too short."""
    rows, cols = bits.shape
    if len(buf) < rows * (cols * VALUE_BYTES + 2):
        return -1
    pos = 0
    for r in range(rows):
        for c in range(cols):
            pos = _put_float(buf, pos, bits[r, c])
            _put(buf, pos, 44)  # ","
            pos += 1
        if cols:
            pos -= 1  # the last comma gives way to the line end
        _put(buf, pos, 13)  # "\r\n"
        _put(buf, pos + 1, 10)
        pos += 2
    return pos


def _bits(table: np.ndarray) -> np.ndarray:
    """``table`` as C-ordered doubles, viewed as their IEEE bits (uint64)."""
    return np.ascontiguousarray(table, dtype=np.float64).view(np.uint64)


def csv_into(table: np.ndarray, buf: np.ndarray) -> int:
    """Write the CSV rows of ``table`` (see :func:`csv_bytes`) at the start of ``buf``.

    For a writer that keeps one buffer for every batch of rows: no allocation, and the file
    takes ``memoryview(buf)[:n]`` without a copy.

    Parameters
    ----------
    table : ndarray, shape (rows, columns)
    buf : ndarray of uint8, shape (at least ``buffer_size(rows, columns)``,)
        C-contiguous.

    Returns
    -------
    int
        Bytes written, ``n``: the text is ``buf[:n]``.

    Raises
    ------
    ValueError
        ``buf`` is shorter than :func:`buffer_size`.
    """
    bits = _bits(table)
    written = _csv(bits, buf)
    if written < 0:
        raise ValueError(f"CSV buffer of {len(buf)} bytes, {buffer_size(*bits.shape)} needed")
    return written


def csv_bytes(table: np.ndarray) -> bytes:
    """CSV rows of ``table``: values as ``repr(float(value))``, ``,`` between, ``\\r\\n`` after.

    Parameters
    ----------
    table : ndarray, shape (rows, columns)

    Returns
    -------
    bytes
        ASCII text.
    """
    bits = _bits(table)
    buf = np.empty(buffer_size(*bits.shape), dtype=np.uint8)
    return buf[: _csv(bits, buf)].tobytes()
