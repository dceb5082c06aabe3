"""Layer 4: the virtual test stand, which follows the paper's procedure and error budget."""
