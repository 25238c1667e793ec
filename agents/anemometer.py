"""A vehicle's anemometer: the scenario's wind at the vehicle's position, plus its own noise.

The wind is the one every process evaluates (:mod:`plume_atmosphere.wind`), at the tick's sim time
and the vehicle's position in that tick's state, so the anemometer reads the very air
velocity the physics applies as drag over that tick. The noise is Gaussian, ``noise_std_m_s``
on each axis, drawn from a generator seeded by (scenario seed, vehicle index, tick): the same
reading at the same tick in every run, also after a physics restart replays ticks. Readings
go out every ``period_ticks`` control ticks on ``vehicle/<id>/wind`` (0: no anemometer).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from plume_atmosphere.wind import WindModel
from swarmbus.messages import AnemometerReading
from swarmbus.scenario import AnemometerSpec

Vec3 = tuple[float, float, float]
_STREAM = 0xA7E

# numpy's SeedSequence (pool of 4 words; its algorithm is fixed, NEP 19) and PCG64's seeding
_M32 = 0xFFFFFFFF
_INIT_A, _MULT_A, _INIT_B, _MULT_B = 0x43B0D7E5, 0x931E8875, 0x8B51F9DD, 0x58F38DED
_MIX_L, _MIX_R = 0xCA01F9DD, 0x4973F715
_PCG_MULT = (2549297995355413924 << 64) + 4865540595714422341
_M128 = (1 << 128) - 1
#: Ticks whose generators are seeded at once.
SEED_BLOCK = 256

Words = npt.NDArray[np.uint64]


def _words(value: int) -> list[int]:
    """``value`` as SeedSequence takes an integer: 32-bit words, least significant first."""
    out = [value & _M32]
    value >>= 32
    while value:
        out.append(value & _M32)
        value >>= 32
    return out


def _pcg64_states(prefix: list[int], ticks: Words) -> Words:
    """(len(ticks), 4) words ``PCG64(SeedSequence([*prefix, tick]))`` draws its state from
    (``SeedSequence.generate_state(4, np.uint64)``), for ticks below 2³², all ticks at once:
    SeedSequence's hash of its entropy words, in 64-bit arithmetic masked to 32 bits."""
    # every word as an array of the ticks' shape: wrapping array arithmetic, no scalar overflow
    entropy = [np.full(ticks.shape, w, dtype=np.uint64) for v in prefix for w in _words(v)]
    entropy.append(ticks)
    h = _INIT_A

    def hashmix(value: Words) -> Words:
        nonlocal h
        value = np.bitwise_xor(value, np.uint64(h))
        h = (h * _MULT_A) & _M32
        value = (value * np.uint64(h)) & np.uint64(_M32)
        return np.asarray(value ^ (value >> np.uint64(16)), dtype=np.uint64)

    def mix(x: Words, y: Words) -> Words:
        r = (np.uint64(_MIX_L) * x - np.uint64(_MIX_R) * y) & np.uint64(_M32)
        return np.asarray(r ^ (r >> np.uint64(16)), dtype=np.uint64)

    zero = np.zeros(ticks.shape, dtype=np.uint64)
    pool = [hashmix(entropy[i] if i < len(entropy) else zero) for i in range(4)]
    for src in range(4):
        for dst in range(4):
            if src != dst:
                pool[dst] = mix(pool[dst], hashmix(pool[src]))
    for word in entropy[4:]:
        for dst in range(4):
            pool[dst] = mix(pool[dst], hashmix(word))
    h = _INIT_B
    halves = []
    for i in range(8):
        value = pool[i % 4] ^ np.uint64(h)
        h = (h * _MULT_B) & _M32
        value = (value * np.uint64(h)) & np.uint64(_M32)
        halves.append(value ^ (value >> np.uint64(16)))
    out = np.empty((ticks.shape[0], 4), dtype=np.uint64)
    for i in range(4):
        out[:, i] = halves[2 * i] | (halves[2 * i + 1] << np.uint64(32))
    return out


class SeededNormals:
    """``Generator(PCG64(SeedSequence([*prefix, tick]))).normal(0, std, 3)`` for any tick, bit for
    bit, without building a SeedSequence and a PCG64 per tick (≈ 35 µs): the seeding of
    ``SEED_BLOCK`` consecutive ticks is hashed in one numpy pass and one generator takes each
    tick's state in turn."""

    def __init__(self, prefix: tuple[int, ...]) -> None:
        self.prefix = list(prefix)
        self._block = -1
        self._states: Words = np.empty((0, 4), dtype=np.uint64)
        self._bits = np.random.PCG64(0)
        self._rng = np.random.Generator(self._bits)

    def normal(self, tick: int, std: float) -> npt.NDArray[np.float64]:
        if not 0 <= tick <= _M32:
            rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([*self.prefix, tick])))
            return rng.normal(0.0, std, 3)
        block = tick // SEED_BLOCK
        if block != self._block:
            first = block * SEED_BLOCK
            ticks = np.arange(first, min(first + SEED_BLOCK, _M32 + 1), dtype=np.uint64)
            self._states = _pcg64_states(self.prefix, ticks)
            self._block = block
        s0, s1, i0, i1 = self._states[tick - block * SEED_BLOCK].tolist()
        # pcg_setseq_128_srandom_r(initstate = s0·2⁶⁴ + s1, initseq = i0·2⁶⁴ + i1)
        inc = (((i0 << 64) | i1) << 1 | 1) & _M128
        state = ((inc + ((s0 << 64) | s1)) * _PCG_MULT + inc) & _M128
        self._bits.state = {
            "bit_generator": "PCG64",
            "state": {"state": state, "inc": inc},
            "has_uint32": 0,
            "uinteger": 0,
        }
        return self._rng.normal(0.0, std, 3)


class Anemometer:
    """One vehicle's anemometer."""

    def __init__(
        self, config: AnemometerSpec, wind: WindModel, scenario_seed: int, vehicle_index: int
    ) -> None:
        self.config = config
        self.wind = wind
        self._seed = (scenario_seed, vehicle_index, _STREAM)
        self._normals = SeededNormals(self._seed)

    def due(self, tick: int) -> bool:
        period = self.config.period_ticks
        return period > 0 and tick % period == 0

    def read(
        self, vehicle_id: str, tick: int, sim_time_s: float, position: Vec3
    ) -> AnemometerReading:
        uniform = self.wind.uniform_at(sim_time_s)  # the same everywhere: no lookup
        if uniform is None:
            v = self.wind.velocity([position], sim_time_s)[0]
            true = (float(v[0]), float(v[1]), float(v[2]))
        else:
            true = (float(uniform[0]), float(uniform[1]), float(uniform[2]))
        measured = true
        if self.config.noise_std_m_s > 0.0:
            # the float64 sums numpy's add of the two vectors gives, without building arrays
            n = self._normals.normal(tick, self.config.noise_std_m_s).tolist()
            measured = (true[0] + n[0], true[1] + n[1], true[2] + n[2])
        return AnemometerReading(
            vehicle_id=vehicle_id,
            sim_time_s=sim_time_s,
            position_enu_m=position,
            wind_enu_m_s=measured,
            true_wind_enu_m_s=true,
        )
