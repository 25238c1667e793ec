"""plume_atmosphere — the atmosphere every role shares: the wind (steady, meander, grid),
dispersion curves, the calibration of a time-dependent plume to its atmosphere, the Gaussian
plume formula, and the gases' molar masses.

Pure science on numpy: it imports nothing else of plumeswarm's, so the contract (the scenario
loader) and every role may use it (docs/architecture.md, "Layers").
"""
