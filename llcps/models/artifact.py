"""The safe artifact format of fitted world models: named numeric arrays in a zip of
``.npy`` files, written and read without pickle, so loading an artifact from a
database someone sent you reads numbers, never code."""

from __future__ import annotations

import io
import re
import zipfile
import zlib
from typing import Mapping

import numpy as np

from llcps.errors import LlcpsError

#: Largest total (uncompressed) array payload an artifact may declare: a guard
#: against a crafted archive that would exhaust memory when read.
MAX_ARTIFACT_BYTES = 1 << 30

_ARRAY_NAME = re.compile(r"^[A-Za-z0-9_./-]{1,128}$")
_FIXED_ZIP_TIME = (1980, 1, 1, 0, 0, 0)


def pack_arrays(arrays: Mapping[str, np.ndarray]) -> bytes:
    """Write named arrays as a deflated zip of ``.npy`` files (no pickle anywhere).

    Entries carry a fixed timestamp so the same arrays always give the same bytes.
    """
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for key in sorted(arrays):
            if not _ARRAY_NAME.match(key):
                raise ValueError(f"bad array name {key!r}")
            value = np.asarray(arrays[key])
            if value.dtype.hasobject:
                raise ValueError(f"array {key!r} holds Python objects; artifacts hold numbers only")
            info = zipfile.ZipInfo(f"{key}.npy", date_time=_FIXED_ZIP_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            with archive.open(info, "w") as member:
                np.lib.format.write_array(member, value, allow_pickle=False)
    return buffer.getvalue()


def unpack_arrays(data: bytes) -> dict[str, np.ndarray]:
    """Read arrays written by :func:`pack_arrays`, refusing anything but plain arrays.

    Raises:
        LlcpsError: not a zip of ``.npy`` files, an oversized payload, or object arrays
            (which would need pickle: ``allow_pickle=False`` refuses them).
    """
    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
    except zipfile.BadZipFile:
        raise LlcpsError("not an array archive (expected a zip of .npy files)") from None
    arrays: dict[str, np.ndarray] = {}
    with archive:
        infos = archive.infolist()
        if sum(info.file_size for info in infos) > MAX_ARTIFACT_BYTES:
            raise LlcpsError("array archive declares more than 1 GiB of data")
        for info in infos:
            key = info.filename[: -len(".npy")]
            if not info.filename.endswith(".npy") or not _ARRAY_NAME.match(key):
                raise LlcpsError(f"unexpected member {info.filename!r} in array archive")
            try:
                with archive.open(info) as member:
                    arrays[key] = np.lib.format.read_array(member, allow_pickle=False)
            except ValueError as exc:
                raise LlcpsError(f"array {key!r} cannot be read safely: {exc}") from None
            except (zipfile.BadZipFile, zlib.error, EOFError, OSError) as exc:  # a damaged member (CRC, deflate stream)
                raise LlcpsError(f"array {key!r} is damaged: {exc}") from None
    return arrays


def array(arrays: Mapping[str, np.ndarray], key: str, shape: tuple[int | None, ...], kind: str = "f") -> np.ndarray:
    """Fetch one artifact array and check its shape and dtype kind (None = any length).

    Raises:
        LlcpsError: missing, wrong shape or dtype, or (for floats) non-finite values.
    """
    if key not in arrays:
        raise LlcpsError(f"array {key!r} is missing")
    value = arrays[key]
    if value.ndim != len(shape) or any(want is not None and got != want for got, want in zip(value.shape, shape)):
        raise LlcpsError(f"array {key!r} has shape {value.shape}, expected {shape}")
    if value.dtype.kind not in kind:
        raise LlcpsError(f"array {key!r} has dtype {value.dtype}, expected kind {kind!r}")
    if value.dtype.kind == "f" and not np.all(np.isfinite(value)):
        raise LlcpsError(f"array {key!r} holds non-finite values")
    return value
