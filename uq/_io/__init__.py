"""Layer 1 (bottom): atomic writes, JSON, one-line input errors, option values, progress, the version."""
