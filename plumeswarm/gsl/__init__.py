"""The source-seeking benchmark (``plumeswarm bench gsl``; docs/gsl.md): the episodes
(:mod:`~plumeswarm.gsl.episode`), the strategies and environments
(:mod:`~plumeswarm.gsl.registry`), the grid and its tables (:mod:`~plumeswarm.gsl.bench`,
:mod:`~plumeswarm.gsl.sweep`, :mod:`~plumeswarm.gsl.stats`, :mod:`~plumeswarm.gsl.figure`)."""
