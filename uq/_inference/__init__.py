"""Layer 5: the exact linear-Gaussian draw kernel, the emcee edge, convergence rules, summaries."""
