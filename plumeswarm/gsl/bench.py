"""``plumeswarm bench gsl``: source-seeking algorithms × environments × sensors, N seeded runs.

Every cell runs the same N starts (:func:`plumeswarm.gsl.episode.start_point`), spread over the
worker processes; the episodes are independent and seeded from (seed, run, vehicle), so
``gsl.md``, ``gsl.json``, ``paired.json`` and ``runs.csv`` are the same bytes for the same
arguments whatever the number of workers. The random walk (floor) and the oracle (ceiling)
run in every cell. Columns, definitions and the seed rule: docs/gsl.md "The protocol".
"""

from __future__ import annotations

import csv
import io
import itertools
import json
import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from agents.behavior import ignores_peers, talks
from deploy.visibility import floor_multiple
from plume_atmosphere.plume_formula import downwind_unit
from plumeswarm.gsl.episode import (
    RADII_M,
    START_ALONG_M,
    START_ALTITUDE_M,
    EpisodeSpec,
    Outcome,
    episode_time_limit_s,
)
from plumeswarm.gsl.family import AUTO_TIME_LIMIT_MULTIPLE, SEARCH_SPEED_M_S
from plumeswarm.gsl.grid import Executor, Journal, Shard, behavior_digest, run_episodes
from plumeswarm.gsl.registry import (
    CEILING,
    FLOOR,
    SENSORS,
    Algorithm,
    GslError,
    environment_names,
    load_environment,
    registered_algorithms,
    resolve_algorithm,
)
from plumeswarm.gsl.stats import Z_95, mcnemar_exact, speedup, summarise, wilson_interval

__all__ = ["Z_95", "GslError", "wilson_interval"]

LOCAL = Executor()

DYNAMICS = ("kinematic", "full")
FULL_SENSOR_HZ = 10  # with full dynamics a reading every control_hz / 10 ticks
TUNING_SEED_MIN = 1000  # tuning uses seeds >= this; the published tables seeds 0–99
#: Below this mean-over-floor at the farthest start a cell is flagged: the sensor cannot see
#: the plume there.
VISIBLE_FLOOR_MULTIPLE = 3.0
VISIBILITY_NOTE = (
    "the sensor cannot see the plume at the farthest starts: the cell measures visibility, "
    "not the algorithm"
)


@dataclass(frozen=True)
class GslOptions:
    algorithms: tuple[str, ...]  # names, floor first and ceiling last
    environments: tuple[str, ...]  # names or paths
    sensors: tuple[str, ...]
    runs: int = 30
    seed: int = 0
    time_limit_s: float = 300.0  # a fixed environment's (a family's is its own)
    control_hz: int = 20
    sensor_period_ticks: int = 2
    dynamics: str = "kinematic"
    jobs: int = 2
    configs: tuple[Algorithm, ...] = ()  # per algorithm
    asked: tuple[str, ...] = ()  # --algorithms as given, for the command line
    vehicles: tuple[int, ...] = ()  # how many fly each algorithm, each a cell; (): its own
    radios: tuple[Radio, ...] = ((),)  # each a radio setting ("radio.key" overrides), a cell
    spacing: float | None = None  # a swarm's crosswind start spacing; None: the algorithm's
    time_limit_auto: bool = False  # --time-limit auto: every episode's limit from its start

    @property
    def swarm(self) -> bool:
        """``--vehicles`` asked for more than one vehicle: the swarm columns and tables."""
        return any(n > 1 for n in self.vehicles)

    @property
    def radio(self) -> Radio:
        """The first radio setting (the only one a sweep takes)."""
        return self.radios[0]

    def radio_text(self) -> str:
        """``--radio`` as given to :func:`parse_radios` ("" for the default link alone)."""
        if self.radios == ((),):
            return ""
        return "/".join(radio_text(r) or PERFECT for r in self.radios)

    def config(self, algorithm: str) -> Algorithm:
        return self.configs[self.algorithms.index(algorithm)]


def _algorithms(asked: Sequence[str]) -> tuple[tuple[str, ...], tuple[Algorithm, ...]]:
    """The asked algorithms (none or "all": every registered one), with the floor first and
    the ceiling last."""
    texts = [t for t in asked if t != "all"] or list(registered_algorithms())
    resolved = dict(resolve_algorithm(t) for t in texts)
    for name in (FLOOR, CEILING):
        resolved.setdefault(name, resolve_algorithm(name)[1])
    middle = [n for n in resolved if n not in (FLOOR, CEILING)]
    names = (FLOOR, *middle, CEILING)
    return names, tuple(resolved[n] for n in names)


def _sensors(asked: Sequence[str]) -> tuple[str, ...]:
    if not asked or list(asked) == ["all"]:
        return tuple(k for k, v in SENSORS.items() if v.missing is None)
    for name in asked:
        if name not in SENSORS:
            raise GslError(f"--sensors {name!r}: unknown; valid: {', '.join(SENSORS)}")
        missing = SENSORS[name].missing
        if missing is not None:
            raise GslError(f"--sensors {name!r}: unavailable in this build (needs {missing})")
    return tuple(asked)


def _environments(asked: Sequence[str]) -> tuple[str, ...]:
    if not asked or list(asked) == ["all"]:
        return tuple(environment_names())
    for name in asked:
        load_environment(name)  # GslError: unknown, or not a valid scenario
    return tuple(asked)


#: ``--radio`` keys and the ``[radio]`` fields they set (docs/agents.md, "The radio").
RADIO_KEYS = {
    "range": "radio.range_m",
    "loss": "radio.loss",
    "latency": "radio.latency_ticks",
    "bytes": "radio.max_message_bytes",
}


Radio = tuple[tuple[str, Any], ...]  # one radio setting: "radio.key" overrides

#: The default link's name in ``--radio`` (a setting with no key).
PERFECT = "perfect"


def parse_radio(text: str) -> Radio:
    """``loss=0.2,latency=12,range=80,bytes=255`` as ``[radio]`` overrides (``perfect`` or
    nothing: none); :class:`GslError` names a bad key or value."""
    out: list[tuple[str, Any]] = []
    if text.strip() == PERFECT:
        return ()
    for part in (p.strip() for p in text.split(",") if p.strip()):
        key, sep, value = part.partition("=")
        if not sep or key.strip() not in RADIO_KEYS:
            raise GslError(
                f"--radio {part!r}: expected KEY=VALUE, KEY one of {', '.join(RADIO_KEYS)}"
            )
        field = RADIO_KEYS[key.strip()]
        try:
            number: Any = int(value) if field.endswith(("_ticks", "_bytes")) else float(value)
        except ValueError:
            raise GslError(f"--radio {part!r}: {value!r} is not a number") from None
        out.append((field, number))
    return tuple(out)


def parse_radios(value: str | Sequence[str] | Sequence[Radio]) -> tuple[Radio, ...]:
    """``--radio``: one setting (``loss=0.5,latency=20``) or several separated by ``/``
    (``perfect/loss=0.2/loss=0.5,latency=20``), each its own cells; :class:`GslError` names
    a bad one or one given twice."""
    if isinstance(value, str):
        texts: list[Any] = value.split("/") if value.strip() else [""]
    else:
        texts = list(value) or [""]
    radios = [parse_radio(t) if isinstance(t, str) else tuple(map(tuple, t)) for t in texts]
    for i, radio in enumerate(radios):
        if radio in radios[:i]:
            raise GslError(f"--radio {radio_text(radio) or PERFECT!r}: given twice")
    return tuple(radios)


def radio_text(radio: Radio) -> str:
    """A radio setting as ``--radio`` spells it ("" for the default link)."""
    names = {v: k for k, v in RADIO_KEYS.items()}
    return ",".join(f"{names[k]}={v:g}" for k, v in radio)


def radio_label(radio: Radio, control_hz: int) -> str:
    """A radio setting for a table: "perfect", or "loss 0.5, 1 s" (latency in seconds at the
    behaviour's rate), range and message bytes when set."""
    if not radio:
        return PERFECT
    values = dict(radio)
    parts = []
    if "radio.loss" in values:
        parts.append(f"loss {values['radio.loss']:g}")
    if "radio.latency_ticks" in values:
        parts.append(f"{values['radio.latency_ticks'] / control_hz:g} s")
    if "radio.range_m" in values:
        parts.append(f"range {values['radio.range_m']:g} m")
    if "radio.max_message_bytes" in values:
        parts.append(f"{values['radio.max_message_bytes']} B")
    return ", ".join(parts)


def hears_peers(config: Algorithm, vehicles: int) -> bool:
    """Whether a radio can change the cell's episodes: more than one vehicle, flying a
    behaviour that talks or reads its peers (one that says ``ignores_peers = True`` and does
    not talk flies the same bits on any radio)."""
    if vehicles <= 1:
        return False
    return talks(config.behavior) or not ignores_peers(config.behavior)


def parse_vehicles(value: int | str | Sequence[int] | None) -> tuple[int, ...]:
    """``--vehicles``: ``3`` or ``1,3,10`` (each count its own cells); :class:`GslError`
    names a bad count."""
    if value is None or value == "" or value == 0:
        return ()
    if isinstance(value, int):
        texts = [str(value)]
    elif isinstance(value, str):
        texts = [t.strip() for t in value.split(",") if t.strip()]
    else:
        texts = [str(v) for v in value]
    counts = []
    for t in texts:
        if not t.isdigit() or not 1 <= int(t) <= 64:
            raise GslError(f"--vehicles {t!r}: expected whole numbers from 1 to 64, e.g. 1,3,10")
        counts.append(int(t))
    return tuple(dict.fromkeys(counts))


def make_options(
    algorithms: Sequence[str],
    environments: Sequence[str],
    sensors: Sequence[str],
    **kwargs: Any,
) -> GslOptions:
    """Validated options; :class:`GslError` names the bad option."""
    dynamics = kwargs.get("dynamics", "kinematic")
    if dynamics not in DYNAMICS:
        raise GslError(f"--dynamics {dynamics!r}: valid: {', '.join(DYNAMICS)}")
    envs = _environments(environments)
    if dynamics == "full":  # the real controller runs at the scenario's rates
        hz = load_environment(envs[0]).scenario.time.control_hz
        kwargs["control_hz"] = hz
        kwargs["sensor_period_ticks"] = max(1, hz // FULL_SENSOR_HZ)
    names, configs = _algorithms(algorithms)
    asked = tuple(a for a in algorithms if a != "all")
    kwargs["radios"] = parse_radios(kwargs.pop("radio", ""))
    for radio in kwargs["radios"]:
        if radio:
            load_environment(envs[0], radio)  # GslError: a value out of range
    kwargs["vehicles"] = parse_vehicles(kwargs.get("vehicles"))
    limit = kwargs.get("time_limit_s", 300.0)
    if limit == "auto":
        kwargs["time_limit_s"], kwargs["time_limit_auto"] = 300.0, True
    elif isinstance(limit, str):
        try:
            kwargs["time_limit_s"] = float(limit)
        except ValueError:
            raise GslError(f"--time-limit {limit!r}: seconds (>= 1) or auto") from None
    if kwargs.get("time_limit_s", 300.0) < 1.0:
        raise GslError(f"--time-limit {limit!r}: seconds (>= 1) or auto")
    return GslOptions(
        algorithms=names,
        environments=envs,
        sensors=_sensors(sensors),
        configs=configs,
        asked=asked,
        **kwargs,
    )


def availability_lines() -> list[str]:
    """Which environments and sensors this build can simulate, and what the others need."""
    lines = [f"environments available: {', '.join(environment_names())} (or a scenario path)"]
    have = [k for k, v in SENSORS.items() if v.missing is None]
    lines.append(f"sensors available: {', '.join(have)}")
    for name, value in SENSORS.items():
        if value.missing is not None:
            lines.append(
                f"sensors unavailable: {name} ({value.description}; needs {value.missing})"
            )
    return lines


def specs_of(opts: GslOptions, **fields: Any) -> list[EpisodeSpec]:
    """Every episode of the options (``fields``: more :class:`EpisodeSpec` fields for all)."""
    specs = []
    for e in opts.environments:
        hz, period = opts.control_hz, opts.sensor_period_ticks
        if opts.dynamics == "full":
            hz = load_environment(e).scenario.time.control_hz
            period = max(1, hz // FULL_SENSOR_HZ)
        for s, (a, algo), n, radio, run in itertools.product(
            opts.sensors,
            zip(opts.algorithms, opts.configs, strict=True),
            opts.vehicles or (0,),
            opts.radios,
            range(opts.runs),
        ):
            if radio != opts.radios[0] and not hears_peers(algo, n or algo.vehicles):
                continue  # the same bits on every radio: flown on the first only
            spec = EpisodeSpec(
                algorithm=a,
                environment=e,
                sensor=s,
                run=run,
                seed=opts.seed,
                time_limit_s=opts.time_limit_s,
                control_hz=hz,
                sensor_period_ticks=period,
                keep_trajectory=run == 0,
                dynamics=opts.dynamics,
                behavior=algo.behavior,
                vehicles=n or algo.vehicles,
                overrides=radio,
                start_spacing_m=opts.spacing,
            )
            spec = replace(spec, **fields)
            if opts.time_limit_auto or load_environment(e).family is not None:
                spec = replace(spec, time_limit_s=episode_time_limit_s(spec))
            specs.append(spec)
    return specs


def _stderr(line: str) -> None:
    print(line, file=sys.stderr)


def run_specs(
    specs: Sequence[EpisodeSpec],
    jobs: int,
    progress: Callable[[int, int], None] | None = None,
    *,
    executor: Executor = LOCAL,
    journal: Journal | None = None,
    shard: Shard | None = None,
    log: Callable[[str], None] | None = None,
    cpu_s: dict[EpisodeSpec, float] | None = None,
    warn: Callable[[str], None] = _stderr,
) -> list[Outcome]:
    """Every episode's outcome, in spec order (the order the workers finish in does not
    matter); a spec given twice is flown once. With a ``journal``, the episodes it holds with
    the parameters their behaviour has now are read back, not flown (``warn``: one line for
    those flown again because the parameters changed, one for those kept without them), and
    each one flown is appended to it as it finishes; with a ``shard``, only the shard's
    episodes run and come back. ``cpu_s``: filled with the CPU seconds of each episode flown
    (in its worker's process)."""
    mine = shard.of(specs) if shard is not None else list(dict.fromkeys(specs))
    done: dict[EpisodeSpec, Outcome] = {}
    digests: dict[str, str] = {}  # behaviour → its digest, computed once here
    if journal is not None:
        for behavior in dict.fromkeys(s.algorithm_config().behavior for s in mine):
            digests[behavior] = behavior_digest(behavior)
        reuse = journal.reusable(mine, lambda s: digests[s.algorithm_config().behavior])
        done = reuse.outcomes
        for line in reuse.notices(journal.path):
            warn(line)
    todo = [s for s in mine if s not in done]
    if log is not None:
        log(f"grid: {len(mine)} episodes, {len(done)} already done, {len(todo)} to run")
    if progress and done:
        progress(len(done), len(mine))
    for outcome, cpu in run_episodes(todo, executor, jobs):
        if journal is not None:
            journal.append(outcome, digests[outcome.spec.algorithm_config().behavior])
        done[outcome.spec] = outcome
        if cpu_s is not None:
            cpu_s[outcome.spec] = cpu
        if progress:
            progress(len(done), len(mine))
    return [done[spec] for spec in (mine if shard is not None else specs)]


def run_all(
    opts: GslOptions,
    progress: Callable[[int, int], None] | None = None,
    cpu_s: dict[EpisodeSpec, float] | None = None,
) -> list[Outcome]:
    return run_specs(specs_of(opts), opts.jobs, progress, cpu_s=cpu_s)


def throughput_lines(cpu_s: dict[EpisodeSpec, float]) -> list[str]:
    """Episodes per core-second and CPU seconds per episode of each algorithm and dynamics
    (every episode's CPU time in its own process: what one idle core gives)."""
    by: dict[tuple[str, str], list[float]] = {}
    for spec, cpu in cpu_s.items():
        by.setdefault((spec.algorithm, spec.dynamics), []).append(cpu)
    lines = ["episodes per core-second (CPU s per episode: mean, max):"]
    for (algorithm, dynamics), times in sorted(by.items()):
        total = sum(times)
        rate = len(times) / total if total > 0 else math.inf
        lines.append(
            f"  {algorithm:<16} {dynamics:<9} {rate:8.3f}  "
            f"({total / len(times):.2f}, {max(times):.2f}; {len(times)} episodes)"
        )
    return lines


Cell = tuple[str, str, str, int, Radio]  # environment, sensor, algorithm, vehicles, radio


def cells_of(outcomes: Sequence[Outcome]) -> dict[Cell, list[Outcome]]:
    cells: dict[Cell, list[Outcome]] = {}
    for o in outcomes:
        s = o.spec
        cells.setdefault(
            (s.environment, s.sensor, s.algorithm, s.vehicles, s.overrides), []
        ).append(o)
    return cells


def floor_multiple_at_farthest_start(
    environment: str, sensor: str, overrides: tuple[tuple[str, Any], ...] = ()
) -> float | None:
    """The environment's mean concentration (its steady Gaussian plume: the time average of
    the same atmosphere) at the farthest start — ``START_ALONG_M[1]`` downwind of the first
    source, on its axis, at ``START_ALTITUDE_M`` — over ``sensor``'s detection floor, rounded
    to 3 decimals; ``None`` for a sensor without a floor (it sees any gas)."""
    scenario = load_environment(environment, overrides).scenario
    source = scenario.plume.sources[0]
    ux, uy = downwind_unit(scenario.wind.from_deg)
    along = START_ALONG_M[1]
    point = (source.x_m + along * ux, source.y_m + along * uy, START_ALTITUDE_M)
    multiple = floor_multiple(scenario, SENSORS[sensor].config, point)
    return None if math.isinf(multiple) else round(multiple, 3)


def row_of(outcomes: Sequence[Outcome]) -> dict[str, Any]:
    """One table row: the cell's names, its environment's identity, its statistics."""
    spec = outcomes[0].spec
    env = load_environment(spec.environment, spec.overrides)
    return {
        "algorithm": spec.algorithm,
        "environment": env.name,
        "time_dependent": env.time_dependent,
        "scenario_sha256": env.sha256,
        "sensor": spec.sensor,
        "floor_multiple_at_farthest_start": floor_multiple_at_farthest_start(
            spec.environment, spec.sensor, spec.overrides
        ),
        "dynamics": spec.dynamics,
        "vehicles": spec.vehicles or spec.algorithm_config().vehicles,
        **({"radio": dict(spec.overrides)} if spec.overrides else {}),
        **summarise(outcomes),
    }


def visibility_table(rows: Sequence[dict[str, Any]]) -> str:
    """Per (environment, sensor): the mean at the farthest start over the sensor's floor, and
    the flag where it is below :data:`VISIBLE_FLOOR_MULTIPLE`."""
    head = (
        f"| environment | sensor | mean at the farthest start ({START_ALONG_M[1]:g} m) / "
        "sensor floor | |\n|---|---|---|---|\n"
    )
    seen: dict[tuple[str, str], float | None] = {}
    for r in rows:
        seen.setdefault((r["environment"], r["sensor"]), r["floor_multiple_at_farthest_start"])
    lines = []
    for (env, sensor), multiple in seen.items():
        value = "no floor" if multiple is None else f"{multiple:.2f}"
        flag = VISIBILITY_NOTE if multiple is not None and multiple < VISIBLE_FLOOR_MULTIPLE else ""
        lines.append(f"| {env} | {sensor} | {value} | {flag} |")
    return head + "\n".join(lines) + "\n"


def rows_of(opts: GslOptions, outcomes: Sequence[Outcome]) -> list[dict[str, Any]]:
    cells = cells_of(outcomes)
    rows = [row_of(cell) for cell in cells.values()]
    if opts.swarm:
        first = opts.radios[0]
        best = best_single(cells)
        for row, (key, cell) in zip(rows, cells.items(), strict=True):
            env, sensor, algorithm, n, radio = key
            heard = hears_peers(opts.config(algorithm), n)
            row.update(
                swarm_columns(
                    cell,
                    cells.get((env, sensor, algorithm, 1, first)),
                    cells.get((env, sensor, best[env, sensor], 1, first))
                    if (env, sensor) in best
                    else None,
                )
            )
            row["radio_label"] = radio_label(radio, opts.control_hz) if heard else "–"
    return rows


def best_single(cells: dict[Cell, list[Outcome]]) -> dict[tuple[str, str], str]:
    """Per (environment, sensor): the algorithm whose 1-vehicle cell declared within 2 m most
    often (the floor and the ceiling left out; on a tie, the first in the grid's order)."""
    best: dict[tuple[str, str], tuple[int, str]] = {}
    for (env, sensor, algorithm, n, _), cell in cells.items():
        if n != 1 or algorithm in (FLOOR, CEILING):
            continue
        wins = sum(o.success for o in cell)
        if (env, sensor) not in best or wins > best[env, sensor][0]:
            best[env, sensor] = (wins, algorithm)
    return {k: v[1] for k, v in best.items()}


def swarm_columns(
    cell: Sequence[Outcome],
    single: Sequence[Outcome] | None,
    best: Sequence[Outcome] | None = None,
) -> dict[str, Any]:
    """A swarm cell's own columns: the median closest approach between two of its vehicles,
    the median total path, the speed-up over the same algorithm's 1-vehicle cell
    (``single``) on the runs both declared within 2 m (:func:`speedup`), and McNemar's exact
    test of its success against the best 1-vehicle cell (``best``) on the same starts."""
    closest = [o.closest_approach_m for o in cell if o.closest_approach_m is not None]
    out: dict[str, Any] = {
        "closest_approach_m": round(float(np.median(closest)), 2) if closest else None,
        "min_closest_approach_m": round(min(closest), 2) if closest else None,
        "total_path_m": round(float(np.median([o.total_path_m for o in cell])), 1),
        "reached_member_2m_rate": round(
            sum(o.nearest_member_m <= RADII_M[0] for o in cell) / len(cell), 3
        ),
        "speedup_over_1": None,
        "speedup_ci95": None,
        "speedup_pairs": 0,
        "vs_best_single": None,
    }
    if best is not None:
        mine = {o.spec.run: o.success for o in cell}
        theirs = {o.spec.run: o.success for o in best}
        shared = sorted(mine.keys() & theirs.keys())
        only_n, only_1, p = mcnemar_exact([mine[k] for k in shared], [theirs[k] for k in shared])
        out["vs_best_single"] = {
            "algorithm": best[0].spec.algorithm,
            "runs": len(shared),
            "only_this": only_n,
            "only_single": only_1,
            "p_exact": round(p, 4),
        }
    if single is None:
        return out
    by_run = {o.spec.run: o.time_to_success_s for o in single}
    pairs = [
        (t1, o.time_to_success_s)
        for o in cell
        if o.time_to_success_s is not None and (t1 := by_run.get(o.spec.run)) is not None
    ]
    if pairs:
        point, ci = speedup([p[0] for p in pairs], [p[1] for p in pairs])
        out["speedup_over_1"] = round(point, 2)
        out["speedup_ci95"] = None if ci is None else [round(ci[0], 2), round(ci[1], 2)]
        out["speedup_pairs"] = len(pairs)
    return out


def scaling_table(rows: Sequence[dict[str, Any]]) -> str:
    """Per algorithm, number of vehicles and radio: success, reached, false declarations,
    median time to declare, the speed-up over 1 vehicle, the paired test against the best
    1-vehicle algorithm, closest approach and total path."""
    head = (
        "| algorithm | environment | sensor | vehicles | radio | success % (95 % CI) "
        "| reached ≤ 2 m % (centroid, any member) | false declarations % | median time s "
        "| speed-up over 1 (95 % CI, pairs) | vs best single vehicle (only N, only 1, p) "
        "| closest approach m (median, min) | total path m |\n"
    )
    head += "|---" * (head.count("|") - 1) + "|\n"
    lines = []
    for r in rows:
        ci = r["speedup_ci95"]
        interval = "" if ci is None else f"{ci[0]:.2f}–{ci[1]:.2f}, "
        gain = (
            "–"
            if r["speedup_over_1"] is None
            else f"{r['speedup_over_1']:.2f} ({interval}{r['speedup_pairs']} pairs)"
        )
        closest = (
            "–"
            if r["closest_approach_m"] is None
            else f"{r['closest_approach_m']:.2f}, {r['min_closest_approach_m']:.2f}"
        )
        vs = r["vs_best_single"]
        versus = (
            "–"
            if vs is None
            else f"{vs['algorithm']}: {vs['only_this']}, {vs['only_single']}, {vs['p_exact']:.3f}"
        )
        lines.append(
            f"| {r['algorithm']} | {r['environment']} | {r['sensor']} | {r['vehicles']} "
            f"| {r['radio_label']} | {_pct(r, 'success_rate')} "
            f"| {_pct(r, 'reached_2m_rate', ci=False)}, "
            f"{_pct(r, 'reached_member_2m_rate', ci=False)} "
            f"| {_pct(r, 'false_declaration_rate', ci=False)} "
            f"| {_fmt(r['median_time_s'], 1)} | {gain} | {versus} | {closest} "
            f"| {r['total_path_m']:.0f} |"
        )
    return head + "\n".join(lines) + "\n"


def paired_rows(outcomes: Sequence[Outcome], swarm: bool = False) -> list[dict[str, Any]]:
    """McNemar's exact test on success (declared within 2 m) for every pair of algorithms in
    every (environment, sensor) — with ``swarm``, every (environment, sensor, vehicles,
    radio), a cell whose episodes no radio changes (:func:`hears_peers`) taking part under
    each radio: run k of both had the same start."""
    groups: dict[tuple[str, str, int], dict[Cell, list[Outcome]]] = {}
    for key, cell in cells_of(outcomes).items():
        env, sensor, _, n, _ = key
        groups.setdefault((env, sensor, n if swarm else 0), {})[key] = cell
    rows = []
    for (env, sensor, n), cells in groups.items():
        heard = {k: hears_peers(c[0].spec.algorithm_config(), n) for k, c in cells.items()}
        radios: list[Radio | None] = list(dict.fromkeys(k[4] for k in cells if heard[k]))
        radios = radios or [None]
        for radio in radios:
            algos = {k[2]: c for k, c in cells.items() if not heard[k] or k[4] == radio}
            label = "–" if radio is None else radio_label(radio, cells_hz(cells))
            for a, b in itertools.combinations(algos, 2):
                runs_a = {o.spec.run: o.success for o in algos[a]}
                runs_b = {o.spec.run: o.success for o in algos[b]}
                shared = sorted(runs_a.keys() & runs_b.keys())
                only_a, only_b, p = mcnemar_exact(
                    [runs_a[k] for k in shared], [runs_b[k] for k in shared]
                )
                rows.append(
                    {
                        "environment": load_environment(env).name,
                        "sensor": sensor,
                        **({"vehicles": n, "radio": label} if swarm else {}),
                        "a": a,
                        "b": b,
                        "runs": len(shared),
                        "a_only": only_a,
                        "b_only": only_b,
                        "p_exact": round(p, 4),
                    }
                )
    return rows


def cells_hz(cells: dict[Cell, list[Outcome]]) -> int:
    """The behaviour rate of a group's episodes (a latency's ticks in seconds)."""
    return next(iter(cells.values()))[0].spec.control_hz


def _fmt(value: float | None, digits: int) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def _pct(row: dict[str, Any], key: str, ci: bool = True) -> str:
    value = row[key]
    if not ci:
        return f"{100 * value:.0f}"
    low, high = row["success_ci95" if key == "success_rate" else f"{key}_ci95"]
    return f"{100 * value:.0f} ({100 * low:.0f}–{100 * high:.0f})"


def _algorithm_cell(row: dict[str, Any], swarm: bool) -> str:
    return f"{row['algorithm']} ×{row['vehicles']}" if swarm else str(row["algorithm"])


def markdown_table(rows: Sequence[dict[str, Any]], swarm: bool = False) -> str:
    radii = [f"{r:g}m" for r in RADII_M]
    head = (
        "| algorithm | environment | sensor | runs | success % (95 % CI) "
        + "".join(f"| declared ≤ {t[:-1]} m % " for t in radii[1:])
        + "".join(f"| reached ≤ {t[:-1]} m % " for t in radii)
        + "| false declarations % (95 % CI) | median time s (IQR) | path / initial distance "
        "| final error m | detections / min |\n"
    )
    head += "|---" * (head.count("|") - 1) + "|\n"
    lines = []
    for r in rows:
        q1, q3 = r["time_iqr_s"]
        time_cell = (
            "–"
            if r["median_time_s"] is None
            else f"{r['median_time_s']:.1f} ({_fmt(q1, 1)}–{_fmt(q3, 1)})"
        )
        cells = [
            _algorithm_cell(r, swarm),
            r["environment"],
            r["sensor"],
            str(r["runs"]),
            _pct(r, "success_rate"),
            *(_pct(r, f"declared_{t}_rate") for t in radii[1:]),
            *(_pct(r, f"reached_{t}_rate") for t in radii),
            _pct(r, "false_declaration_rate"),
            time_cell,
            _fmt(r["path_ratio"], 2),
            _fmt(r["final_error_m"], 2),
            _fmt(r["detections_per_min"], 0),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return head + "\n".join(lines) + "\n"


def paired_table(rows: Sequence[dict[str, Any]]) -> str:
    swarm = bool(rows) and "vehicles" in rows[0]
    head = (
        "| environment | sensor | "
        + ("vehicles | radio | " if swarm else "")
        + "A | B | runs | only A succeeds | only B succeeds "
        "| p (McNemar exact) |\n|---|---|---|---|---|---|---|---|"
        + ("---|---|" if swarm else "")
        + "\n"
    )
    lines = [
        f"| {r['environment']} | {r['sensor']} | "
        + (f"{r['vehicles']} | {r['radio']} | " if swarm else "")
        + f"{r['a']} | {r['b']} | {r['runs']} "
        f"| {r['a_only']} | {r['b_only']} | {r['p_exact']:.4f} |"
        for r in rows
    ]
    return head + "\n".join(lines) + "\n"


def command_line(opts: GslOptions, sub: str = "") -> str:
    """The command that produces the tables (without --jobs and --out, which do not change
    them)."""
    parts = ["plumeswarm bench gsl", *([sub] if sub else [])]
    if opts.asked:
        parts.append(f"--algorithms {','.join(opts.asked)}")
    parts.append(f"--environments {','.join(opts.environments)}")
    parts.append(f"--sensors {','.join(opts.sensors)}")
    parts.append(f"--runs {opts.runs} --seed {opts.seed}")
    if opts.vehicles:
        parts.append(f"--vehicles {','.join(str(n) for n in opts.vehicles)}")
    if opts.spacing is not None:
        parts.append(f"--spacing {opts.spacing:g}")
    if opts.radio_text():
        parts.append(f"--radio {opts.radio_text()}")
    if opts.time_limit_auto:
        parts.append("--time-limit auto")
    elif opts.time_limit_s != 300.0:
        parts.append(f"--time-limit {opts.time_limit_s:g}")
    parts.append(f"--dynamics {opts.dynamics}")
    if opts.dynamics == "kinematic" and (opts.control_hz, opts.sensor_period_ticks) != (20, 2):
        parts.append(
            f"--control-hz {opts.control_hz} --sensor-period-ticks {opts.sensor_period_ticks}"
        )
    return " ".join(parts)


def seed_note(opts: GslOptions) -> str:
    if opts.seed >= TUNING_SEED_MIN:
        return f"Seed {opts.seed}: tuning seeds (≥ {TUNING_SEED_MIN}), not a published table."
    return f"Seed {opts.seed}: test seeds (the published tables use seed 0, runs 0–99)."


def protocol_line(opts: GslOptions) -> str:
    counts = ", ".join(str(n) for n in opts.vehicles)
    swarm = f"{counts} vehicles per algorithm, " if opts.vehicles else ""
    if opts.swarm:
        spacing = "the algorithm's" if opts.spacing is None else f"{opts.spacing:g} m"
        swarm += (
            f"a swarm's starts on a crosswind line centred on the run's start ({spacing} "
            "spacing; 0: a circle of 2 m), "
        )
    radio = f"radio {opts.radio_text()} (docs/agents.md), " if opts.radio_text() else ""
    if len(opts.radios) > 1:
        radio = (
            f"radios {opts.radio_text()} (docs/agents.md; each its own cells; a cell whose "
            "episodes no radio changes, one vehicle or a behaviour that ignores its peers, is "
            "flown on the first only and shown with radio –), "
        )
    families = [e for e in opts.environments if load_environment(e).family is not None]
    if opts.time_limit_auto or families:
        return protocol_line_drawn(opts, swarm, radio, families)
    return (
        f"{opts.runs} runs per cell, {swarm}{radio}"
        f"seed {opts.seed}, dynamics {opts.dynamics} "
        f"(control {opts.control_hz} Hz, sensor every {opts.sensor_period_ticks} ticks), "
        f"limit {opts.time_limit_s:g} s, starts 30–80 m downwind and ±20 m crosswind at 10 m "
        "(run k: the same start for every algorithm), a time-dependent release running "
        "max(60 s, 1.5 × 80 m / wind speed) before; success: a declaration within 2 m of the "
        "source."
    )


def protocol_line_drawn(opts: GslOptions, swarm: str, radio: str, families: Sequence[str]) -> str:
    """The protocol line of a grid with a randomised family or ``--time-limit auto``."""
    names = ", ".join(load_environment(e).name for e in families)
    drawn = (
        f"in the randomised families ({names}) every run draws its source, wind, release and "
        'class and its start (docs/gsl.md "Randomised families"), '
        if families
        else ""
    )
    fixed = (
        f"limit {AUTO_TIME_LIMIT_MULTIPLE:g} × the straight flight from the start at "
        f"{SEARCH_SPEED_M_S:g} m/s"
        if opts.time_limit_auto
        else f"limit {opts.time_limit_s:g} s"
    )
    return (
        f"{opts.runs} runs per cell, {swarm}{radio}"
        f"seed {opts.seed}, dynamics {opts.dynamics} "
        f"(control {opts.control_hz} Hz, sensor every {opts.sensor_period_ticks} ticks), "
        f"{drawn}a family's limit its time_limit_multiple × the straight flight from the "
        f"start at {SEARCH_SPEED_M_S:g} m/s; in the other environments {fixed}, starts 30–80 m "
        "downwind and ±20 m crosswind at 10 m (run k: the same start for every algorithm), "
        "a time-dependent release running max(60 s, 1.5 × the farthest start / wind speed) "
        "before; success: a declaration within 2 m of the source."
    )


def environment_lines(opts: GslOptions) -> list[str]:
    lines = []
    for name in opts.environments:
        env = load_environment(name)
        kind = "time-dependent" if env.time_dependent else "steady"
        lines.append(
            f"- environment `{env.name}` ({kind}; sha256 {env.sha256[:12]}…): {env.description}"
        )
    return lines


def report_text(
    opts: GslOptions, rows: Sequence[dict[str, Any]], paired: Sequence[dict[str, Any]] = ()
) -> str:
    """The Markdown report: the command, protocol, environments, tables. No wall-clock
    content."""
    avail = "\n".join(f"- {line}" for line in availability_lines())
    text = (
        f"```\n{command_line(opts)}\n```\n\n{protocol_line(opts)} {seed_note(opts)}\n\n"
        + "\n".join(environment_lines(opts))
        + f"\n{avail}\n\n{markdown_table(rows, opts.swarm)}"
        + "\nSensor visibility: the time-averaged plume at the farthest start in multiples of "
        f"the sensor's detection floor; below {VISIBLE_FLOOR_MULTIPLE:g}, flagged.\n\n"
        + visibility_table(rows)
    )
    if opts.swarm:
        text += (
            "\nSwarm scaling (success: the swarm's first declaration within 2 m; reached: the "
            "vehicles' centroid, then any one member, within 2 m; speed-up: median time to "
            "declare of 1 vehicle over that of N on the runs both declared within 2 m, paired "
            "by start, 95 % percentile bootstrap; closest approach: between any two vehicles; "
            "total path: all vehicles'):"
            "\n\n" + scaling_table(rows)
        )
    if paired:
        text += (
            "\nPaired comparisons on the same starts (success = declared within 2 m; "
            "two-sided exact p):\n\n" + paired_table(paired)
        )
    return text


RUN_COLUMNS = (
    "algorithm",
    "environment",
    "sensor",
    "dynamics",
    "run",
    "seed",
    "start_x_m",
    "start_y_m",
    "initial_distance_m",
    "declared",
    "declared_s",
    "estimate_x_m",
    "estimate_y_m",
    "final_error_m",
    "success",
    "min_distance_m",
    *(f"first_within_{r:g}m_s" for r in RADII_M),
    "path_length_m",
    "path_ratio",
    "detections_per_min",
)


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, float):
        return f"{value:.4f}"
    return str(value)


#: Appended to ``RUN_COLUMNS`` when ``--vehicles`` asks for a swarm.
SWARM_COLUMNS = ("vehicles", "radio", "closest_approach_m", "total_path_m", "nearest_member_m")


def runs_csv(outcomes: Sequence[Outcome], swarm: bool = False) -> str:
    """Every episode, one line each (``RUN_COLUMNS``; with ``swarm``, then
    ``SWARM_COLUMNS``)."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(RUN_COLUMNS + (SWARM_COLUMNS if swarm else ()))
    for o in outcomes:
        s = o.spec
        extra = (
            (
                s.vehicles,
                radio_text(s.overrides) or PERFECT,
                o.closest_approach_m,
                o.total_path_m,
                o.nearest_member_m,
            )
            if swarm
            else ()
        )
        writer.writerow(
            _cell(v)
            for v in (
                s.algorithm,
                load_environment(s.environment).name,
                s.sensor,
                s.dynamics,
                s.run,
                s.seed,
                o.start_xy[0],
                o.start_xy[1],
                o.initial_distance_m,
                o.declared,
                o.declared_s,
                o.estimate_xy[0],
                o.estimate_xy[1],
                o.final_error_m,
                o.success,
                o.min_distance_m,
                *o.first_within_s,
                o.path_length_m,
                o.path_length_m / o.initial_distance_m,
                o.detections_per_min,
                *extra,
            )
        )
    return buf.getvalue()


def write_outputs(
    out: Path, opts: GslOptions, rows: Sequence[dict[str, Any]], outcomes: Sequence[Outcome]
) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    paired = paired_rows(outcomes, opts.swarm)
    files = {
        "gsl.md": report_text(opts, rows, paired),
        "gsl.json": json.dumps(list(rows), indent=1, ensure_ascii=False) + "\n",
        "paired.json": json.dumps(paired, indent=1, ensure_ascii=False) + "\n",
        "runs.csv": runs_csv(outcomes, opts.swarm),
    }
    written = []
    for name, text in files.items():
        (out / name).write_text(text)
        written.append(out / name)
    # matplotlib only when writing figures
    from plumeswarm.gsl.figure import plot_errors, plot_scaling, plot_success, plot_trajectories

    written.append(plot_success(out / "success.png", rows))
    if opts.swarm:
        written.append(plot_scaling(out / "swarm.png", rows))
    written.append(plot_errors(out / "final_error.png", outcomes))
    for env in opts.environments:
        samples = [o for o in outcomes if o.spec.environment == env and o.trajectories]
        name = load_environment(env).name
        written.append(plot_trajectories(out / f"trajectories_{name}.png", samples))
    return written
