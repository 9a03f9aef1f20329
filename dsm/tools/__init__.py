"""Around the stages: the benchmark (dsm bench), the environment and plugins, clock reads."""
