"""Cooperative infotaxis: infotaxis searchers that share every step's observation over the radio.

Each member flies :class:`~agents.behaviors.infotaxis.Infotaxis` (its encounter model, its
hit counting, its declaration by evidence) on a belief that holds the swarm's evidence, not
only its own:

- **What it shares.** At the end of each of its steps a member publishes one
  :class:`Observation`: where the step observed (the mean of its readings' positions), the
  step's duration, its hit count, the mean wind it judged the step in, and the place it heads
  for next (8 numbers, 65 bytes of msgpack). That is every input of the step's likelihood, so
  a receiver computes the very likelihood the sender applied. Agents that fold their
  conspecifics' observations into their own maps are the collaborative infotaxis of Song,
  He, Ristic, Li & Lei (J. Phys. A, doi:10.1088/1751-8121/ab5088; there weighted by how
  much two maps differ, here all alike).
- **One belief, updated once a step.** The peers' observations that arrive are kept and
  folded in at the member's next step end, with its own, in one Bayes update: the belief is
  multiplied by the product of the step's likelihoods and normalised once. Observations are
  independent given the source (the Poisson model), so the posterior is the prior times the
  product of the likelihoods of every observation held, whatever the order they were applied
  in: under a perfect radio every member holds the same posterior (to rounding), and an
  observation the radio delays is applied when it arrives, however old; one it loses is
  missing from that member's posterior and from nothing else.
- **A common grid.** With more than one member the grid is the swarm's: laid across the
  centroid of the members' planned starts (the scenario's spawn points of the vehicles flying
  this behaviour) along the scenario's mean wind, so every member lays the same cells
  without a message. One member alone lays infotaxis's (at its start, along its first
  anemometer reading).
- **The swarm's evidence weight.** Members near one another meet the same bursts of a
  meandering plume, so their observations of one step are not independent: infotaxis's
  ``evidence_weight`` (0.5: a 1 s step counts as half an independent observation) is divided
  by N^``swarm_exponent`` for every observation, own and received alike (so every member
  still holds the same posterior). With ``swarm_exponent`` 0.5 the N observations of a step
  count as √N of a lone searcher's: between fully redundant members (1) and independent
  ones (N). Chosen on tuning seed 1000, runs 0–4, ``meander_low`` (docs/gsl.md).
- **Its own move, not a peer's.** Each member chooses its move by the lowest expected entropy
  of its belief, as infotaxis does, among the places no peer has announced as its next
  target (within ``avoid_radius_m``, the grid's 1 m cell: the same place at the belief's
  resolution); if every candidate is taken, among all of them. Two members that observe the
  same cell add little to one another (the informational overlap that "socialtaxis" has
  each searcher minimise: Karpas, Shklarsh & Schneidman 2017, PNAS); the peers' announced
  targets are the only coordination.

With one vehicle, or where the runner carries no peer messages (``ctx.mailbox`` is
``None``), it is infotaxis bit for bit. A peer observation's likelihood is computed once per
process for every member that receives it (a small memo keyed by the message's bits and the
grid), so the swarm's cost grows with its observations, not with their copies. Use
``behavior = "agents.behaviors.coop_infotaxis:CooperativeInfotaxis"`` on every member.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from typing import ClassVar

import msgspec

from agents.behavior import BehaviorContext
from agents.behaviors.infotaxis import Infotaxis
from agents.behaviors.infotaxis_core import FloatArray, IntArray, bayes_update, choose_move
from agents.behaviors.seeking import SeekStep
from agents.behaviors.wind import WindFrame, scenario_wind
from swarmbus.messages import Setpoint


class Observation(msgspec.Struct, frozen=True, array_like=True):
    """One step of a member: where it observed (ENU m), how long (s), its hits, the mean wind
    (east, north m/s) it judged them in, and the place it heads for next (ENU m)."""

    x_m: float
    y_m: float
    dt_s: float
    hits: int
    wind_east_m_s: float
    wind_north_m_s: float
    target_x_m: float
    target_y_m: float


#: (x, y, dt, hits, wind east, wind north): the likelihood inputs of an observation.
Evidence = tuple[float, float, float, int, float, float]
#: Per model: the cells a peer observation's plume reaches and their likelihood ratio there.
Factors = tuple[tuple[IntArray, FloatArray], ...]

#: Peer likelihoods kept per process (each is used by every member once, within a few steps).
MEMO_SIZE = 64
_memo: OrderedDict[tuple[object, ...], Factors] = OrderedDict()


class CooperativeInfotaxis(Infotaxis):
    vehicles = 3
    source = (
        "Vergassola, Villermaux & Shraiman 2007 infotaxis; every step's observation shared "
        "(collaborative infotaxis, Song et al., J. Phys. A)"
    )
    talks: ClassVar[bool] = True
    own_state: ClassVar[tuple[str, ...]] = (*Infotaxis.own_state, "pending", "peer_targets")
    start_spacing_m = 4.0
    avoid_radius_m = 1.0
    swarm_exponent = 0.5

    def __init__(self, ctx: BehaviorContext) -> None:
        super().__init__(ctx)
        own = ctx.scenario.vehicles[ctx.vehicle_index].behavior
        starts = [v.spawn_enu_m for v in ctx.scenario.vehicles if v.behavior == own]
        self.shared = self.mailbox is not None and len(starts) > 1
        self.swarm_start = (
            sum(p[0] for p in starts) / len(starts),
            sum(p[1] for p in starts) / len(starts),
        )
        self.planned_wind = scenario_wind(ctx)
        if self.shared:  # every member weighs every observation alike
            self.evidence_weight *= len(starts) ** -self.swarm_exponent
        #: Peer observations received and not yet applied, as :data:`Evidence`.
        self.pending: list[Evidence] = []
        #: Each peer's latest announced next place.
        self.peer_targets: dict[str, tuple[float, float]] = {}
        self.stepped: Evidence | None = None

    def seek(self, step: SeekStep) -> Setpoint | None:
        for received in sorted(step.inbox, key=lambda r: (r.sent_tick, r.sender)):
            m = received.message
            if isinstance(m, Observation):
                self.pending.append(
                    (m.x_m, m.y_m, m.dt_s, m.hits, m.wind_east_m_s, m.wind_north_m_s)
                )
                self.peer_targets[received.sender] = (m.target_x_m, m.target_y_m)
        if self.shared and self.belief is None:
            wind = self.planned_wind(step.own)
            x, y = self.swarm_start
            self.grid_origin = (wind, x, y)
            self._build_grid(WindFrame.of(wind), x, y)
            self.step_started_s = step.own.sim_time_s
        self.stepped = None
        setpoint = super().seek(step)
        if self.shared and self.stepped is not None and self.mailbox is not None:
            x, y, dt, hits, we, wn = self.stepped
            tx, ty = self.target_xy if self.target_xy is not None else (x, y)
            self.mailbox.publish(Observation(x, y, dt, hits, we, wn, tx, ty))
        return setpoint

    def _update(self, frame: WindFrame, x: float, y: float, dt_s: float) -> None:
        e, n, k = self.wind_sum
        ox, oy = self._observed_at(x, y)
        self.stepped = (ox, oy, dt_s, self.observation(), e / k, n / k)
        if not self.pending:
            super()._update(frame, x, y, dt_s)
            return
        assert self.belief is not None
        likelihood = self._own_likelihood(frame, x, y, dt_s).copy()
        for evidence in self.pending:
            for k_model, (cells, ratio) in enumerate(self._peer_factors(evidence)):
                likelihood[k_model, cells] *= ratio
        self.belief = bayes_update(self.belief, likelihood, None)
        self.pending = []
        self._next_step()

    def _peer_factors(self, evidence: Evidence) -> Factors:
        """A peer observation's likelihood per model, to the power ``evidence_weight``, as the
        cells its plume reaches and their ratio to the background's (the background's own
        factor is the same in every cell, so normalisation removes it)."""
        assert self.grid_origin is not None and self.cells_xy is not None
        key = (type(self), self.evidence_weight, self.grid_origin, evidence)
        found = _memo.get(key)
        if found is not None:
            _memo.move_to_end(key)
            return found
        x, y, dt, hits, we, wn = evidence
        sparse = self._sparse_at(self.cells_xy, WindFrame.of((we, wn)), x, y, dt)
        h = min(hits, self.n_classes - 1)
        # a step lasts at least 1 s, so the background's 0.02 /s gives every class a
        # positive probability
        background = float(sparse.background[h])
        assert background > 0.0, background
        factors = []
        for k, cells in enumerate(sparse.inside):
            lo, hi = sparse.offsets[k], sparse.offsets[k + 1]
            ratio = sparse.classes[h, lo:hi] / background
            if self.evidence_weight != 1.0:
                ratio = ratio**self.evidence_weight
            factors.append((cells, ratio))
        out = tuple(factors)
        _memo[key] = out
        if len(_memo) > MEMO_SIZE:
            _memo.popitem(last=False)
        return out

    def _decide(self, frame: WindFrame, x: float, y: float, dt_s: float) -> tuple[float, float]:
        places = self._places(frame, x, y)
        taken = self.peer_targets.values()
        free = [
            p for p in places if all(math.dist(p, t) > self.avoid_radius_m for t in taken)
        ] or places
        return free[choose_move(self._scores(frame, free, dt_s))]
