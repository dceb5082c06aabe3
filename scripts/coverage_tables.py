"""Tables a coverage study writes into its own summary and scripts/readme_numbers.py into docs/:
one function for both, in a module that imports nothing heavy (the studies import the models)."""

from __future__ import annotations


def model_check_table(checked: dict, models=("discrepancy", "surface")) -> list[str]:
    """The model check's table (scripts/between_coverage.py's ``model_check``): per (spring, grid)
    and model, the campaigns the check flagged and the pooled share of force queries covered in
    all campaigns and in those it passed; by grid, then spring."""

    def pct(v):
        return "-" if v is None else f"{v:.2f}"

    lines = [
        "| spring | grid | model | flagged | covered, all | covered, check passed |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for key in sorted(checked, key=lambda k: (k.split("/")[1], k)):
        spring, grid = key.split("/")
        for m in models:
            c = checked[key][m]
            lines.append(
                f"| {spring} | {grid} | {m} | {c['flagged']} of {checked[key]['campaigns']} | "
                f"{pct(c['force_covered_all'])} | {pct(c['force_covered_when_passed'])} |"
            )
    return lines
