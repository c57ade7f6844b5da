"""``python -m jbevo.render``: a thin entry point; the command is :mod:`jbevo.cli.render`."""

from jbevo.cli.render import main

__all__ = ["main"]

if __name__ == "__main__":
    raise SystemExit(main())
