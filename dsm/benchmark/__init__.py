"""dsm benchmark: the frozen shadow-bias suite (dsm-bench-1), its results, comparison and leaderboard."""
