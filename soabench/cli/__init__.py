"""The ``soabench`` command line (docs/user-guide/commands.md): one module per command, each with ``add_parser``
(its options and help) and ``handle`` (parse, call the one function of the layer that owns the work, print);
:mod:`soabench.cli.main` wires them into one parser and turns every error a user can cause into one line and exit
status 2.

A handler imports its layer when the command runs, so that building the parser (``--help``, a usage error) imports
no simulation, compiled kernel or plotting library.
"""
