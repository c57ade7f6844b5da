"""The command lines (``python -m jbevo.train``, ``.evaluate``, ``.localize``, ``.metrics``,
``.demo``, ``.render``); they share :mod:`jbevo.cli.common`. No library module imports them."""

__all__: list[str] = []
