"""``uq report --units input``: the figures show the recordings' own units beside theirs (issue 30 item 2)."""

from __future__ import annotations

import pytest

from uq._data.units import OutputUnits
from uq._report import html

US = OutputUnits.of({"pressure": "psi", "height": "in", "force": "lbf", "volume": "in3"}, "input")


def test_axes_in_mm_and_kn_get_second_axes_in_inches_and_pounds():
    plt = html.pyplot()
    fig, (a, b) = plt.subplots(1, 2)
    a.set(xlabel="height x (mm)", ylabel="force P (kN)")
    b.set(xlabel="height x (mm)", ylabel="effective area F_eff = P / p_u (cm²)")
    html.input_unit_axes(fig, US)
    secondary = [c for ax in (a, b) for c in ax.child_axes]
    labels = sorted(s.get_xlabel() or s.get_ylabel() for s in secondary)
    assert labels == [
        "effective area F_eff = P / p_u (in^2)",
        "force P (lbf)",
        "height x (in)",
        "height x (in)",
    ]
    top = next(s for s in a.child_axes if s.get_xlabel())
    assert top._functions[0](25.4) == pytest.approx(1.0)  # 25.4 mm is 1 in
    right = next(s for s in a.child_axes if s.get_ylabel())
    assert right._functions[0](4.4482216152605e-3) == pytest.approx(1.0)  # 1 lbf in kN
    plt.close(fig)


def test_units_the_figure_already_shows_get_no_second_axis():
    plt = html.pyplot()
    fig, ax = plt.subplots()
    ax.set(xlabel="height x (mm)", ylabel="force (N)")
    html.input_unit_axes(fig, OutputUnits())  # bar, mm, N: nothing to add
    assert ax.child_axes == []
    assert html.encode(fig, "png", OutputUnits())[:4] == b"\x89PNG"


def test_write_report_draws_every_figure_with_the_units(n50_fit, tmp_path, monkeypatch):
    """Three of the shared fit's tests (the figures, not the fit, are the point)."""
    from dataclasses import replace

    from uq._derived.bands import campaign_bands
    from uq._report.campaign import write_report

    rec = n50_fit.recordings
    fit = replace(n50_fit, recordings=replace(rec, tests=rec.tests[4:7]), tests=n50_fit.tests[4:7])
    seen = []
    real = html.input_unit_axes
    monkeypatch.setattr(html, "input_unit_axes", lambda fig, u: seen.append(u) or real(fig, u))
    write_report(fit, tmp_path, bands=campaign_bands(fit, n_draws=60, seed=0), units=US)
    n_figures = len(list(tmp_path.glob("*.png")))
    assert n_figures >= len(fit.tests) + 3 and len(seen) == n_figures
    assert all(u == US for u in seen)
