"""The ``plumeswarm`` command line (click): :mod:`plumeswarm.cli.main` (the group and most
commands), :mod:`plumeswarm.cli.plume`, :mod:`plumeswarm.cli.certs` and
:mod:`plumeswarm.cli.recording`
(command groups and bodies), :mod:`plumeswarm.cli.common` (what they share). The commands parse
arguments and call library functions; nothing outside this package imports it."""
