"""Layer 8: derived quantities: bands, design margins, checks against point estimates, result documents."""
