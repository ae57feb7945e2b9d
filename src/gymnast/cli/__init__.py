"""The `gymnast` command line: one subcommand per job, each a thin call into the library.

`app` gathers the subcommands into the console script; each room holds the commands of one part
of the pipeline (`data`, `policy`, `world_model`, `judge`, `practice`, `measure`), `flags` the flag
types several of them share, and `settings` the one rule for presets, overrides and ``--resume``.
"""

from gymnast.cli.app import main

__all__ = ["main"]
