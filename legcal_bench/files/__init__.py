"""Writing files: atomic writes, figures, and markdown + JSON reports."""
