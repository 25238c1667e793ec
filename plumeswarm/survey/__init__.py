"""A plume survey that estimates a source's release rate by the mass-balance method
(``plumeswarm bench survey``; docs/survey.md).

A vehicle flies crosswind legs at several heights on a vertical *curtain* downwind of the
source (:mod:`~plumeswarm.survey.pattern`), records what it reads (position, time,
concentration, the wind its anemometer measures) and the flux of gas through the curtain is
integrated from those readings (:mod:`~plumeswarm.survey.flux`): Q = ∫∫ (C − C_b)·U⊥ dy dz.
The estimate takes readings from any vehicle; :mod:`~plumeswarm.survey.plane` flies the
pattern with the Aerosonde fixed-wing (its autopilot and physics), :mod:`~plumeswarm.survey.flight`
with a point moving at a constant ground speed, and :mod:`~plumeswarm.survey.bench` runs it
over the benchmark environments.
"""

from plumeswarm.survey.flux import FluxEstimate, SurveyError, SurveyReading, estimate_flux
from plumeswarm.survey.pattern import CurtainPlan, plan_curtain, plan_for_scenario

__all__ = [
    "CurtainPlan",
    "FluxEstimate",
    "SurveyError",
    "SurveyReading",
    "estimate_flux",
    "plan_curtain",
    "plan_for_scenario",
]
