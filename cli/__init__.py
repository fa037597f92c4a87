"""The ``nbrdf`` and ``nbrdf-view`` command lines (SPEC section 8): one
module per command family, each command's flags generated from one
documented dataclass (``nbrdf.cli.config``). Nothing in the library imports
this package."""
