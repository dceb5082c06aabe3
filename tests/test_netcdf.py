"""uq._io.netcdf: the NetCDF-4 bytes of a fit's file, written by the netCDF-C library in memory,
read back exactly by h5netcdf (uq's reader) and by ArviZ, with zlib only where it pays."""

from __future__ import annotations

import numpy as np
import pytest

from uq._io.netcdf import netcdf_bytes, read_netcdf, write_netcdf_atomic

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


def test_same_bytes_for_the_same_groups():
    """Deterministic output: the file has no time stamps or other run-dependent bytes."""
    groups, attrs = _groups()
    assert netcdf_bytes(groups, attrs) == netcdf_bytes(groups, attrs)
