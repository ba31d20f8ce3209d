"""A frame read from disk: a PNG or a JPEG checked by its magic bytes and its size, its
bytes' SHA-256 (checked against its capture record), and a JPEG's quality from its
quantization tables."""

from __future__ import annotations

import errno
import hashlib
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mirrorsim.errors import InputError
from mirrorsim.formats.files import decode_image, read_regular_bytes
from mirrorsim.scene.model import MAX_RESOLUTION

# a frame file's first bytes: PNG's signature, and JPEG's start-of-image marker and the
# next marker's 0xFF (a JPEG stores its colour at half resolution: see measure_region)
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
JPEG_MAGIC = b"\xff\xd8\xff"


@dataclass(frozen=True)
class StoredFrame:
    """A frame's 8-bit RGB pixels and whether its file stored the colour at half
    resolution (a JPEG's 4:2:0 chroma), which the detector measures otherwise: both
    from one read of the file, so that a file replaced between two reads cannot pair
    one file's pixels with the other's kind."""

    pixels: np.ndarray
    subsampled: bool
    jpeg_quality: int = 0  # the JPEG's quality as its tables say (0: a lossless frame)
    sha256: str = ""  # of the file's bytes, as read (what a capture record names)


def read_frame(path: str | Path, size: tuple[int, int] | None = None) -> np.ndarray:
    """An 8-bit RGB frame from a PNG or JPEG file (see :func:`read_stored_frame`)."""
    return read_stored_frame(path, size).pixels


def read_stored_frame(path: str | Path, size: tuple[int, int] | None = None) -> StoredFrame:
    """An 8-bit RGB frame from a PNG or JPEG file, and whether it is a JPEG.

    Its size is read from the file's header before anything is decoded: a frame larger
    than ``MAX_RESOLUTION``, or (``size``: the capture record's camera, width × height)
    of another size, is refused at once.

    Raises
    ------
    InputError
        If the file is missing, not a PNG or JPEG, of the wrong size, or damaged (one
        line, no library noise).  A JPEG gives a warning: compression blurs the edges
        that are measured.
    """
    try:
        raw = read_regular_bytes(path)
    except FileNotFoundError:
        raise InputError(path, "", "no such file") from None
    except OSError as exc:  # "not a regular file" for a folder, FIFO, device or socket
        raise InputError(path, "", exc.strerror if exc.errno == errno.EINVAL and
                         exc.strerror else f"cannot read: {exc.strerror or exc}") from None
    head = raw[:8]
    if not (head.startswith(PNG_MAGIC) or head.startswith(JPEG_MAGIC)):
        raise InputError(path, "", "not a PNG or JPEG image")
    found = header_size(raw)
    if found is None:
        raise InputError(path, "", "a damaged image: its header gives no size")
    if size is not None and found != tuple(size):
        raise InputError(path, "", f"the frame is {found[0]}×{found[1]} px but the capture "
                         f"record's camera is {size[0]}×{size[1]}")
    if found[0] > MAX_RESOLUTION[0] or found[1] > MAX_RESOLUTION[1]:
        raise InputError(path, "", f"the frame is {found[0]}×{found[1]} px, over the "
                         f"largest camera ({MAX_RESOLUTION[0]}×{MAX_RESOLUTION[1]})")
    rgb = decode_image(raw)
    if rgb is None:
        raise InputError(path, "", "a damaged image that cannot be decoded")
    jpeg = head.startswith(JPEG_MAGIC)
    if jpeg:
        warnings.warn(f"{path}: a JPEG frame: compression blurs the edges the detector "
                      "measures; expect larger errors", RuntimeWarning, stacklevel=2)
    return StoredFrame(rgb, jpeg, jpeg_quality(raw) if jpeg else 0,
                       hashlib.sha256(raw).hexdigest())


# libjpeg's luminance quantization table at quality 50 (ITU-T T.81 Annex K), whose
# scaled copy a JPEG of quality q holds: its sum is all an estimate of q needs, so the
# order the file stores it in (zigzag) does not matter
_IJG_LUMA_SUM = 3688


def jpeg_quality(data: bytes) -> int:
    """The quality (1–100) a JPEG was written at, estimated from its first quantization
    table as libjpeg scales it (q < 50: ×5000/q %, else ×(200 − 2q) %); 0 for a file
    without one.  What the frame shows of its compression, known without the scene."""
    i = 2
    while i + 4 < len(data):
        if data[i] != 0xFF:
            return 0
        marker = data[i + 1]
        if marker in (0xD8, 0x01, 0xFF) or 0xD0 <= marker <= 0xD7:
            i += 1 if marker == 0xFF else 2
            continue
        length = int.from_bytes(data[i + 2:i + 4], "big")
        if marker == 0xDB:  # DQT: Pq/Tq, then 64 values of 8 (Pq 0) or 16 bits
            precision = data[i + 4] >> 4
            body = data[i + 5:i + 5 + 64 * (1 + precision)]
            values = (np.frombuffer(body, ">u2") if precision else
                      np.frombuffer(body, np.uint8)).astype(float)
            if values.size != 64:
                return 0
            scale = 100.0 * values.sum() / _IJG_LUMA_SUM
            q = 5000.0 / scale if scale > 100.0 else (200.0 - scale) / 2.0
            return int(np.clip(round(q), 1, 100))
        if marker == 0xDA:  # the scan starts: no table came before it
            return 0
        i += 2 + length
    return 0


def header_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) from a PNG's IHDR or a JPEG's start-of-frame marker, without
    decoding; None if the header is damaged."""
    if data.startswith(PNG_MAGIC):
        if len(data) < 24 or data[12:16] != b"IHDR":
            return None
        return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
    i = 2
    while i + 9 < len(data):
        if data[i] != 0xFF:
            return None
        while data[i + 1] == 0xFF and i + 10 < len(data):  # fill bytes before a marker
            i += 1
        marker = data[i + 1]
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:  # no length follows
            i += 2
            continue
        # SOF0..SOF15 hold the size; C4 (Huffman), C8 (reserved), CC (arithmetic) do not
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            return int.from_bytes(data[i + 7:i + 9], "big"), int.from_bytes(
                data[i + 5:i + 7], "big")
        i += 2 + int.from_bytes(data[i + 2:i + 4], "big")
    return None
