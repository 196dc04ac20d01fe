"""The command lines ``cadra1`` and ``cadra2``: thin shells that parse arguments, call the
library and print what its results' reports say (docs/cli.md). One module per ``cadra2``
subcommand; nothing outside this package imports it but to call a ``main``."""
