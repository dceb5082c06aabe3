"""The README's numbers come from runs and committed reports, never typed (scripts/readme_numbers.py)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "scripts" / "readme_numbers.py"


def _blocks(text: str) -> tuple:
    sys.path.insert(0, str(SCRIPT.parent))
    try:
        import readme_numbers
    finally:
        sys.path.pop(0)
    return [m["name"] for m in readme_numbers.BLOCK.finditer(text)], readme_numbers


def test_every_generated_block_is_known_and_filled():
    names, mod = _blocks((ROOT / "README.md").read_text())
    assert set(names) <= set(mod.BLOCKS)
    assert {"fit-n50", "calibration", "diagnose-proof", "diagnose-n50", "speed"} <= set(names)
    for m in mod.BLOCK.finditer((ROOT / "README.md").read_text()):
        assert m["body"].strip(), (
            f"README block {m['name']} is empty: run python scripts/readme_numbers.py"
        )


def test_report_blocks_agree_with_committed_reports():
    """Blocks made from reports/ (calibration, coverage, proof, timings) are what the script makes of them."""
    proc = subprocess.run(
        [sys.executable, str(SCRIPT), "--check"], cwd=ROOT, capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_regenerate_replaces_only_the_block_body():
    _, mod = _blocks("")
    text = "a\n<!-- generated: speed -->\nold\n<!-- end generated: speed -->\nb\n"
    mod.BLOCKS["__t"] = ("report", lambda: "new\n")
    try:
        out, changed = mod.regenerate(text.replace("speed", "__t"), {"__t"})
    finally:
        del mod.BLOCKS["__t"]
    assert (
        out == "a\n<!-- generated: __t -->\nnew\n<!-- end generated: __t -->\nb\n"
        and changed == ["__t"]
    )
