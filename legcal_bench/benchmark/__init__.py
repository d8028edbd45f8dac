"""The benchmark: suites (with tags), the plan of cells, the worker tasks, the runner
(local processes or Dask), the leaderboard, and the regression fixture."""
