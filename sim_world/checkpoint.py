"""Checkpoints of the physics world, so a killed physics process resumes where it was.

A :class:`WorldCheckpoint` is everything the world needs to continue identically from a tick:
pybullet's own state (every body's pose and velocities and its contact cache, as the bytes of
``saveBullet``; restoring poses and velocities alone is not bit-exact and lets grounded
vehicles drift by millimetres within a few seconds), every vehicle's motor state (rotor speeds,
targets, enabled) and contact flags (landed, crashed, in contact, fastest speed of the tick),
the step count and the tick, and the plume's values that this tick carries to the autopilots
(``SimTick.plume_values``). The file is one msgpack document, written atomically (temporary
file + rename), so a reader sees the previous checkpoint or the next one, never half of one.

:class:`CheckpointWriter` writes on its own thread, so the disk's latency stays out of the
physics loop (which only captures the state and, one tick later, makes sure it is on disk).

A :class:`ProgressMarker` is a tiny memory-mapped file where the physics notes every tick it
publishes (tick number and a monotonic wall time): it survives a SIGKILL, so the process that
resumes from the checkpoint can say how much sim time it replays and how long ticks stopped.
"""

from __future__ import annotations

import logging
import mmap
import os
import struct
import tempfile
import time
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import msgspec

from swarmbus.closeable import Closeable
from swarmbus.errors import PlumeswarmError
from swarmbus.messages import PlumeSample

log = logging.getLogger(__name__)

FORMAT = "physics_checkpoint/v2"
# pybullet writes its state to a file only; a RAM-backed directory keeps that off the disk.
_SCRATCH_DIR = "/dev/shm" if os.path.isdir("/dev/shm") else None
_MARKER = struct.Struct("<qq")  # last published tick, time.monotonic_ns() at publication


class CheckpointError(PlumeswarmError, ValueError):
    """A checkpoint file that cannot be read, or that belongs to another world."""


class VehicleCheckpoint(msgspec.Struct, frozen=True, kw_only=True):
    vehicle_id: str
    vehicle_type: str
    omega_rad_s: list[float]
    target_rad_s: list[float]
    settled: bool
    wrench: tuple[float, float, float, float]  # cached body thrust and torques when settled
    motors_enabled: bool
    crashed: bool
    on_ground: bool
    in_contact: bool
    max_speed2: float
    # Also in ``bullet``; kept readable (and used to check that the restore took).
    position_enu_m: tuple[float, float, float]
    attitude_xyzw: tuple[float, float, float, float]
    velocity_enu_m_s: tuple[float, float, float]
    angular_velocity_enu_rad_s: tuple[float, float, float]


class WorldCheckpoint(msgspec.Struct, frozen=True, kw_only=True):
    format: str = FORMAT
    world: str
    physics_hz: int
    control_hz: int
    tick: int
    step_count: int
    sim_time_s: float
    vehicles: list[VehicleCheckpoint]
    bullet: bytes  # pybullet ``saveBullet`` of the whole world
    # The plume's answer to the last sensor tick that goes into this tick's ``plume_values``
    # (the physics has it before it steps to this tick), carried again on resume.
    plume_sample: PlumeSample | None = None


_encoder = msgspec.msgpack.Encoder()
_decoder = msgspec.msgpack.Decoder(WorldCheckpoint)


def scratch_file(suffix: str) -> Path:
    """A new empty file for pybullet to write or read (the caller removes it)."""
    fd, name = tempfile.mkstemp(prefix="plumeswarm-", suffix=suffix, dir=_SCRATCH_DIR)
    os.close(fd)
    return Path(name)


def save(path: Path, checkpoint: WorldCheckpoint) -> None:
    """Write ``checkpoint`` to ``path`` atomically (a new temporary file, then rename)."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "wb") as f:
        f.write(_encoder.encode(checkpoint))
    os.replace(tmp, path)


def load(path: Path) -> WorldCheckpoint:
    """Read a checkpoint; :class:`CheckpointError` says what is wrong with the file."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise CheckpointError(f"cannot read checkpoint {path}: {exc.strerror or exc}") from None
    try:
        checkpoint = _decoder.decode(data)
    except (msgspec.ValidationError, msgspec.DecodeError) as exc:
        raise CheckpointError(f"checkpoint {path} is not a physics checkpoint: {exc}") from None
    if checkpoint.format != FORMAT:
        raise CheckpointError(f"checkpoint {path} has format {checkpoint.format!r}, not {FORMAT}")
    return checkpoint


def remove(path: Path) -> None:
    """Remove a checkpoint and its progress marker (a fresh run starts from spawn)."""
    for p in (path, marker_path(path)):
        p.unlink(missing_ok=True)


class CheckpointWriter:
    """Writes checkpoints to ``path`` one at a time on a worker thread; keeps timings."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="checkpoint")
        self._pending: Future[float] | None = None
        self._tick = -1
        self.written = 0
        self.write_s = 0.0  # total and longest time on the worker
        self.longest_write_s = 0.0
        self.waited_s = 0.0  # total time callers spent in wait()

    @property
    def pending(self) -> bool:
        return self._pending is not None

    def submit(self, checkpoint: WorldCheckpoint) -> None:
        self.wait()
        self._tick = checkpoint.tick
        self._pending = self._pool.submit(self._write, checkpoint)

    def _write(self, checkpoint: WorldCheckpoint) -> float:
        t0 = time.monotonic()
        save(self.path, checkpoint)
        return time.monotonic() - t0

    def wait(self) -> None:
        """Until the submitted checkpoint is on disk (a failed write is logged, not raised)."""
        pending, self._pending = self._pending, None
        if pending is None:
            return
        t0 = time.monotonic()
        try:
            took = pending.result()
        except OSError as exc:
            log.error("checkpoint of tick %d not written to %s: %s", self._tick, self.path, exc)
        else:
            self.written += 1
            self.write_s += took
            self.longest_write_s = max(self.longest_write_s, took)
        finally:
            self.waited_s += time.monotonic() - t0

    def close(self) -> None:
        self.wait()
        self._pool.shutdown()


def marker_path(checkpoint_path: Path) -> Path:
    return checkpoint_path.with_name(checkpoint_path.name + ".progress")


class ProgressMarker(Closeable):
    """The last published tick and its wall time, in a memory-mapped file (survives SIGKILL)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise CheckpointError(f"cannot write {path}: {exc.strerror or exc}") from None
        try:
            if os.fstat(fd).st_size < _MARKER.size:
                os.ftruncate(fd, _MARKER.size)
            self._map = mmap.mmap(fd, _MARKER.size)
        finally:
            os.close(fd)
        self._view = memoryview(self._map).cast("q")  # 8-byte aligned stores: never torn

    @staticmethod
    def read(path: Path) -> tuple[int, float] | None:
        """(last tick, its ``time.monotonic()``) noted in ``path``, or None."""
        try:
            data = path.read_bytes()
        except OSError:
            return None
        if len(data) < _MARKER.size:
            return None
        tick, wall_ns = _MARKER.unpack_from(data)
        return (tick, wall_ns / 1e9) if wall_ns > 0 else None

    def mark(self, tick: int) -> None:
        view = self._view
        view[0] = tick
        view[1] = time.monotonic_ns()

    def close(self) -> None:
        self._view.release()
        self._map.close()
