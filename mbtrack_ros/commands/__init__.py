"""Subcommands of ``mbtrack``: each module has ``add_parser(subparsers)`` and ``run(args)``."""
