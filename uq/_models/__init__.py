"""Layer 6: the models: per-pressure cubics, the pressure-coupled surface, the diagnose models."""
