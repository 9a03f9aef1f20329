"""An experiment run: the plan, the runner and its record, resume, motion, the cluster backend, the folder lock."""
