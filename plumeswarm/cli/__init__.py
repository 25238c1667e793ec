"""The ``plumeswarm`` command line (click): :mod:`plumeswarm.cli.main` (the group and most
commands), :mod:`plumeswarm.cli.plume`, :mod:`plumeswarm.cli.certs` and
:mod:`plumeswarm.cli.recording`
(command groups and bodies), :mod:`plumeswarm.cli.common` (what they share). The commands parse
arguments and call library functions; nothing outside this package imports it.

Importing it first checks that the packages plumeswarm installs are its own
(:mod:`plumeswarm._integrity`): if not, one line says which and the process exits with status 2.
"""

from plumeswarm._integrity import exit_if_not_ours

exit_if_not_ours()  # before any command module imports the packages it checks
