"""The package version (one home: uq.__version__, pyproject.toml reads it from here)."""

__version__ = "0.1.0"
