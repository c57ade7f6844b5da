"""``python -m jbevo.train``: a thin entry point; the command is :mod:`jbevo.cli.train`."""

from jbevo.cli.train import main

__all__ = ["main"]

if __name__ == "__main__":
    raise SystemExit(main())
