"""Layer 7: the discrepancy engine (locate the mismatch, name and model the missing physics)."""
