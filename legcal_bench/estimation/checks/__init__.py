"""Data checks: what a recording measures before a fit, and the per-stance contact check after."""
