"""The speed benchmark (dsm perf): what each stage costs in time and memory, into a file."""
