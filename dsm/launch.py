"""The ``dsm`` command's entry point: the command line's modules (Mitsuba, Dr.Jit, matplotlib) take
most of a second to import, and a Ctrl-C then must end the command as it does later: one line, exit 130."""
import sys


def main() -> int:
    """Import the command line and run it; a Ctrl-C while importing exits 130 with one line."""
    try:
        from .cli import main as run
    except KeyboardInterrupt:
        print("dsm: interrupted (while starting)", file=sys.stderr)
        return 130
    return run()
