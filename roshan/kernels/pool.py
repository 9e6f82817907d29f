"""Pooled simulator bundles: the Taichi objects behind an env, kept for the next env of the same build.

Taichi never frees a field tree before ``ti.reset()`` (and one process holds at most 512), and a
``@ti.data_oriented`` object compiles its kernels for itself: a new env of an already-built shape used to cost
~20 MB of fields that stayed after ``close()`` and seconds of compiling. So an env takes its simulators (FireSim,
DroneSims, ExploreMaps, task kernels, renderer) from here and gives them back on ``close()`` (or when it is
garbage collected); the next env with the same *build key* gets them back, compiled, with every field restored
to its freshly constructed values, so its trajectories are bit-identical to those of brand-new simulators.

The build key is everything that decides field shapes and compile-time constants: map contents, the config
sections the simulators read, the number of envs and, for the planner, its level settings and the policies'
frame counts. The seed is not part of it (it is a kernel argument). The pool belongs to the Taichi runtime
(:func:`roshan.runtime.for_this_runtime`): a reset starts a new, empty one, since the objects die with the runtime.
"""

import hashlib
import warnings
import weakref
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import taichi as ti

from roshan.config import CONTROLLERS, Config, FlyConfig, PlannerConfig
from roshan.kernels.drones import DroneSim
from roshan.kernels.episode import EpisodeKernels
from roshan.kernels.explore import ExploreMaps, meander_length
from roshan.kernels.fire import FireSim
from roshan.kernels.fire_layout import FireSizes, choose_parallel, fire_sizes
from roshan.kernels.fly import FlyKernels, time_limit
from roshan.kernels.planner import PlannerKernels, candidate_count, planner_time_limit
from roshan.kernels.render import EnvZeroFrames
from roshan.maps import LandCoverMap
from roshan.memory import check_fits, format_bytes
from roshan.runtime import current_arch, ensure_taichi, for_this_runtime

# ---------------------------------------------------------------------------------------------- bundles


@dataclass(eq=False)
class FlySims:
    """What a FlyVectorEnv simulates with."""

    fire: FireSim
    drones: DroneSim
    kernels: FlyKernels
    viewer: EnvZeroFrames
    t_max: int


@dataclass(eq=False)
class PlannerSims:
    """What a PlannerVectorEnv simulates with."""

    fire: FireSim
    drones: DroneSim
    explorers: DroneSim
    maps: ExploreMaps
    kernels: PlannerKernels
    viewer: EnvZeroFrames
    t_max: int
    max_candidates: int


@dataclass(frozen=True)
class Estimate:
    """What a bundle would allocate, worked out before anything is: its bytes (fields, host arrays and the pool's
    pristine copies), the fire's sizes, and the settings that make it smaller beyond the fire's."""

    bytes: int
    fire: FireSizes
    ways_out: tuple[str, ...] = ()


def fire_estimate(land: LandCoverMap, cfg: Config, num_envs: int) -> tuple[int, FireSizes]:
    """Bytes of a bundle's FireSim (its pristine copy included) and its sizes."""
    z = fire_sizes(land.rows, land.cols, cfg.fire, cfg.ignition, num_envs)
    chunked = choose_parallel(cfg.fire.parallel, num_envs, z.num_fires) == "chunks"
    return z.estimate_bytes(chunked) + z.pristine_bytes(), z


def fly_estimate(land: LandCoverMap, cfg: Config, num_envs: int) -> Estimate:
    """What :func:`take_fly_sims` would allocate for ``num_envs`` envs (the renderer, made at the first frame,
    aside)."""
    fire_bytes, z = fire_estimate(land, cfg, num_envs)
    drones = DroneSim.field_bytes(num_envs, cfg.drones)
    return Estimate(fire_bytes + drones + EpisodeKernels.field_bytes(num_envs), z)


def planner_estimate(land: LandCoverMap, cfg: Config, pc: PlannerConfig, num_envs: int) -> Estimate:
    """What :func:`take_planner_sims` would allocate for ``num_envs`` envs (the renderer aside)."""
    fire_bytes, z = fire_estimate(land, cfg, num_envs)
    k = candidate_count(pc, cfg.drones, land.rows * land.cols)
    max_len = meander_length(land.rows, land.cols, pc.num_explorers, pc.explorer_view_range, pc.meander)
    total = (fire_bytes + DroneSim.field_bytes(num_envs, cfg.drones)
             + DroneSim.field_bytes(num_envs, pc.explorer_drones(cfg.drones))
             + ExploreMaps.field_bytes(num_envs, land.rows, land.cols, pc.num_explorers, max_len)
             + PlannerKernels.field_bytes(num_envs, cfg.drones.num_drones, k))
    return Estimate(total, z, (f"a smaller planner.max_candidates (now {k:,} per env)",))


def take_fly_sims(land: LandCoverMap, cfg: Config, fly: FlyConfig, num_envs: int, seed: int,
                  owner: object, extra_bytes: int = 0,
                  who: str = "FlyVectorEnv") -> tuple[FlySims, Callable[[], None]]:
    """FlyAgent simulators for ``owner`` (an env), pooled or new, and the call that gives them back.

    The give-back call is idempotent and also runs when ``owner`` is garbage collected, so an env that is
    dropped without ``close()`` still returns its simulators. A new bundle is first estimated, with the
    ``extra_bytes`` the caller will allocate next to it, and refused (MemoryLimitError, naming ``who``) where
    that would not fit in the memory available.
    """
    key = ("fly", land_key(land), cfg.fire, cfg.wind, cfg.ignition, cfg.drones, fly, num_envs)

    def build() -> FlySims:
        fire = FireSim(land, cfg.fire, cfg.wind, cfg.ignition, num_envs=num_envs, seed=seed, check_memory=False)
        drones = DroneSim(fire, cfg.drones)
        t_max = time_limit(land.rows, land.cols, land.cell_size, cfg.fire.dt, cfg.drones.max_speed,
                           cfg.ignition.fire_percentage, fly)
        return FlySims(fire, drones, FlyKernels(fire, drones, fly, t_max), EnvZeroFrames(drones), t_max)

    return current_pool().take(key, build, lambda: fly_estimate(land, cfg, num_envs), extra_bytes, who, land, seed,
                               owner)


def take_planner_sims(land: LandCoverMap, cfg: Config, pc: PlannerConfig, num_envs: int, seed: int, *,
                      controller: str, evaluation: bool, fly_frames: int, explore_frames: int,
                      owner: object, extra_bytes: int = 0,
                      who: str = "PlannerVectorEnv") -> tuple[PlannerSims, Callable[[], None]]:
    """PlannerAgent simulators (planner drones, explorers, fire map, planner kernels), pooled or new, and the
    call that gives them back (see :func:`take_fly_sims`, also for the memory check)."""
    if controller not in CONTROLLERS:
        raise ValueError(f"controller must be one of {', '.join(CONTROLLERS)}, got {controller!r}")
    key = ("planner", land_key(land), cfg.fire, cfg.wind, cfg.ignition, cfg.drones, pc, num_envs, controller,
           evaluation, fly_frames, explore_frames)

    def build() -> PlannerSims:
        fire = FireSim(land, cfg.fire, cfg.wind, cfg.ignition, num_envs=num_envs, seed=seed, check_memory=False)
        drones = DroneSim(fire, cfg.drones, lands=True)  # the planner level's landing rule (every controller)
        explorers = DroneSim(fire, pc.explorer_drones(cfg.drones))
        maps = ExploreMaps(fire, explorers, pc.num_explorers, pc.explorer_view_range, version=pc.meander,
                           index_bound=pc.explorer_index_bound)
        t_max = planner_time_limit(land.rows, land.cols, land.cell_size, cfg.fire.dt, cfg.drones.max_speed,
                                   cfg.ignition.fire_percentage, pc.time_limit)
        kernels = PlannerKernels(fire, drones, explorers, maps, pc, controller=controller, evaluation=evaluation,
                                 t_max=t_max, fly_frames=fly_frames, explore_frames=explore_frames)
        viewer = EnvZeroFrames(drones, explorers, maps.fire_map)
        return PlannerSims(fire, drones, explorers, maps, kernels, viewer, t_max, kernels.K)

    return current_pool().take(key, build, lambda: planner_estimate(land, cfg, pc, num_envs), extra_bytes, who, land,
                               seed, owner)


def land_key(land: LandCoverMap) -> tuple:
    """A map's identity for the pool: its contents and cell size (the name and georeferencing change no field)."""
    digest = hashlib.sha1(np.ascontiguousarray(land.classes).tobytes()).hexdigest()
    return land.classes.shape, digest, float(land.cell_size), bool(land.is_uniform)


# ---------------------------------------------------------------------------------------------- the pool


class Pristine:
    """The freshly constructed state of some objects: their Python attributes (e.g. ``FireSim.seed``) and the
    values of every Taichi field they hold.

    All fields go through three kernels compiled once per bundle (per-field ``to_numpy``/``fill`` would compile
    one kernel per field: ~6 s for a FlyAgent bundle). Fields that are all zero after construction are zeroed
    on restore; the others (maps, class tables, random tables, ...) are copied back from a saved copy, which is
    small. Construction restores once so every kernel is compiled with the bundle, not at its first reuse.
    """

    def __init__(self, objects: list[object]):
        self.attrs = [(obj, dict(vars(obj))) for obj in objects]
        fields = _fields_of(objects)
        flags = np.zeros(len(fields), np.int32)
        _unrolled(_flag_nonzero, fields, flags)
        self.zero = tuple(f for f, nz in zip(fields, flags, strict=True) if not nz)
        self.live = tuple(f for f, nz in zip(fields, flags, strict=True) if nz)
        self.saved = tuple(_field_like(f) for f in self.live)
        _unrolled(_copy, self.live, self.saved)
        self.restore()

    def restore(self) -> None:
        for obj, attrs in self.attrs:
            vars(obj).update(attrs)
        _unrolled(_restore, self.zero, self.saved, self.live)


@dataclass(eq=False)
class _Entry:
    sims: FlySims | PlannerSims
    pristine: Pristine


class SimulatorPool:
    """The free bundles of one Taichi runtime, per build key. A bundle given back after its runtime was reset
    goes to that runtime's pool, which nobody asks any more."""

    def __init__(self):
        self.free: dict[tuple, list[_Entry]] = {}

    def take(self, key: tuple, build: Callable[[], FlySims | PlannerSims], estimate: Callable[[], Estimate],
             extra_bytes: int, who: str, land: LandCoverMap, seed: int,
             owner: object) -> tuple[FlySims | PlannerSims, Callable[[], None]]:
        free = self.free.get(key)
        if free:
            check_fits(who, extra_bytes, ["fewer envs (--envs / sim.envs)"], current_arch())
            entry = free.pop()
            entry.pristine.restore()
        else:
            est = estimate()
            need = est.bytes + extra_bytes
            z = est.fire
            check_fits(f"{who}: {z.describe(land.name)}, about {format_bytes(need / z.num_envs)} per env,", need,
                       [*z.ways_out(), *est.ways_out], current_arch())
            sims = build()
            entry = _Entry(sims, Pristine(_simulators(sims)))
        entry.sims.fire.restart_streams(seed)
        entry.sims.fire.relabel(land)  # same contents; keep the caller's name and georeferencing
        give_back = weakref.finalize(owner, self.give_back, key, entry)
        give_back.atexit = False  # nothing to return at interpreter exit
        return entry.sims, give_back

    def give_back(self, key: tuple, entry: _Entry) -> None:
        self.free.setdefault(key, []).append(entry)

    def count(self) -> int:
        return sum(len(v) for v in self.free.values())


def current_pool() -> SimulatorPool:
    """The pool of the current Taichi runtime."""
    ensure_taichi()
    return for_this_runtime("simulator pool", SimulatorPool)


def pooled_count() -> int:
    """Bundles waiting in the pool (tests)."""
    return current_pool().count()


def _simulators(sims: FlySims | PlannerSims) -> list[object]:
    """The objects whose fields and attributes make a bundle's state, each drone group's parts included
    (:meth:`DroneSim.parts`). The viewer is left out: its fields are allocated at the first render and repainted
    whole by every render."""
    objects = [v for v in vars(sims).values() if isinstance(v, (FireSim, DroneSim, ExploreMaps, FlyKernels,
                                                                PlannerKernels))]
    return objects + [part for v in objects if isinstance(v, DroneSim) for part in v.parts()]


def _fields_of(objects: list[object]) -> tuple:
    seen: dict[int, ti.Field] = {}
    for obj in objects:
        for v in vars(obj).values():
            if isinstance(v, ti.Field):
                seen.setdefault(id(v), v)
    return tuple(seen.values())


def _field_like(f: ti.Field) -> ti.Field:
    if isinstance(f, ti.MatrixField):
        return ti.Matrix.field(f.n, f.m, f.dtype, f.shape) if f.ndim == 2 else ti.Vector.field(f.n, f.dtype, f.shape)
    return ti.field(f.dtype, f.shape)


# Fields are template arguments: each kernel is unrolled over a bundle's fields (one parallel loop per field)
# and compiled once per bundle.


def _unrolled(kernel, *args) -> None:
    """Launch a kernel unrolled over many fields without Taichi's compile-time warning about long unrolling
    (one loop per field compiles fast; the warning is about deep static loops)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="You are unrolling", category=SyntaxWarning)
        kernel(*args)


@ti.kernel
def _flag_nonzero(fields: ti.template(), flags: ti.types.ndarray(dtype=ti.i32, ndim=1)):
    for k in ti.static(range(len(fields))):
        for i in ti.grouped(fields[k]):
            if ti.static(isinstance(fields[k], ti.MatrixField)):
                if (fields[k][i] != 0).any():
                    flags[k] = 1
            elif fields[k][i] != 0:
                flags[k] = 1


@ti.kernel
def _copy(src: ti.template(), dst: ti.template()):
    for k in ti.static(range(len(src))):
        for i in ti.grouped(src[k]):
            dst[k][i] = src[k][i]


@ti.kernel
def _restore(zero: ti.template(), saved: ti.template(), live: ti.template()):
    for k in ti.static(range(len(zero))):
        for i in ti.grouped(zero[k]):
            zero[k][i] = _zero_of(zero[k])
    for k in ti.static(range(len(live))):
        for i in ti.grouped(live[k]):
            live[k][i] = saved[k][i]


@ti.func
def _zero_of(f: ti.template()):
    """A zero element of field f's type."""
    if ti.static(not isinstance(f, ti.MatrixField)):
        return ti.cast(0, f.dtype)
    elif ti.static(f.ndim == 2):
        return ti.Matrix.zero(f.dtype, f.n, f.m)
    else:
        return ti.Vector.zero(f.dtype, f.n)
