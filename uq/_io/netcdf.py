"""NetCDF-4 files: groups of xarray Datasets with root attributes, the layout of ArviZ's
InferenceData (``arviz.from_netcdf`` reads what is written here), written atomically and read
back with one-line errors. Apart from ``uq._io.files`` so that what writes JSON does not load
xarray (and pandas under it)."""

from __future__ import annotations

import contextlib
import io
import os
import struct
import sys
from pathlib import Path

from uq._io.errors import InputError
from uq._io.files import write_bytes_atomic


def _compressible(dtype) -> bool:
    """Integers, booleans and byte strings are zlib-compressed; floating-point numbers and text
    are not: draws of floats barely compress, and compressing them took most of the time to
    write a fit's file (measured by benchmarks/bench.py --batch; docs/batch.md)."""
    return dtype.kind in {"b", "i", "u", "S"}


def _encoding(data) -> dict:
    return {
        name: {"zlib": True}
        for name, values in data.variables.items()
        if _compressible(values.dtype)
    }


def netcdf_bytes(groups: dict, attrs: dict | None = None) -> bytes:
    """Groups (name -> xarray Dataset) and root attributes as NetCDF-4 bytes, made in memory
    (the layout ArviZ's ``idata.to_netcdf(path)`` writes and ``arviz.from_netcdf`` reads: root
    attributes, every group; integers zlib-compressed, floats stored as they are).

    All groups go into the file in one pass (xarray's ``DataTree.to_netcdf``), written by the
    netCDF-C library (the ``netCDF4`` package) in its in-memory mode: h5netcdf, which wrote them
    before, spends tens of milliseconds a variable looking up the file's dimension scales through
    h5py, and a fit's file took 5 to 10 times as long (benchmarks/bench.py --batch measures both
    ways; docs/batch.md). With an xarray without ``DataTree`` (before 2024.10) the groups are
    appended one by one through h5netcdf.

    Why in memory: HDF5 writing straight to a full disk (or past a file-size limit) fails inside
    the library, which can crash the interpreter (a segmentation fault, exit 139, seen in h5py);
    the bytes are written afterwards like any other output, where a full disk is a one-line error."""
    # reason: xarray costs about half a second to import; only saving and loading a model need it
    import xarray as xr

    with _local_dask_scheduler():
        if hasattr(xr, "DataTree"):
            tree = {"/": xr.Dataset(attrs=attrs or {})} | {f"/{g}": d for g, d in groups.items()}
            encoding = {f"/{g}": _encoding(d) for g, d in groups.items()}
            # a path of None: the netCDF4 engine writes in memory and returns the bytes
            data = xr.DataTree.from_dict(tree).to_netcdf(None, engine="netcdf4", encoding=encoding)
            return _without_root_times(bytes(data))
        buf = io.BytesIO()
        mode = "w"
        if attrs:  # the file's own attributes, on the root group
            xr.Dataset(attrs=attrs).to_netcdf(buf, mode=mode, engine="h5netcdf", group="/")
            mode = "a"
        for group, data in groups.items():
            data.to_netcdf(
                buf, mode=mode, group=f"/{group}", engine="h5netcdf", encoding=_encoding(data)
            )
            mode = "a"
    return buf.getvalue()


def _without_root_times(data: bytes) -> bytes:
    """The same file with its root group's time stamps zeroed, so that the same groups give the
    same bytes. The netCDF-C library creates the root group with creation order tracked, which in
    HDF5 also stores the group's access, modification, change and birth times (to the second) in
    its version-2 object header; netCDF-C offers no switch for it (h5py, under h5netcdf, turned
    them off in 3.15). Every other object netCDF-C writes has no times (tested).

    The header is found where HDF5's file format puts it (superblock version 2 or 3: the root
    group's object header address at byte 36); its four times are set to 0 and its checksum (HDF5's
    Jenkins lookup3 over the header chunk) written anew, which HDF5 verifies on reading. A file
    laid out otherwise is returned as it is."""
    if data[:8] != b"\x89HDF\r\n\x1a\n" or data[8] not in (2, 3) or data[9:11] != b"\x08\x08":
        return data
    (root,) = struct.unpack_from("<Q", data, 36)
    if data[root : root + 5] != b"OHDR\x02" or not data[root + 5] & 0x20:
        return data
    flags = data[root + 5]
    at = root + 6 + 16 + (4 if flags & 0x10 else 0)  # times; phase-change values
    width = 1 << (flags & 0x03)
    chunk = int.from_bytes(data[at : at + width], "little")
    end = at + width + chunk  # the checksum follows the chunk
    out = bytearray(data)
    out[root + 6 : root + 22] = bytes(16)
    out[end : end + 4] = struct.pack("<I", _lookup3(bytes(out[root:end])))
    return bytes(out)


def _lookup3(key: bytes, initval: int = 0) -> int:
    """Bob Jenkins' lookup3 ``hashlittle``, the checksum of HDF5's metadata
    (``H5_checksum_lookup3``); the header it checks is a few hundred bytes."""
    m = 0xFFFFFFFF
    v = [(0xDEADBEEF + len(key) + initval) & m] * 3  # a, b, c
    if not key:
        return v[2]

    def step(x, y, k, z=None):  # x -= y; x ^= rot(y, k); y += z  (mix), or x ^= y; x -= rot(y, k)
        r = ((v[y] << k) | (v[y] >> (32 - k))) & m
        if z is None:
            v[x] = ((v[x] ^ v[y]) - r) & m
        else:
            v[x] = ((v[x] - v[y]) & m) ^ r
            v[y] = (v[y] + v[z]) & m

    padded = key + bytes(-len(key) % 12)  # the last 1..12 bytes go to the final mix
    for i in range(0, len(padded), 12):
        for j, word in enumerate(struct.unpack_from("<3I", padded, i)):
            v[j] = (v[j] + word) & m
        if i + 12 < len(padded):
            for x, y, z, k in ((0, 2, 1, 4), (1, 0, 2, 6), (2, 1, 0, 8), (0, 2, 1, 16),
                               (1, 0, 2, 19), (2, 1, 0, 4)):  # fmt: skip
                step(x, y, k, z)
    for x, y, k in (
        (2, 1, 14),
        (0, 2, 11),
        (1, 0, 25),
        (2, 1, 16),
        (0, 2, 4),
        (1, 0, 14),
        (2, 1, 24),
    ):
        step(x, y, k)
    return v[2]


@contextlib.contextmanager
def _local_dask_scheduler():
    """In a Dask worker (``uq batch``), xarray would take a cluster-wide lock named after the
    target, which a buffer in memory cannot name; the data here are in memory, so a local lock is right."""
    if "dask" not in sys.modules:
        yield
        return
    dask = sys.modules["dask"]
    with dask.config.set(scheduler="synchronous"):
        yield


def write_netcdf_atomic(path: str | os.PathLike, idata=None, *, groups=None, attrs=None) -> Path:
    """Write an ArviZ InferenceData (or ``groups`` and ``attrs``) to ``path`` as NetCDF, atomically
    (:func:`netcdf_bytes`, then :func:`uq._io.files.write_bytes_atomic`): a full disk is an
    :class:`InputError` and leaves no file."""
    if idata is not None:
        groups = {g: getattr(idata, g) for g in idata.groups()}
        attrs = dict(idata.attrs)
    return write_bytes_atomic(path, netcdf_bytes(groups, attrs))


def read_netcdf(path, groups: tuple[str, ...]) -> tuple[dict, dict]:
    """(root attributes, {group: Dataset loaded into memory}) of a NetCDF-4 file; a missing file,
    one that is not NetCDF-4, or one without ``groups`` is an InputError naming it."""
    path = str(path)
    if not Path(path).is_file():
        raise InputError(f"{path}: no such file")
    # reason: xarray costs about half a second to import; only reading a saved model needs it
    import xarray as xr

    try:
        with xr.open_dataset(path, engine="h5netcdf") as root:
            attrs = dict(root.attrs)
        out = {}
        for g in groups:
            with xr.open_dataset(path, group=g, engine="h5netcdf") as ds:
                out[g] = ds.load()
    except Exception as exc:  # h5py/h5netcdf raise OSError, ValueError, KeyError... on other files
        raise InputError(
            f"{path}: not a readable NetCDF file with groups {', '.join(groups)} "
            f"({type(exc).__name__}: {' '.join(str(exc).split())[:120]})"
        ) from None
    return attrs, out
