"""``python -m jbevo.demo``: a thin entry point; the command is :mod:`jbevo.cli.demo`."""

from jbevo.cli.demo import main

__all__ = ["main"]

if __name__ == "__main__":
    raise SystemExit(main())
