"""`python -m dsm ...` is the `dsm` command line."""
import sys

from .cli import main

sys.exit(main())
