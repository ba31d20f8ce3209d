"""The command line: parser, the command registry, commands, printed tables, plots.

The only place that knows a ``--flag``."""
