"""Layer 2: units and the basis scale, the force-noise formula, the physical mechanisms (one home each)."""
