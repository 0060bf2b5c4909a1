"""The verbs of the `woody` command, one module each: ``add_arguments(parser)`` and ``run(args) -> int``."""
