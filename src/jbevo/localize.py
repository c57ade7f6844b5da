"""``python -m jbevo.localize``: a thin entry point; the command is :mod:`jbevo.cli.localize`."""

from jbevo.cli.localize import main

__all__ = ["main"]

if __name__ == "__main__":
    raise SystemExit(main())
