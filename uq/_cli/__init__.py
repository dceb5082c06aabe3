"""Layer 11 (top): the command line, one module per command; the only user of argparse."""
