"""The one saved format of every fitted model: NetCDF-4 in ArviZ's InferenceData layout.

A fitted model's ``save(path, **provenance)`` writes (``az.from_netcdf`` reads it; docs/formats.md,
section 6, has the tables):

* root attributes: ``uq_file_kind`` (``FILE_KIND``), ``uq_format_version`` (``FORMAT_VERSION``),
  ``model`` (the registry name, which says what loads the file), ``label``, and the provenance:
  ``recordings_path``, ``recordings_sha256``, ``x0_mm``, ``piston_area_cm2``, ``seed``,
  ``uq_version``, ``written_by``, ``settings_json``, ``stand_json``, ``converged``,
  ``warnings_json`` (the sampler's verdict and warnings), ``max_draws`` (the fixed draws' bound,
  -1 for none), ``recordings_comments_json`` (the recordings' header lines, e.g. that they are
  reconstructed; exports repeat them) and whatever else the writer adds (``model_info_json``: why
  ``uq margin`` chose it; ``model_check_json``: its posterior-predictive check at the tested points
  when it was fitted);
* group ``posterior``: every named coefficient block as a variable (chain, draw, coefficient) in
  physical units, and the sampled parameters as reported (chain, draw);
* group ``constant_data``: the model's orders and geometry (``orders``/``orders_field``,
  ``geometry``/``geometry_field``), the tested pressures and ranges, and ``json_document``: the
  model's JSON document when it was saved.

:func:`read` refuses anything else with one line: a file that is not NetCDF, not a saved model, or
of another format version (version 1, the saved answers of uq 0.1 round 6, says how to re-save).
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np

from uq._io.errors import InputError
from uq._io.files import dumps_json, sha256_of
from uq._io.netcdf import read_netcdf, write_netcdf_atomic
from uq._io.version import __version__
from uq._models import registry

FILE_KIND = "uq fitted model"
FORMAT_VERSION = 2
#: what uq wrote before (``uq margin --save-fit``, ``uq surface --out`` up to round 6)
OLD_KIND = "uq margin answer"
GROUPS = ("posterior", "constant_data")


def provenance_of(recordings, *, seed: int | None, settings=None, stand=None) -> dict:
    """What a fit records of where it came from (the model's ``provenance``)."""
    out = {"seed": seed, "uq_version": __version__}
    if recordings is not None:
        out |= {
            "recordings_path": str(Path(recordings.path).resolve()),
            "x0_mm": recordings.x0_m * 1e3,
            "piston_area_cm2": recordings.piston_area_m2 * 1e4,
        }
        if getattr(recordings, "sha256", None):  # the hash taken when read (no second read)
            out["recordings_sha256"] = recordings.sha256
        # the file's own header lines (e.g. "RECONSTRUCTED recordings ..."), which every export of
        # the saved model repeats
        out["recordings_comments"] = list(getattr(recordings, "comments", ()) or ())
    if settings is not None:
        out["settings"] = asdict(settings)
    if stand is not None:
        out["stand"] = asdict(stand)
    return out


def _attrs(model, provenance: dict) -> dict:
    prov = dict(model.provenance) | provenance
    path = prov.get("recordings_path")
    sha = prov.get("recordings_sha256") or (
        sha256_of(path) if path and Path(path).is_file() else ""
    )
    conv = model.convergence
    attrs = {
        "uq_file_kind": FILE_KIND,
        "uq_format_version": FORMAT_VERSION,
        "model": model.name,
        "label": model.label,
        "recordings_path": str(path or ""),
        "recordings_sha256": sha,
        "x0_mm": float(prov.get("x0_mm", model.x0_m * 1e3)),
        "piston_area_cm2": float(prov.get("piston_area_cm2", np.nan)),
        "seed": -1 if prov.get("seed") is None else int(prov["seed"]),
        "uq_version": __version__,
        "written_by": str(prov.get("written_by", "save")),
        "settings_json": json.dumps(prov.get("settings")),
        "stand_json": json.dumps(prov.get("stand")),
        "converged": int(bool(prov.get("converged", conv is None or conv.converged))),
        "warnings_json": json.dumps(list(prov.get("warnings", conv.messages() if conv else []))),
        "max_draws": -1 if model.max_draws is None else int(model.max_draws),
        "recordings_comments_json": json.dumps(list(prov.get("recordings_comments", []))),
    }
    if prov.get("model_info") is not None:
        attrs["model_info_json"] = dumps_json(prov["model_info"])
    if prov.get("model_check") is not None:  # uq margin --save-fit: the check at the tested points
        attrs["model_check_json"] = dumps_json(prov["model_check"])
    return attrs


def write(path, model, variables: dict, params: dict, document: dict, **provenance) -> Path:
    """Write ``model`` atomically: ``variables`` {name: (dims, values, attrs, coefficient names or
    None)} into ``posterior``, ``params`` {"orders": (field names, values), ...} and the tested
    ranges into ``constant_data``, provenance (the model's, updated by ``provenance``: ``seed``,
    ``written_by``, ``settings``, ``stand``, ``converged``, ``warnings``, ``model_info``) as root
    attributes."""
    # reason: xarray costs about half a second to import; only saving and loading a model need it
    import xarray as xr

    data, coords = {}, {}
    for name, (dims, values, attrs, names) in variables.items():
        values = np.asarray(values)
        data[name] = xr.Variable(dims, values, attrs)
        for dim, n in zip(dims, values.shape, strict=True):
            coords.setdefault(dim, list(names) if dim == dims[-1] and names else np.arange(n))
    const = {
        "tested_pressure_bar": ("test", np.asarray(model.tested_pressures_bar, float)),
        "tested_height_range_m": ("bound", list(model.height_range_m)),
        "tested_pressure_range_bar": ("bound", list(model.pressure_range_bar)),
        "json_document": ((), dumps_json(document)),
    }
    const_coords = {"bound": ["min", "max"]}
    for what, (names, values) in params.items():
        const[what] = (f"{what}_field", np.asarray(values))
        const_coords[f"{what}_field"] = list(names)
    groups = {
        "posterior": xr.Dataset(data, coords=coords),
        "constant_data": xr.Dataset(const, coords=const_coords),
    }
    return write_netcdf_atomic(path, groups=groups, attrs=_attrs(model, provenance))


def read(path) -> tuple[dict, dict]:
    """(root attributes, {"posterior", "constant_data"}) of a saved model; one line otherwise."""
    path = str(path)
    attrs, _ = read_netcdf(path, ())
    kind, version = attrs.get("uq_file_kind"), int(attrs.get("uq_format_version", -1))
    if kind == OLD_KIND:
        raise InputError(
            f"{path}: a saved answer of format version {version} (uq {attrs.get('uq_version', '?')}); "
            f"this uq reads saved models of version {FORMAT_VERSION} only: fit "
            f"{attrs.get('recordings_path', 'the recordings')} again and save it (uq margin with "
            "its save-fit option, or uq surface with its out option)"
        )
    if kind != FILE_KIND:
        raise InputError(
            f"{path}: not a saved model (no uq_file_kind = '{FILE_KIND}'); write one with uq "
            "surface or uq margin, or a fitted model's save()"
        )
    if version != FORMAT_VERSION:
        raise InputError(
            f"{path}: saved-model format version {version}; this uq reads version {FORMAT_VERSION}"
        )
    return read_netcdf(path, GROUPS)


def load(path):
    """The fitted model a file of ``save`` holds, by the class its registry entry names (no refit,
    no JAX); a file that is not a saved model, or is damaged, is one line naming it."""
    attrs, groups = read(path)
    name = str(attrs.get("model", ""))
    if name not in registry.names():
        raise InputError(
            f"{path}: holds the model '{name}', which no registered model is (a model plugged in "
            f"from outside: install or register it); the registered ones are "
            f"{', '.join(registry.names())}"
        )
    kind = registry.entry(name).model_class()
    try:
        return kind.from_saved(attrs, groups)
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from None
    except Exception as exc:  # a damaged or hand-edited file: say so in one line
        raise InputError(
            f"{path}: damaged saved model ({type(exc).__name__}: {' '.join(str(exc).split())[:120]})"
        ) from None


def require_blocks(posterior, names) -> None:
    """Refuse, in one line naming them, a saved model whose ``posterior`` lacks any of the blocks
    ``names`` its layout needs (a file of an older uq, or an incomplete one)."""
    missing = [n for n in names if n not in posterior.data_vars]
    if missing:
        raise InputError(
            f"incomplete saved model: no block {', '.join(missing)} (saved by an older uq, or "
            "cut short); fit and save it again"
        )


def provenance_from(attrs: dict) -> dict:
    """A loaded model's ``provenance`` from the root attributes."""
    out = {
        k: attrs[k]
        for k in ("recordings_path", "recordings_sha256", "uq_version", "written_by", "label")
        if k in attrs
    }
    out["seed"] = int(attrs["seed"]) if int(attrs.get("seed", -1)) >= 0 else None
    out["x0_mm"], out["piston_area_cm2"] = float(attrs["x0_mm"]), float(attrs["piston_area_cm2"])
    out["settings"] = json.loads(attrs.get("settings_json", "null"))
    out["stand"] = json.loads(attrs.get("stand_json", "null"))
    out["converged"] = bool(int(attrs.get("converged", 1)))
    out["warnings"] = json.loads(attrs.get("warnings_json", "[]"))
    out["recordings_comments"] = json.loads(attrs.get("recordings_comments_json", "[]"))
    if "model_info_json" in attrs:
        out["model_info"] = json.loads(attrs["model_info_json"])
    if "model_check_json" in attrs:
        out["model_check"] = json.loads(attrs["model_check_json"])
    return out


def max_draws_of(attrs: dict) -> int | None:
    m = int(attrs.get("max_draws", -1))
    return None if m < 0 else m
