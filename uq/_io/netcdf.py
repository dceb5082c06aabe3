"""NetCDF-4 files: groups of xarray Datasets with root attributes, the layout of ArviZ's
InferenceData (``arviz.from_netcdf`` reads what is written here), written atomically and read
back with one-line errors. Apart from ``uq._io.files`` so that what writes JSON does not load
xarray (and pandas under it)."""

from __future__ import annotations

import contextlib
import io
import os
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
            return bytes(data)
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
