"""``python -m jbevo.evaluate``: a thin entry point; the command is :mod:`jbevo.cli.evaluate`."""

from jbevo.cli.evaluate import main

__all__ = ["main"]

if __name__ == "__main__":
    raise SystemExit(main())
