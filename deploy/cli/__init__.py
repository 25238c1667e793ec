"""The ``plumeswarm`` command line (click): :mod:`deploy.cli.main` (the group and most
commands), :mod:`deploy.cli.plume`, :mod:`deploy.cli.certs` and :mod:`deploy.cli.recording`
(command groups and bodies), :mod:`deploy.cli.common` (what they share). The commands parse
arguments and call library functions; nothing outside this package imports it."""
