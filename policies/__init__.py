"""Walking policies (our own frozen policies, and the runner for published ones)."""
