"""The run-time type checker the test suite installs on jbevo (see conftest): beartype with
PEP 484's numeric tower (an ``int`` is a valid ``float``, as static checkers read it)."""

from beartype import BeartypeConf, beartype

checker = beartype(conf=BeartypeConf(is_pep484_tower=True))
