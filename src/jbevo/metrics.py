"""``python -m jbevo.metrics``: a thin entry point; the command is :mod:`jbevo.cli.metrics`."""

from jbevo.cli.metrics import main

__all__ = ["main"]

if __name__ == "__main__":
    raise SystemExit(main())
