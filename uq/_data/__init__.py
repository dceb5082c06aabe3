"""Layer 3: recordings (the CSV format and its validation), the paper's tables, stand descriptions."""
