"""Example behaviour plug-ins (``module:Class`` in a scenario's ``[[vehicles]] behavior``)."""
