"""Binary masks as COCO's compressed run-length encoding (RLE), without pycocotools.

A mask's runs are counted down its columns (Fortran order), starting with a run of
zeros; the counts are written as the ASCII string of COCO's ``maskApi.c``
(``rleToString``): each count less the one two before it, in 5-bit groups from the
lowest, 0x20 set on every group but the last, plus 48.  pycocotools' ``mask.decode``
reads the ``{"size": [h, w], "counts": str}`` it gives (tests/test_annotations.py
checks both ways against pycocotools where it is installed).
"""

from __future__ import annotations

import numpy as np


def runs(mask: np.ndarray) -> list[int]:
    """The run lengths of a 2-D boolean mask down its columns, zeros first."""
    flat = np.asarray(mask, bool).ravel(order="F")
    if flat.size == 0:
        return []
    change = np.flatnonzero(flat[1:] != flat[:-1]) + 1
    bounds = np.r_[0, change, flat.size]
    counts = np.diff(bounds).tolist()
    return ([0] + counts) if flat[0] else counts


def encode(mask: np.ndarray) -> dict:
    """A mask's compressed RLE: ``{"size": [h, w], "counts": str}``."""
    counts = runs(mask)
    out = []
    for i, c in enumerate(counts):
        x = c - counts[i - 2] if i > 2 else c
        more = True
        while more:
            ch = x & 0x1F
            x >>= 5  # arithmetic: a negative difference ends in −1
            more = x != -1 if ch & 0x10 else x != 0
            out.append(chr((ch | 0x20 if more else ch) + 48))
    h, w = np.asarray(mask).shape
    return {"size": [int(h), int(w)], "counts": "".join(out)}


def decode(rle: dict) -> np.ndarray:
    """The boolean mask of a compressed RLE (:func:`encode`'s inverse; its counts as
    text, or as the bytes pycocotools gives)."""
    h, w = (int(v) for v in rle["size"])
    s, counts, p = rle["counts"], [], 0
    s = s.decode("ascii") if isinstance(s, bytes) else s
    while p < len(s):
        x = k = 0
        more = True
        while more:
            c = ord(s[p]) - 48
            x |= (c & 0x1F) << (5 * k)
            more = bool(c & 0x20)
            p, k = p + 1, k + 1
            if not more and c & 0x10:
                x |= -1 << (5 * k)
        if len(counts) > 2:
            x += counts[-2]
        counts.append(x)
    if sum(counts) != h * w:
        raise ValueError(f"an RLE of {sum(counts)} pixels for a {h}×{w} mask")
    values = np.zeros(len(counts), bool)
    values[1::2] = True
    return np.repeat(values, counts).reshape((h, w), order="F")
