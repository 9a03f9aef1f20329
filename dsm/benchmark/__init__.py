"""dsm benchmark: the frozen shadow-bias suites (dsm-bench-1, dsm-bench-2), their results, comparison and leaderboard."""
