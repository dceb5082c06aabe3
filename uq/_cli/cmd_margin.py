"""``uq margin``: the command line of :mod:`uq._derived.margin` (options, query files, fitting or loading
the answering model, printing)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from uq._cli.common import add_misfit, add_stand, record_convergence, record_misfit, stand_from
from uq._derived.margin import AUTO, load_answer, margin, model_choices
from uq._io.errors import InputError, refuse_outside
from uq._io.files import sha256_of
from uq._models import registry


def configure_margin(p) -> None:
    from uq._cli.common import add_json, add_recordings, add_sampling, positive_float, probability

    add_recordings(p, file_optional=True)
    add_sampling(p)
    add_json(p)
    p.add_argument("--height-mm", type=positive_float, help="height x of the element, mm")
    p.add_argument("--load-N", type=positive_float, help="load the element has to carry, N")
    p.add_argument(
        "--prob",
        type=probability,
        default=0.95,
        help="probability of carrying at least the load (default 0.95)",
    )
    p.add_argument(
        "--pressure-bar", type=positive_float, help="also give the force band at this overpressure"
    )
    p.add_argument(
        "--tolerance-pct",
        type=positive_float,
        help="with --pressure-bar: usable stroke where the force stays within this %% of the load",
    )
    p.add_argument(
        "--model",
        choices=model_choices(),
        default=None,
        help=f"which model answers: {AUTO} (default) fits the {registry.default('margin')} model "
        "and the per-pressure cubics and takes the one PSIS-LOO prefers by more than 2 SE (the "
        f"{registry.default('margin')} model when indistinguishable); a model's name skips the "
        f"comparison ({registry.help_words()})",
    )
    p.add_argument(
        "--save-fit",
        metavar="FIT.nc",
        help="after fitting, save the answering model's posterior draws to FIT.nc (NetCDF) for --fit",
    )
    p.add_argument(
        "--fit",
        metavar="FIT.nc",
        help="answer from a saved fit (uq margin --save-fit, uq surface --out) instead of FILE.csv: no refit",
    )
    p.add_argument(
        "--queries",
        metavar="Q.csv",
        help="many queries: a CSV with columns height_mm, load_N and optional prob, pressure_bar, "
        "tolerance_pct (empty cells take the options' values); the JSON is a list, one result a row",
    )
    add_stand(p)
    add_misfit(p)
    _configure_design_margins(p)


def _configure_design_margins(p) -> None:
    """Design margins on the sealed spring (uq._derived.design.design_margin): the element carries
    --load-N at --height-mm, charged and closed there."""
    from uq._cli.cmd_design import add_sealed_options
    from uq._cli.common import positive_float

    g = p.add_argument_group(
        "design margins on the sealed spring (docs/design.md): charged at --height-mm to carry "
        "--load-N there, then closed"
    )
    g.add_argument(
        "--max-frequency-hz",
        type=positive_float,
        help="is the natural frequency below this, with probability --prob?",
    )
    g.add_argument(
        "--rate-target-N-per-m",
        type=positive_float,
        help="is the sealed vertical rate within --rate-tolerance-pct of this, with probability --prob?",
    )
    g.add_argument(
        "--rate-tolerance-pct",
        type=positive_float,
        default=10.0,
        help="tolerance of --rate-target-N-per-m, %% (default 10)",
    )
    g.add_argument(
        "--force-limit-N",
        type=positive_float,
        help="stroke from the design height along the sealed curve until the force reaches this "
        "(compression if above the load, rebound if below), and the stroke held with probability --prob",
    )
    add_sealed_options(
        g,
        "internal volume at --height-mm carrying --load-N, litres, measured (e.g. by filling with "
        "water); required by the design margins",
        "its standard deviation, litres",
        "extra reservoir volume, litres",
    )


DESIGN_OPTIONS = ("max_frequency_hz", "rate_target_N_per_m", "force_limit_N")


def _design_asked(args) -> bool:
    return any(getattr(args, o, None) is not None for o in DESIGN_OPTIONS)


def _check_design_usage(args) -> None:
    """The design margins' options, checked before anything is read or fitted."""
    if not _design_asked(args):
        return
    if args.volume_l is None:
        raise InputError(
            "option --volume-l: the design margins need the element's internal volume at --height-mm "
            "carrying --load-N (litres; measure it, e.g. by filling the element with water: the stand gives "
            "only volume changes)"
        )
    if args.volume_sd_l > args.volume_l / 4:
        raise InputError(
            f"option --volume-sd-l: {args.volume_sd_l:g} L is more than a quarter of the volume "
            f"{args.volume_l:g} L: measure V more closely"
        )
    if args.dvdp_l_per_bar == "model":
        raise InputError(
            "option --dvdp-l-per-bar: 'model' is not offered for design margins (the charge moves "
            "with each draw's required pressure); give a number of litres per bar"
        )


def _check_design_volume(args, rec) -> None:
    """Design margins on a campaign without piston readings, refused before fitting: the sealed
    spring needs dV/dx over the pressures its charge moves through."""
    if not _design_asked(args) or rec.has_piston:
        return
    asked = next(o for o in DESIGN_OPTIONS if getattr(args, o, None) is not None)
    raise InputError(
        f"option {_option(asked)}: {rec.path} has no piston readings (force-only campaign or catalogue "
        "table), so the sealed rate, frequency and stroke cannot be given: they need dV/dx over the "
        "pressures the sealed spring moves through (omit the design options: the pressure needed and "
        "the force band are answered)"
    )


def _design_answer(args, ans, q: dict) -> dict:
    """One query's design margins (uq._derived.design.design_margin)."""
    from uq._cli.cmd_design import sealed_design
    from uq._derived.design import design_margin

    # the charge 1.0 bar is replaced: each draw is charged to the pressure that carries the load
    design = sealed_design(args, q["height_mm"] * 1e-3, 1.0)
    return design_margin(
        ans,
        q["height_mm"] * 1e-3,
        q["load_N"],
        design,
        q["prob"],
        max_frequency_Hz=args.max_frequency_hz,
        rate_target_N_per_m=args.rate_target_N_per_m,
        rate_tolerance_pct=args.rate_tolerance_pct,
        force_limit_N=args.force_limit_N,
    )


QUERY_COLUMNS = ("height_mm", "load_N", "prob", "pressure_bar", "tolerance_pct")


def _option(column: str) -> str:
    """The option of a query column (``height_mm`` -> ``--height-mm``)."""
    return "--" + column.replace("_", "-")


def _place(q: dict, column: str) -> str:
    """Where a query's value came from: ``option --x`` on the command line, or ``Q.csv, row N, column 'c'``."""
    from uq._io.errors import where

    return f"option {_option(column)}" if q["row"] is None else where(q["file"], q["row"], column)


def _check_query(q: dict) -> None:
    """Values every query must have, checked before anything is read or fitted."""
    for col in ("height_mm", "load_N", "pressure_bar", "tolerance_pct"):
        v = q[col]
        if v is not None and not (np.isfinite(v) and v > 0):
            raise InputError(f"{_place(q, col)}: expected a positive number, got {v:g}")
    if not (np.isfinite(q["prob"]) and 0.0 < q["prob"] < 1.0):
        raise InputError(
            f"{_place(q, 'prob')}: expected a probability strictly between 0 and 1, got {q['prob']:g}"
        )
    if q["tolerance_pct"] is not None and q["pressure_bar"] is None:
        raise InputError(
            f"{_place(q, 'tolerance_pct')}: needs --pressure-bar (the stroke is taken at one pressure)"
            if q["row"] is None
            else f"{_place(q, 'tolerance_pct')}: needs a pressure_bar on the row (the stroke is taken at one pressure)"
        )


def read_queries(path: str, defaults: dict) -> list[dict]:
    """The rows of a queries CSV (header height_mm, load_N [, prob, pressure_bar, tolerance_pct]).

    Empty optional cells take ``defaults`` (the command-line options). Every defect is an
    InputError naming the file, the row (as an editor counts lines) and the column."""
    import csv

    from uq._io.errors import where

    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            lines = fh.read().splitlines()
    except UnicodeDecodeError:
        raise InputError(
            f"{path}: not a UTF-8 text file (option --queries names a CSV file)"
        ) from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read: {exc.strerror or exc} (option --queries)") from None
    rows = [
        (i + 1, cells)
        for i, cells in enumerate(csv.reader(lines))
        if cells and any(c.strip() for c in cells) and not cells[0].lstrip().startswith("#")
    ]
    if not rows:
        raise InputError(
            f"{path}: no header row (expected columns height_mm, load_N and optionally prob, pressure_bar, tolerance_pct)"
        )
    head_row, header = rows[0]
    header = [h.strip() for h in header]
    for j, h in enumerate(header):
        if h not in QUERY_COLUMNS:
            raise InputError(
                f"{where(path, head_row, h or f'#{j + 1}')}: unknown column; expected height_mm, load_N "
                "and optionally prob, pressure_bar, tolerance_pct"
            )
        if header.count(h) > 1:
            raise InputError(f"{where(path, head_row, h)}: duplicated column")
    for need in ("height_mm", "load_N"):
        if need not in header:
            raise InputError(
                f"{path}: missing column '{need}' (expected height_mm, load_N and optionally prob, "
                "pressure_bar, tolerance_pct)"
            )
    if len(rows) == 1:
        raise InputError(f"{path}: no queries below the header row")
    out = []
    for row, cells in rows[1:]:
        if len(cells) != len(header):
            raise InputError(f"{where(path, row)}: {len(cells)} cells for {len(header)} columns")
        q = {"file": path, "row": row} | {c: defaults[c] for c in QUERY_COLUMNS}
        for col, text in zip(header, cells, strict=True):
            text = text.strip()
            if not text:
                if col in ("height_mm", "load_N"):
                    raise InputError(
                        f"{where(path, row, col)}: empty; every query needs a height and a load"
                    )
                continue
            try:
                q[col] = float(text)
            except ValueError:
                raise InputError(
                    f"{where(path, row, col)}: expected a number, got '{text}'"
                ) from None
        _check_query(q)
        out.append(q)
    return out


def _queries_from(args) -> list[dict]:
    """The queries of the command line (one, or the rows of --queries); checked before any work."""
    given = {c: getattr(args, c) for c in QUERY_COLUMNS}
    if args.queries:
        for c in ("height_mm", "load_N"):
            if given[c] is not None:
                raise InputError(
                    f"option {_option(c)}: not with --queries (the queries file gives each row's {c})"
                )
        return read_queries(args.queries, given)
    if (
        given["height_mm"] is None
        and given["load_N"] is None
        and args.save_fit
        and args.json is None
    ):
        return []  # only fit and save
    for c in ("height_mm", "load_N"):
        if given[c] is None:
            raise InputError(
                f"option {_option(c)}: required (or give the queries in a CSV with --queries)"
            )
    q = {"file": None, "row": None} | given
    _check_query(q)
    return [q]


def _check_ranges(q: dict, height_range_m, pressure_range_bar) -> None:
    """Heights and pressures outside the tested ranges, refused before any fitting or answering (no extrapolation)."""
    refuse_outside(_place(q, "height_mm"), q["height_mm"] * 1e-3, *height_range_m, "heights")
    plo, phi = pressure_range_bar
    if q["pressure_bar"] is not None and not plo - 1e-9 <= q["pressure_bar"] <= phi + 1e-9:
        raise InputError(
            f"{_place(q, 'pressure_bar')}: overpressure {q['pressure_bar']:g} bar is outside the tested pressures "
            f"{plo:g}..{phi:g} bar; the model does not extrapolate"
        )


def answer_query(ans, info: dict, q: dict) -> dict:
    """One query's margin result; a refusal of a --queries row names the file, row and column."""
    try:
        return margin(
            ans,
            q["height_mm"] * 1e-3,
            q["load_N"],
            q["prob"],
            pressure_bar=q["pressure_bar"],
            tolerance_pct=q["tolerance_pct"],
            model_info=info,
        )
    except InputError as exc:
        column = {"height_m": "height_mm"}.get(exc.param, exc.param)
        if column not in QUERY_COLUMNS:
            raise
        rest = str(exc)[len(exc.param) + 1 :] if str(exc).startswith(f"{exc.param}:") else f" {exc}"
        raise InputError(f"{_place(q, column)}:{rest}") from None


def _answer_or_refusal(ans, info: dict, q: dict, per_row: bool) -> dict:
    """:func:`answer_query`; for a row of a queries file a refusal is that row's answer
    (``{"row", "height_m", "load_N", "refused"}``) instead of the end of the command."""
    try:
        return answer_query(ans, info, q)
    except InputError as exc:
        if not per_row:
            raise
        return {
            "row": q["row"],
            "height_m": q["height_mm"] * 1e-3,
            "load_N": q["load_N"],
            "refused": str(exc),
        }


def _check_usage(args) -> None:
    """Which sources and outputs go together; before anything is read."""
    from uq._cli.common import check_output_path

    if (args.file is None) == (args.fit is None):
        raise InputError(
            "give exactly one of FILE.csv (fit the recordings) and --fit FIT.nc (answer from a saved fit)"
            if args.file is None
            else "option --fit: not with FILE.csv; give either the recordings (to fit) or a saved fit"
        )
    if args.save_fit is not None:
        if args.fit is not None:
            raise InputError(
                "option --save-fit: not with --fit (the saved fit is already saved); give FILE.csv to fit and save"
            )
        if args.save_fit == "-":
            raise InputError(
                "option --save-fit: needs a file name (NetCDF is not written to stdout)"
            )
        check_output_path(args.save_fit, "--save-fit")
    if args.queries is not None and args.json is not None and args.json != "-":
        if Path(args.queries).resolve() == Path(args.json).resolve():
            raise InputError(
                f"option --json {args.json}: is the queries file; refusing to overwrite it"
            )


def command_margin(args) -> int:
    from uq._cli.cmd_design import print_check
    from uq._cli.common import load
    from uq._derived.model_check import predictive_check, unavailable
    from uq._io.files import emit_json

    _check_usage(args)
    _check_design_usage(args)
    queries = _queries_from(args)  # checked before the fit, not after
    if args.fit is not None:
        ans, info, meta = load_answer(args.fit)
        if args.model not in (None, AUTO) and ans.name != args.model:
            raise InputError(
                f"option --model {args.model}: {args.fit} holds the {ans.label}; "
                f"fit again with FILE.csv --model {args.model} --save-fit"
            )
        for q in queries:
            _check_ranges(q, ans.height_range_m, ans.pressure_range_bar)
        diagnostics = {"warnings": meta["warnings"], "converged": meta["converged"]}
        source, rec = args.fit, None
        # the check made when the fit was saved (uq margin --save-fit), else none: no readings
        check = meta.get("model_check") or unavailable(
            ans, "a saved fit keeps no readings' replicates: fit the recordings to check it"
        )
    else:
        from uq._cli.common import settings_from
        from uq._derived import comparison_worker

        args.model = args.model or AUTO
        stand = stand_from(args)  # a bad --stand file is refused before the recordings are read
        fitted = (
            (registry.default("margin"), registry.CUBICS) if args.model == AUTO else (args.model,)
        )
        settings = settings_from(args)
        settings.require_walkers(max(registry.entry(m).n_sampled for m in fitted))
        rec = load(args)
        kw = {"seed": args.seed, "settings": settings, "stand": stand}
        # the cubics fitted beside the model, and compared, in a worker that starts before this
        # process imports JAX (uq._derived.comparison_worker)
        with comparison_worker.running(rec, args.model == AUTO, **kw) as worker:
            from uq._derived.comparison import fit_and_choose

            _check_design_volume(args, rec)
            tested = [t.pressure_bar for t in rec.tests]
            for q in queries:
                _check_ranges(q, rec.height_range_m, (min(tested), max(tested)))
            ans, info, diagnostics = fit_and_choose(
                rec, model=args.model, jobs=None, worker=worker, **kw
            )
        source = rec.path
        check = predictive_check(ans, seed=args.seed)  # the answering model at the tested points
    # every answer before anything is written; with a queries file each row gets its own answer
    # or its own refusal (a row the model cannot answer does not abort the others)
    results = [_answer_or_refusal(ans, info, q, bool(args.queries)) for q in queries]
    for q, r in zip(queries, results, strict=True):
        if "refused" not in r:  # a refused row keeps its four keys (docs/formats.md)
            if _design_asked(args):
                r["design"] = _design_answer(args, ans, q)
            r["model_check"] = check
    if args.fit is not None:
        print(
            f"{source}: saved fit of {meta['recordings_path']} (sha256 {meta['recordings_sha256'][:12]}..., "
            f"seed {meta['seed']}, uq {meta['uq_version']}); no refit"
        )
        p = Path(meta["recordings_path"])
        if p.is_file() and sha256_of(p) != meta["recordings_sha256"]:
            print(
                f"  warning: {p} has changed since the fit was saved (sha256 differs); the answer is for the recordings "
                "as they were then"
            )
    if args.save_fit is not None:
        ans.save(
            args.save_fit,
            written_by="uq margin --save-fit",
            model_info=info,
            converged=diagnostics["converged"],
            warnings=diagnostics["warnings"],
            model_check=check,
        )
        print(
            f"{source}: saved the {ans.label} to {args.save_fit} (answer later with uq margin --fit {args.save_fit})"
        )
    if args.queries:
        _print_table(source, ans, info, queries, results)
    elif queries:
        _print_one(source, ans, info, queries[0], results[0])
    print_check(check, named=False)
    for q, r in zip(queries, results, strict=True):
        if "design" in r:
            _print_design(q, r["design"], len(queries) > 1)
    for note in diagnostics.get("notes", ()):
        print(f"  {note}")
    for w in diagnostics["warnings"]:
        print(f"  warning{' (from the saved fit)' if args.fit is not None else ''}: {w}")
    refused = [q["row"] for q, r in zip(queries, results, strict=True) if "refused" in r]
    if refused:
        print(
            f"uq margin: {len(refused)} of {len(queries)} queries refused (rows "
            f"{', '.join(map(str, refused))}); the others are answered",
            file=sys.stderr,
        )
    if queries or args.json is not None:
        emit_json(results if args.queries else results[0], args.json)
    record_convergence(args, diagnostics["converged"], "the fit the answers come from")
    record_misfit(args, check)
    return 0


def _not_rising(res) -> str:
    """The one phrasing of a result's ``not_rising_share`` (``uq._derived.margin.pressure_needed``)."""
    return (
        f"in {100 * res['not_rising_share']:.1f} % of the draws the force crosses the load more "
        "than once in pressure: their lowest crossing is taken (the interval widens downwards)"
    )


def _print_one(source, ans, info, q, res) -> None:
    e = res["pressure_bar_needed"]
    print(f"{source}: {q['load_N']:g} N at {q['height_mm']:g} mm, answered by the {ans.label}")
    print(f"  why: {info['why']}")
    if info.get("omitted"):
        print(f"  {info['omitted']}")
    c = info.get("comparison")
    if c:
        m, cub = c[c["model"]], c[registry.CUBICS]
        print(
            f"  PSIS-LOO: {c['model']} {m['elpd_loo']:.1f} (max Pareto k {m['max_pareto_k']:.2f}), "
            f"cubics {cub['elpd_loo']:.1f} (max Pareto k {cub['max_pareto_k']:.2f}), "
            f"difference {c['elpd_diff']:.1f} +- {c['elpd_diff_se']:.1f}"
        )
    print(
        f"  pressure needed: {e['mean']:.3f} bar (sd {e['sd']:.3f}; 90 % interval {e['q05']:.3f}..{e['q95']:.3f})"
    )
    print(
        f"  carries at least the load with probability {q['prob']:g} from {res['pressure_bar_for_prob']:.3f} bar"
    )
    if res.get("not_rising_share"):
        print(f"  {_not_rising(res)}")
    if "force_at_pressure" in res:
        f = res["force_at_pressure"]["force_N"]
        print(
            f"  force at {q['pressure_bar']:g} bar: {f['mean']:.0f} N (90 % {f['q05']:.0f}..{f['q95']:.0f}), "
            f"P(force >= load) = {res['force_at_pressure']['prob_carries_load']:.3f}"
        )
    if "usable_stroke" in res:
        s = res["usable_stroke"]
        c = s["stroke_credible"]
        if c:
            print(
                f"  usable stroke (within {q['tolerance_pct']:g} % with prob >= {q['prob']:g} at each height): "
                f"{c['from_m'] * 1e3:.1f}..{c['to_m'] * 1e3:.1f} mm, whole range within with prob {c['prob_whole_range_within']:.3f}"
            )
        else:
            print(
                f"  usable stroke: none; force within {q['tolerance_pct']:g} % at {q['height_mm']:g} mm with prob "
                f"{s['prob_within_at_height']:.3f} < {q['prob']:g}"
            )


def _print_table(source, ans, info, queries, results) -> None:
    print(
        f"{source}: {len(queries)} queries from {queries[0]['file']}, answered by the {ans.label}"
    )
    print(f"  why: {info['why']}")
    if info.get("omitted"):
        print(f"  {info['omitted']}")
    print(
        "   row  height_mm    load_N  prob  p_needed_bar (90 %)        p_for_prob  force at p_bar (90 %)      stroke_mm"
    )
    for q, r in zip(queries, results, strict=True):
        if "refused" in r:
            print(
                f"  {q['row']:>4}  {q['height_mm']:9g}  {q['load_N']:8g}  refused: {r['refused']}"
            )
            continue
        e = r["pressure_bar_needed"]
        force = stroke = ""
        if "force_at_pressure" in r:
            f = r["force_at_pressure"]["force_N"]
            force = f"{f['mean']:.0f} ({f['q05']:.0f}..{f['q95']:.0f}) at {q['pressure_bar']:g}"
        if "usable_stroke" in r:
            c = r["usable_stroke"]["stroke_credible"]
            stroke = f"{c['from_m'] * 1e3:.1f}..{c['to_m'] * 1e3:.1f}" if c else "none"
        print(
            f"  {q['row']:>4}  {q['height_mm']:9g}  {q['load_N']:8g}  {q['prob']:4g}  "
            f"{e['mean']:6.3f} ({e['q05']:.3f}..{e['q95']:.3f})  {r['pressure_bar_for_prob']:10.3f}  {force:<25}  {stroke}".rstrip()
            + (f"  [{_not_rising(r)}]" if r.get("not_rising_share") else "")
        )


def _print_design(q: dict, d: dict, several: bool) -> None:
    from uq._cli.cmd_design import est

    head = f"  row {q['row']}: " if several else "  "
    print(
        f"{head}sealed at {q['height_mm']:g} mm carrying {q['load_N']:g} N (charge {est(d['charge_bar'], 1, '.3f')} bar, "
        f"{d['volume_l']:g} L): rate {est(d['rate_N_per_m'], 1e-3, '.1f')} kN/m, natural frequency "
        f"{est(d['natural_frequency_Hz'], 1, '.3f')} Hz"
    )
    pr = q["prob"]
    if "frequency_below" in d:
        f = d["frequency_below"]
        print(
            f"    natural frequency below {f['max_frequency_Hz']:g} Hz with probability {f['probability']:.3f} "
            f"({'meets' if f['meets_prob'] else 'does not meet'} {pr:g}); with probability {pr:g} below "
            f"{f['frequency_for_prob_Hz']:.3f} Hz"
        )
    if "rate_within" in d:
        r = d["rate_within"]
        print(
            f"    rate within {r['tolerance_pct']:g} % of {r['target_N_per_m'] * 1e-3:g} kN/m with probability "
            f"{r['probability']:.3f} ({'meets' if r['meets_prob'] else 'does not meet'} {pr:g}); deviation "
            f"{est(r['deviation_pct'], 1, '+.1f')} %"
        )
    if "stroke_to_force_limit" in d:
        s = d["stroke_to_force_limit"]
        held = s["stroke_for_prob_m"]
        mean = f"{est(s['stroke_m'], 1e3, '.1f')} mm; " if s["stroke_m"] else ""
        print(
            f"    stroke to {s['force_limit_N']:g} N, {s['direction']}: {mean}"
            + (
                f"at least {held * 1e3:.1f} mm with probability {pr:g}"
                if held is not None
                else f"the limit is not reached within the tested range with probability {1 - s['prob_reached_in_tested_range']:.3f}"
            )
        )
