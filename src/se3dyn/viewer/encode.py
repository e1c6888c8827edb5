"""Compact binary frames for the page: quantised positions and rotations, deflate, base64.

Frames ``H`` (n, M, 4, 4) become 6 unsigned 16-bit integers per node and stored time (12 bytes
instead of 128):

* position ``x``: per node and axis over the run, ``u = round((x - lo) / (hi - lo) * 65535)``;
  the error is at most ``(hi - lo) / 131070`` (about 8e-6 of the node's travel);
* rotation, as the unit quaternion ``q = (x, y, z, w)``: "smallest three". The component of
  largest magnitude ``q_i`` (at least 1/2) is dropped after making it positive (``q`` and ``-q``
  are the same rotation); the other three lie in [-1/sqrt 2, 1/sqrt 2] and are stored in 15 bits
  each, ``v = round((c sqrt 2 + 1) / 2 * 32767)``; the index i takes the top bits of the first two
  words. The dropped component is ``sqrt(1 - sum c^2)``. With the step ``d = sqrt 2 / 32767``
  each stored component is off by at most d/2, the dropped one (>= 1/2) by at most
  ``sqrt 3 d``, so the quaternion by ``sqrt 3 d`` and the rotation angle by at most
  ``2 sqrt 3 d = 1.5e-4`` rad (:data:`ANGLE_BOUND`).

The (n, M, 6) words are then differenced along time (mod 2^16: smooth motion gives small
numbers), split into low and high bytes and deflated (zlib): :func:`decode_frames` and the page's
JavaScript undo the same steps in reverse.
"""

from __future__ import annotations

import base64
import zlib

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = ["ANGLE_BOUND", "quaternions", "encode_frames", "decode_frames", "pack", "unpack", "Blob"]

_Q15 = 32767.0
_S = np.sqrt(0.5)
#: Largest rotation angle error of the quantised rotations (rad), see the module docstring.
ANGLE_BOUND = 2.0 * np.sqrt(3.0) * np.sqrt(2.0) / _Q15


def quaternions(R: np.ndarray, continuous: bool = True) -> np.ndarray:
    """Unit quaternions ``(x, y, z, w)`` of rotation matrices.

    Parameters
    ----------
    R : ndarray, shape (n, M, 3, 3)
    continuous : bool
        Flip signs so that consecutive quaternions of a node (axis 0) have a non-negative dot
        product (shortest-path interpolation between stored times, as glTF expects).

    Returns
    -------
    ndarray, shape (n, M, 4)
    """
    n, M = R.shape[:2]
    q = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_quat().reshape(n, M, 4)
    if continuous and n > 1:
        for k in range(1, n):
            flip = np.einsum("ij,ij->i", q[k], q[k - 1]) < 0
            q[k, flip] = -q[k, flip]
    return q


def encode_frames(H: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quantise frames (see the module docstring).

    Parameters
    ----------
    H : ndarray, shape (n, M, 4, 4)

    Returns
    -------
    words : ndarray of uint16, shape (n, M, 6)
        3 position words, 3 rotation words per node and time (before the time differences).
    lo, hi : ndarray, shape (M, 3)
        Position bounds of each node over the run.
    """
    H = np.asarray(H, dtype=float)
    n, M = H.shape[:2]
    x = H[:, :, :3, 3]
    lo = x.min(axis=0) if n else np.zeros((M, 3))
    hi = x.max(axis=0) if n else np.zeros((M, 3))
    span = np.where(hi > lo, hi - lo, 1.0)
    words = np.zeros((n, M, 6), dtype=np.uint16)
    words[..., :3] = np.rint((x - lo) / span * 65535.0).clip(0, 65535).astype(np.uint16)
    q = quaternions(H[:, :, :3, :3], continuous=False)
    i = np.argmax(np.abs(q), axis=-1)
    big = np.take_along_axis(q, i[..., None], axis=-1)
    q = q * np.where(big < 0, -1.0, 1.0)
    # the three remaining components, in order
    keep = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])[i]
    c = np.take_along_axis(q, keep, axis=-1)
    v = np.rint((c / _S + 1.0) * 0.5 * _Q15).clip(0, _Q15).astype(np.uint16)
    words[..., 3] = v[..., 0] | ((i & 1) << 15).astype(np.uint16)
    words[..., 4] = v[..., 1] | ((i >> 1) << 15).astype(np.uint16)
    words[..., 5] = v[..., 2]
    return words, lo, hi


def decode_frames(words: np.ndarray, lo: np.ndarray, hi: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`encode_frames` (the page does the same in JavaScript).

    Returns
    -------
    x : ndarray, shape (n, M, 3)
        Positions.
    q : ndarray, shape (n, M, 4)
        Unit quaternions ``(x, y, z, w)``.
    """
    w = np.asarray(words).astype(np.int64)
    span = np.where(hi > lo, hi - lo, 0.0)
    x = lo + w[..., :3] / 65535.0 * span
    i = (w[..., 3] >> 15) | ((w[..., 4] >> 15) << 1)
    c = np.stack([w[..., 3] & 0x7FFF, w[..., 4] & 0x7FFF, w[..., 5] & 0x7FFF], axis=-1)
    c = (c / _Q15 * 2.0 - 1.0) * _S
    big = np.sqrt(np.clip(1.0 - np.sum(c * c, axis=-1), 0.0, None))
    q = np.zeros(w.shape[:-1] + (4,))
    keep = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])[i]
    np.put_along_axis(q, keep, c, axis=-1)
    np.put_along_axis(q, i[..., None], big[..., None], axis=-1)
    return x, q / np.linalg.norm(q, axis=-1, keepdims=True)


class Blob:
    """A typed array for the page: ``dtype``, ``shape``, ``codec`` and the base64 text."""

    def __init__(self, name: str, dtype: str, shape: tuple, codec: str, text: str, raw: int):
        self.name, self.dtype, self.shape, self.codec, self.text = name, dtype, shape, codec, text
        self.raw = raw  #: bytes before compression

    def attrs(self) -> str:
        shape = ",".join(str(int(s)) for s in self.shape)
        return (f'id="se3dyn-blob-{self.name}" data-dtype="{self.dtype}" '
                f'data-shape="{shape}" data-codec="{self.codec}"')


_JS_TYPES = {"uint16": "<u2", "int32": "<i4", "uint32": "<u4", "float32": "<f4", "uint8": "u1"}


def pack(name: str, arr: np.ndarray, *, delta: bool = False, level: int = 6) -> Blob:
    """Encode an array for the page.

    ``delta`` (uint16 only): differences along axis 0 (mod 2^16), then the low and the high
    bytes as two planes (``codec = "delta16+split"``). Always deflated (zlib) and base64-encoded.
    """
    a = np.ascontiguousarray(arr, dtype=np.dtype(_JS_TYPES[str(np.dtype(arr.dtype).name)]))
    codec = "deflate"
    data: bytes
    if delta:
        if a.dtype != np.dtype("<u2"):
            raise TypeError("delta coding is for uint16 arrays")
        d = a.copy()
        if len(d) > 1:
            d[1:] = a[1:] - a[:-1]  # wraps mod 2^16
        b = d.reshape(-1).view(np.uint8).reshape(-1, 2)
        data = np.ascontiguousarray(b.T).tobytes()
        codec = "delta16+split+deflate"
    else:
        data = a.tobytes()
    text = base64.b64encode(zlib.compress(data, level)).decode("ascii")
    return Blob(name, str(np.dtype(arr.dtype).name), a.shape, codec, text, len(data))


def unpack(blob: Blob) -> np.ndarray:
    """Inverse of :func:`pack` (reference for the page's decoder)."""
    data = zlib.decompress(base64.b64decode(blob.text))
    dt = np.dtype(_JS_TYPES[blob.dtype])
    if blob.codec.startswith("delta16"):
        b = np.frombuffer(data, dtype=np.uint8).reshape(2, -1).T
        d = np.ascontiguousarray(b).view("<u2").reshape(blob.shape)
        return np.cumsum(d, axis=0, dtype=np.uint16)  # wraps mod 2^16
    return np.frombuffer(data, dtype=dt).reshape(blob.shape).copy()
