"""Running a grid's episodes anywhere: the executors (a local process pool, a Ray cluster), the
journal that lets a grid resume, shards for batch schedulers, and their merge.

An episode is a pure function of its :class:`~plumeswarm.gsl.episode.EpisodeSpec`, so where
and in which order it runs does not change its outcome. Every finished episode is appended to
the output directory's ``episodes.jsonl`` (one line, flushed; the first line says which grid
the directory holds); a grid started again with the same options and ``--out`` reads it back
and runs only the episodes it lacks, and the tables are written from all of them, in the grid's
order: the same bytes as a run never interrupted. Each line keeps a digest of the parameters of
the episode's behaviour (:func:`behavior_digest`); an episode kept with other parameters is
flown again. ``--shard i/N`` runs every N-th episode starting at the i-th;
:func:`merge_journals` puts the N directories back together.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import multiprocessing
import os
import re
import socket
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from plumeswarm.gsl.episode import EpisodeSpec, Outcome, run_episode
from plumeswarm.gsl.registry import GslError, behavior_class_name, behavior_parameters
from swarmbus.extras import missing_extra_message

JOURNAL = "episodes.jsonl"
EXECUTORS = ("local", "ray")
#: How many times Ray runs an episode again after its worker process died.
RAY_MAX_RETRIES = 3
REACH_TIMEOUT_S = 10.0


@dataclass(frozen=True)
class Shard:
    """The ``index``-th (1-based) of ``count`` slices: every ``count``-th episode of the grid
    from the ``index``-th on, so that each shard gets its share of every algorithm."""

    index: int
    count: int

    def __str__(self) -> str:
        return f"{self.index}/{self.count}"

    def of(self, specs: Sequence[EpisodeSpec]) -> list[EpisodeSpec]:
        return list(dict.fromkeys(specs))[self.index - 1 :: self.count]


def parse_shard(text: str) -> Shard:
    """``i/N`` with 1 ≤ i ≤ N → the shard; :class:`GslError` naming the value otherwise."""
    index, sep, count = text.partition("/")
    try:
        shard = Shard(int(index), int(count))
    except ValueError:
        shard = Shard(0, 0)
    if not sep or not 1 <= shard.index <= shard.count:
        raise GslError(f"--shard {text!r}: expected i/N with 1 <= i <= N (e.g. 1/4)")
    return shard


@dataclass(frozen=True)
class Executor:
    """``local`` (a process pool of ``jobs`` workers) or ``ray`` (``address``: a cluster's
    ``HOST:PORT``, ``auto`` for the one ``ray start`` made here, ``""``: a Ray started for
    this run)."""

    kind: str = "local"
    address: str = ""

    def __str__(self) -> str:
        return self.kind + (f"={self.address}" if self.address else "")


def parse_executor(text: str) -> Executor:
    """``local``, ``ray`` or ``ray=ADDRESS``; :class:`GslError` naming the value otherwise."""
    kind, sep, address = text.partition("=")
    if kind not in EXECUTORS or (kind == "local" and sep) or (sep and not address):
        raise GslError(f"--executor {text!r}: valid: local, ray, ray=ADDRESS (e.g. ray=auto)")
    return Executor(kind, address)


def spec_key(spec: EpisodeSpec) -> str:
    """The episode's identity in a journal: a digest of every field of its spec (a start
    spacing left to the algorithm is left out, as before the field existed)."""
    fields = dataclasses.asdict(spec)
    if fields["start_spacing_m"] is None:
        del fields["start_spacing_m"]
    text = json.dumps(fields, sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def spec_name(spec: EpisodeSpec) -> str:
    """The episode for people: algorithm/environment/sensor run k (and what else differs)."""
    name = f"{spec.algorithm}/{spec.environment}/{spec.sensor} run {spec.run}"
    extra = [f"{k}={v}" for k, v in spec.overrides]
    if spec.behavior and "?" in spec.behavior:
        extra.append(spec.behavior.partition("?")[2])
    return name + (f" ({', '.join(extra)})" if extra else "")


def grid_digest(specs: Sequence[EpisodeSpec]) -> str:
    """The whole grid's identity: its episodes, in order."""
    keys = "\n".join(spec_key(s) for s in dict.fromkeys(specs))
    return hashlib.sha256(keys.encode()).hexdigest()[:24]


def _plain(value: Any) -> Any:
    """A parameter's value as JSON holds it, the same in every process: containers element by
    element (a set sorted), a dataclass as its name and fields, an array as a list, anything
    else its repr without a memory address."""
    if value is None or isinstance(value, str | int | float):
        return value
    if isinstance(value, dict):
        return {k if isinstance(k, str) else repr(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, set | frozenset):
        return sorted((_plain(v) for v in value), key=repr)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        fields = {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
        return {"dataclass": type(value).__qualname__, **fields}
    if callable(getattr(value, "tolist", None)):  # a NumPy array or scalar
        return _plain(value.tolist())
    return re.sub(r" at 0x[0-9a-fA-F]+", "", repr(value))


def behavior_digest(behavior: str) -> str:
    """The identity of the behaviour ``behavior`` names as a journal keeps it: a digest of its
    class's ``module:qualname`` and its parameters (the public class attributes,
    :func:`~plumeswarm.gsl.registry.behavior_parameters`); not of its code."""
    params = {k: _plain(v) for k, v in behavior_parameters(behavior).items()}
    text = json.dumps(
        {"class": behavior_class_name(behavior), "parameters": params}, sort_keys=True, default=repr
    )
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def outcome_record(outcome: Outcome, behavior: str | None = None) -> dict[str, Any]:
    """The journal line of ``outcome`` (``behavior``: its behaviour's digest, if known)."""
    fields = {f.name: getattr(outcome, f.name) for f in dataclasses.fields(outcome)}
    del fields["spec"]
    record = {"key": spec_key(outcome.spec), "episode": spec_name(outcome.spec), "outcome": fields}
    return record if behavior is None else {**record, "behavior": behavior}


def outcome_of(spec: EpisodeSpec, fields: dict[str, Any]) -> Outcome:
    """The outcome a journal line holds, for ``spec`` (JSON floats round-trip exactly)."""
    return Outcome(
        spec=spec,
        **{
            **fields,
            "estimate_xy": tuple(fields["estimate_xy"]),
            "start_xy": tuple(fields["start_xy"]),
            "first_within_s": tuple(fields["first_within_s"]),
            "trajectories": [[tuple(p) for p in t] for t in fields["trajectories"]],
        },
    )


@dataclass
class Journal:
    """``DIR/episodes.jsonl``: the grid's header, then one line per finished episode."""

    path: Path
    header: dict[str, Any]
    records: dict[str, dict[str, Any]]  # key → the outcome's fields
    # key → the digest of its behaviour's parameters (None: a line from before the digest)
    behaviors: dict[str, str | None] = field(default_factory=dict)

    @staticmethod
    def read(path: Path, repair: bool = False) -> Journal | None:
        """The journal at ``path`` (None if there is none, or not even a whole header); a
        last line cut off by a kill is dropped (and, with ``repair``, cut from the file)."""
        if not path.exists():
            return None
        data = path.read_bytes()
        whole = data[: data.rfind(b"\n") + 1]
        if repair and len(whole) != len(data):
            with path.open("r+b") as f:
                f.truncate(len(whole))
        lines = whole.decode().splitlines()
        if not lines:
            return None
        try:
            header = json.loads(lines[0])["grid"]
            records, behaviors = {}, {}
            for line in lines[1:]:  # an episode flown again: its last line
                record = json.loads(line)
                records[record["key"]] = record["outcome"]
                behaviors[record["key"]] = record.get("behavior")
        except (ValueError, KeyError, TypeError) as exc:
            raise GslError(f"{path}: not a grid journal ({exc})") from None
        return Journal(path, header, records, behaviors)

    @staticmethod
    def open(out: Path, header: dict[str, Any]) -> Journal:
        """The journal of ``out`` for the grid ``header``: the one there (refused with one line
        if it holds another grid), else a new one."""
        path = out / JOURNAL
        journal = Journal.read(path, repair=True)
        if journal is None:
            out.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps({"grid": header}, sort_keys=True) + "\n")
            return Journal(path, header, {})
        if journal.header != header:
            why = _difference(journal.header, header)
            raise GslError(
                f"--out {out}: holds episodes of {why}; resume with the options that made it "
                "or give another --out"
            )
        return journal

    def reusable(self, specs: Sequence[EpisodeSpec], digest: Callable[[EpisodeSpec], str]) -> Reuse:
        """Which of ``specs`` the journal holds: kept with their behaviour's ``digest``
        (reused), kept with another (flown again), kept without one (reused, unchecked)."""
        reuse = Reuse()
        for spec in specs:
            key = spec_key(spec)  # a digest of the spec: once per episode
            fields = self.records.get(key)
            if fields is None:
                continue
            kept = self.behaviors.get(key)
            if kept is not None and kept != digest(spec):
                reuse.changed.append(spec)
                continue
            reuse.outcomes[spec] = outcome_of(spec, fields)
            reuse.unchecked += kept is None
        return reuse

    def append(self, outcome: Outcome, behavior: str | None = None) -> None:
        """One line (with ``behavior``, the digest of the episode's behaviour), written whole
        and flushed before the next episode is counted."""
        record = outcome_record(outcome, behavior)
        line = json.dumps(record, sort_keys=True) + "\n"
        with self.path.open("a") as f:
            f.write(line)
            f.flush()
            os.fsync(f.fileno())
        self.records[record["key"]] = record["outcome"]
        self.behaviors[record["key"]] = behavior


@dataclass
class Reuse:
    """What a journal gives a grid that resumes: the outcomes to use again, the episodes kept
    with other behaviour parameters (to fly again), how many outcomes were kept without."""

    outcomes: dict[EpisodeSpec, Outcome] = field(default_factory=dict)
    changed: list[EpisodeSpec] = field(default_factory=list)
    unchecked: int = 0

    def notices(self, path: Path) -> list[str]:
        """One line for the episodes flown again, one for those reused unchecked."""
        lines = []
        if self.changed:
            names = ", ".join(dict.fromkeys(s.algorithm for s in self.changed))
            lines.append(
                f"{len(self.changed)} episode(s) in {path} flown again: the parameters of "
                f"their behaviour changed ({names})"
            )
        if self.unchecked:
            lines.append(
                f"{self.unchecked} episode(s) reused from {path} without a check of their "
                "behaviour's parameters (kept before the check existed); to fly them again give "
                "another --out or delete that file"
            )
        return lines


def _difference(theirs: dict[str, Any], ours: dict[str, Any]) -> str:
    """How the grid a journal holds differs from ours, for people."""
    if theirs.get("command") != ours.get("command"):
        return f"`{theirs.get('command')}`, not `{ours.get('command')}`"
    if theirs.get("digest") != ours.get("digest"):
        return "the same command over other episodes (the algorithms or environments changed)"
    if theirs.get("shard") != ours.get("shard"):
        return f"{_shard_text(theirs)}, not {_shard_text(ours)}"
    mine, yours = theirs.get("args", {}), ours.get("args", {})
    keys = sorted(k for k in mine.keys() | yours.keys() if mine.get(k) != yours.get(k))
    return "the grid with " + ", ".join(f"{k}={mine.get(k)!r} (now {yours.get(k)!r})" for k in keys)


def _shard_text(header: dict[str, Any]) -> str:
    shard = header.get("shard")
    return "the whole grid" if not shard else f"shard {shard[0]}/{shard[1]}"


def grid_header(
    kind: str, args: dict[str, Any], command: str, specs: Sequence[EpisodeSpec], shard: Shard | None
) -> dict[str, Any]:
    """What a directory's journal says it holds: the grid (``kind`` and the ``args`` that
    rebuild its options, its ``command`` for people, the digest of its episodes) and the
    shard."""
    return {
        "kind": kind,
        "args": args,
        "command": command,
        "digest": grid_digest(specs),
        "episodes": len(dict.fromkeys(specs)),
        "shard": None if shard is None else [shard.index, shard.count],
    }


def timed_episode(spec: EpisodeSpec) -> tuple[Outcome, float]:
    """The episode's outcome and the CPU seconds its own process spent on it."""
    cpu0 = time.process_time()
    outcome = run_episode(spec)
    return outcome, time.process_time() - cpu0


def _local(specs: Sequence[EpisodeSpec], jobs: int) -> Iterator[tuple[Outcome, float]]:
    if jobs <= 1 or len(specs) <= 1:
        yield from map(timed_episode, specs)
        return
    ctx = multiprocessing.get_context("fork")
    with ctx.Pool(min(jobs, len(specs))) as pool:
        yield from pool.imap_unordered(timed_episode, specs, chunksize=1)


def _import_ray() -> Any:
    try:
        import ray
    except ImportError:
        raise GslError(str(missing_extra_message("ray", "--executor ray"))) from None
    return ray


def _reachable(address: str) -> None:
    """:class:`GslError` (one line) unless ``address`` (``HOST:PORT``; ``""`` and ``auto``
    are found by Ray) accepts a connection: Ray itself would wait for it a long time."""
    host, sep, port = address.rpartition(":")
    if not sep or not port.isdigit():
        return
    try:
        socket.create_connection((host, int(port)), timeout=REACH_TIMEOUT_S).close()
    except OSError as exc:
        raise GslError(
            f"--executor ray={address}: no Ray head answers there ({exc.strerror or exc}); "
            "start one with `ray start --head`"
        ) from None


def _ray(specs: Sequence[EpisodeSpec], address: str) -> Iterator[tuple[Outcome, float]]:
    """Each episode a Ray task, retried (``RAY_MAX_RETRIES``) if its worker process dies;
    outcomes as they finish, each once."""
    ray = _import_ray()
    started = not ray.is_initialized()
    if started:
        _reachable(address)
        try:
            ray.init(
                address=address or "local",
                logging_level="ERROR",
                log_to_driver=False,
                include_dashboard=False,
                configure_logging=False,
            )
        except (ConnectionError, RuntimeError, ValueError) as exc:
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise GslError(f"--executor ray={address}: cannot reach Ray ({first})") from None
    try:
        task = ray.remote(max_retries=RAY_MAX_RETRIES, num_cpus=1)(timed_episode)
        pending = {task.remote(s): s for s in specs}
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            for ref in ready:
                spec = pending.pop(ref)
                try:
                    yield ray.get(ref)
                except ray.exceptions.RayError as exc:
                    first = str(exc).strip().splitlines()[0]
                    raise GslError(
                        f"{spec_name(spec)}: failed on the Ray cluster ({first}); the finished "
                        "episodes are kept: run the same command again to resume"
                    ) from None
    finally:
        if started:
            ray.shutdown()


def run_episodes(
    specs: Sequence[EpisodeSpec], executor: Executor, jobs: int
) -> Iterator[tuple[Outcome, float]]:
    """Every spec's outcome and the CPU seconds its worker spent on it, in the order they
    finish."""
    if executor.kind == "ray":
        return _ray(specs, executor.address)
    return _local(specs, jobs)


def check_executor(executor: Executor) -> None:
    """:class:`GslError` (one line) if the executor cannot run here."""
    if executor.kind == "ray":
        _import_ray()
        _reachable(executor.address)


@dataclass(frozen=True)
class Merged:
    """Shards put back together: the grid's header (without a shard), every outcome's
    fields by episode key, and the keys found in more than one directory."""

    header: dict[str, Any]
    records: dict[str, dict[str, Any]]
    overlap: frozenset[str] = frozenset()
    behaviors: dict[str, str | None] = field(default_factory=dict)


def merge_journals(dirs: Sequence[Path]) -> Merged:
    """The journals of ``dirs``, which must hold parts of one grid; :class:`GslError` (one
    line naming the directories) otherwise. :func:`missing_episodes` checks the episodes."""
    journals = []
    for d in dirs:
        journal = Journal.read(d / JOURNAL)
        if journal is None:
            raise GslError(f"merge: {d} holds no {JOURNAL} (not the --out of bench gsl)")
        journals.append(journal)
    first = journals[0]
    grid = {k: v for k, v in first.header.items() if k != "shard"}
    records: dict[str, dict[str, Any]] = {}
    behaviors: dict[str, str | None] = {}
    overlap: set[str] = set()
    for d, journal in zip(dirs, journals, strict=True):
        theirs = {k: v for k, v in journal.header.items() if k != "shard"}
        if theirs != grid:
            raise GslError(
                f"merge: {d} holds `{theirs.get('command')}`, {dirs[0]} `{grid.get('command')}`"
            )
        for key, fields in journal.records.items():
            if key in records:
                overlap.add(key)
            records[key] = fields
            behaviors[key] = journal.behaviors.get(key)
    return Merged({**grid, "shard": None}, records, frozenset(overlap), behaviors)


def _listed(names: Sequence[str]) -> str:
    shown = list(names[:5])
    more = f" and {len(names) - 5} more" if len(names) > 5 else ""
    return ", ".join(shown) + more


def missing_episodes(merged: Merged, specs: Sequence[EpisodeSpec]) -> None:
    """:class:`GslError` naming, in the grid's order, the episodes more than one shard ran,
    or else those no shard ran."""
    unique = list(dict.fromkeys(specs))
    twice = [spec_name(s) for s in unique if spec_key(s) in merged.overlap]
    if twice:
        raise GslError(f"merge: episodes in more than one directory: {_listed(twice)}")
    missing = [spec_name(s) for s in unique if spec_key(s) not in merged.records]
    if missing:
        raise GslError(f"merge: {len(missing)} episode(s) in no directory: {_listed(missing)}")
