"""uq._io.netcdf: the NetCDF-4 bytes of a fit's file, written by the netCDF-C library in memory,
read back exactly by h5netcdf (uq's reader) and by ArviZ, with zlib only where it pays."""

from __future__ import annotations

import re
import struct
import time

import numpy as np
import pytest

from uq._io.netcdf import (
    _lookup3,
    _without_root_times,
    netcdf_bytes,
    read_netcdf,
    write_netcdf_atomic,
)

xr = pytest.importorskip("xarray")


def _groups() -> tuple[dict, dict]:
    rng = np.random.default_rng(3)
    posterior = xr.Dataset(
        {
            "a_P": (("chain", "draw"), rng.normal(size=(4, 50))),
            "sigma": (("chain", "draw", "k"), rng.gamma(2.0, size=(4, 50, 3))),
        },
        coords={"chain": np.arange(4), "draw": np.arange(50), "k": ["x", "y", "z"]},
        attrs={"model": "per-pressure cubics", "pressure_bar": 5.0},
    )
    stats = xr.Dataset(
        {"lp": (("chain", "draw"), rng.normal(size=(4, 50)))},
        coords={"chain": np.arange(4), "draw": np.arange(50)},
    )
    observed = xr.Dataset(
        {
            "force_N": ("reading", rng.normal(1e4, 50.0, size=37)),
            "order": ("reading", np.arange(37, dtype=np.int64)),
            "kept": ("reading", rng.random(37) > 0.2),
        }
    )
    return {"posterior": posterior, "sample_stats": stats, "observed_data": observed}, {
        "uq_version": "test",
        "seed": 7,
    }


def test_bytes_read_back_exactly_by_uq_and_arviz(tmp_path):
    import arviz as az

    groups, attrs = _groups()
    path = write_netcdf_atomic(tmp_path / "fit.nc", groups=groups, attrs=attrs)
    assert path.read_bytes()[:8] == b"\x89HDF\r\n\x1a\n"  # NetCDF-4 is an HDF5 file
    root, back = read_netcdf(path, tuple(groups))
    assert root == attrs
    for name, ds in groups.items():
        assert set(back[name].data_vars) == set(ds.data_vars)
        for var in ds.data_vars:
            np.testing.assert_array_equal(back[name][var].values, ds[var].values)
            assert back[name][var].dtype == ds[var].dtype
    assert back["posterior"].attrs == groups["posterior"].attrs
    assert list(back["posterior"]["k"].values) == ["x", "y", "z"]
    idata = az.from_netcdf(path)
    assert set(idata.groups()) == set(groups)
    np.testing.assert_array_equal(idata.posterior["a_P"], groups["posterior"]["a_P"])


def test_zlib_on_integers_and_booleans_not_on_floats(tmp_path):
    import h5netcdf

    groups, attrs = _groups()
    path = tmp_path / "fit.nc"
    path.write_bytes(netcdf_bytes(groups, attrs))
    with h5netcdf.File(path, "r") as f:
        obs = f["observed_data"]
        assert obs.variables["order"].compression == "gzip"
        assert obs.variables["kept"].compression == "gzip"
        assert obs.variables["force_N"].compression is None
        assert f["posterior"].variables["a_P"].compression is None


def test_same_bytes_for_the_same_groups_in_another_second():
    """Deterministic output: the file has no time stamps or other run-dependent bytes. HDF5 keeps
    times to the second, and netCDF-C stores them in the root group's header: the two files are
    written in different seconds, so this fails if the zeroing of those times is undone."""
    groups, attrs = _groups()
    first = netcdf_bytes(groups, attrs)
    time.sleep(1.0 - time.time() % 1.0 + 0.05)
    assert netcdf_bytes(groups, attrs) == first


def test_the_root_times_zeroed_under_a_valid_checksum(tmp_path):
    """What netCDF-C wrote, with the root group's four times zeroed and its header's checksum made
    anew: the same checksum function gives every object header's stored checksum, and HDF5 (which
    verifies them on reading) reads the file."""
    import h5py

    groups, attrs = _groups()
    tree = {"/": xr.Dataset(attrs=attrs)} | {f"/{g}": d for g, d in groups.items()}
    raw = bytes(xr.DataTree.from_dict(tree).to_netcdf(None, engine="netcdf4"))
    headers = [m.start() for m in re.finditer(b"OHDR", raw)]
    assert len(headers) > 10
    timed = [o for o in headers if raw[o + 5] & 0x20]
    (root,) = struct.unpack_from("<Q", raw, 36)
    assert timed == [root]  # only the root group has times
    for o in headers:
        flags = raw[o + 5]
        at = o + 6 + (16 if flags & 0x20 else 0) + (4 if flags & 0x10 else 0)
        width = 1 << (flags & 3)
        end = at + width + int.from_bytes(raw[at : at + width], "little")
        assert _lookup3(raw[o:end]) == struct.unpack_from("<I", raw, end)[0]
    fixed = _without_root_times(raw)
    assert raw[root + 6 : root + 22] != bytes(16)
    assert fixed[root + 6 : root + 22] == bytes(16)
    assert [i for i in range(len(raw)) if raw[i] != fixed[i]] != []
    path = tmp_path / "fixed.nc"
    path.write_bytes(fixed)
    with h5py.File(path, "r") as f:
        assert set(f) >= set(groups)
        np.testing.assert_array_equal(f["posterior"]["a_P"][()], groups["posterior"]["a_P"])
    assert _without_root_times(b"not an HDF5 file") == b"not an HDF5 file"
