"""Records of one fixed byte layout, many at once: a template copied and its numbers written in.

A per-tick MCAP Message record (:mod:`vjm_ros.logs.mcap_block`) is a constant byte image in
which only numbers change from tick to tick: the record's sequence number (``uint32``), its log
and publish times (``uint64``, ns), the message stamps (``int32`` seconds, ``uint32``
nanoseconds) and runs of ``float64`` values, all little-endian at fixed byte offsets.
:func:`stamp_records` writes a whole block of such records in one compiled pass (the GIL
released): the image copied to each record's place, then every number stored at its offset.
Offsets need no alignment.

Cost, the four-bar's 10 s log (10 001 ticks of 623 bytes, five messages each, and 1001 markers
records), its ten blocks replayed in one process: 0.9 ms for every record, against about 4.5 ms
for the numpy column writes it replaces (the image broadcast to every row, a strided copy per
number and block, and the rows copied once more to interleave the markers).
"""

from __future__ import annotations

import numpy as np

from vjm_ros.jit import jit


@jit(allocates=False, inline="always")
def _put(out, at, value, width):
    """Store the ``width`` low bytes of ``value`` (uint64) at ``out[at:]``, little-endian
    (through unsigned indices: no check for a negative one, so the stores merge into one)."""
    for i in range(width):
        out[np.uint64(at + i)] = (value >> np.uint64(8 * i)) & np.uint64(0xFF)


@jit(allocates=False)
def stamp_records(out, starts, image, seq, ns, seq_at, ns_at, stamp_at, bits, bits_at):
    """Write ``len(starts)`` records of layout ``image`` into ``out``.

    Parameters
    ----------
    out : ndarray of uint8
        Written at ``starts[r] : starts[r] + len(image)`` for each record ``r``.
    starts : ndarray of int64, shape (R,)
        Byte offset of each record in ``out``.
    image : ndarray of uint8, shape (S,)
        The record with every number zero.
    seq : ndarray of uint64, shape (R,)
        Sequence number of each record, stored as ``uint32`` at each offset of ``seq_at``.
    ns : ndarray of uint64, shape (R,)
        Time of each record, ns: stored as ``uint64`` at each offset of ``ns_at``, and as a
        stamp (``int32`` s, ``uint32`` ns) at each offset of ``stamp_at``.
    seq_at, ns_at, stamp_at : ndarray of int64
        Byte offsets in a record.
    bits : ndarray of uint64, shape (R, V)
        IEEE bits of each record's ``float64`` values.
    bits_at : ndarray of int64, shape (V,)
        Byte offset of each value in a record.
    """
    size = np.uint64(len(image))
    billion = np.uint64(1_000_000_000)
    for r in range(len(starts)):
        base = np.uint64(starts[r])
        for i in range(size):
            out[base + i] = image[i]
        for at in seq_at:
            _put(out, base + np.uint64(at), seq[r], 4)
        t = ns[r]
        for at in ns_at:
            _put(out, base + np.uint64(at), t, 8)
        for at in stamp_at:
            _put(out, base + np.uint64(at), t // billion, 4)
            _put(out, base + np.uint64(at) + np.uint64(4), t % billion, 4)
        for j in range(len(bits_at)):
            _put(out, base + np.uint64(bits_at[j]), bits[r, j], 8)
