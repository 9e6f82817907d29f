"""The simulator's sections: map, fire physics, wind, initial fires, drones, batch and arch."""

import math
from dataclasses import dataclass, field

from roshan.config.schema import INT32_MAX, ConfigError, Section, choice, num
from roshan.episode import EXTRA_COLUMNS, Column

# Upper bounds of the pool sizes: a particle pool of 2^26 (1.3-2.1 GiB per env) serves a map of ~80 million cells
# burning whole (the reference peaks at 0.4 convection and 0.8 radiation particles per cell), and 2^24 blocks hold
# 2^30 cell records (32-bit indices). Larger values are typing mistakes; they used to end in a traceback or fill
# the machine's memory.
MAX_PARTICLES = 1 << 26
MAX_BLOCKS = 1 << 24


@dataclass(frozen=True)
class ConvectionConfig(Section):
    """Convection particles: Langevin SDE for hot gas / embers (docs/model/fire.md §7.1)."""

    enabled: bool = True  # emit_convective
    y_st: float = num(1.0, 0.0, lo_open=True, doc="initial intensity")
    y_lim: float = num(0.2, 0.0, lo_open=True, doc="intensity below which a particle dies")
    fl: float = num(0.15, 0.0, doc="position scaling factor F_l")
    c0: float = num(1.98, 0.0, doc="Kolmogorov-like constant C_0")
    tau_mem: float = num(10.0, 0.0, lo_open=True, doc="intensity decay time (s)")
    lt: float = num(80.0, 0.0, lo_open=True, doc="integral length scale L_t (m)")


@dataclass(frozen=True)
class RadiationConfig(Section):
    """Radiation particles: random walk on a slowly growing circle (docs/model/fire.md §7.2)."""

    enabled: bool = True  # emit_radiation
    y_st: float = num(1.0, 0.0, lo_open=True, doc="initial intensity")
    y_lim: float = num(0.165, 0.0, lo_open=True, doc="intensity below which a particle dies")


@dataclass(frozen=True)
class FireConfig(Section):
    """The FireSPIN cellular automaton (docs/model/fire.md §1-8)."""

    dt: float = num(0.1, 0.0, 10.0, lo_open=True, doc="time step (s)")
    flood_duration: float = num(5.0, 0.0, doc="how long a flooded cell stays flooded (s)")
    uniform_ignition_time: float = num(100.0, 0.0, lo_open=True, doc="tau_ign on the uniform map (s)")
    uniform_burning_time: float = num(120.0, 0.0, lo_open=True, doc="tau_burn on the uniform map (s)")
    convection: ConvectionConfig = field(default_factory=ConvectionConfig)
    radiation: RadiationConfig = field(default_factory=RadiationConfig)
    conv_capacity: int = num(0, 0, MAX_PARTICLES, doc="convection particles per env; 0 = auto from the map size")
    rad_capacity: int = num(0, 0, MAX_PARTICLES, doc="radiation particles per env; 0 = auto from the map size")
    layout: str = choice("auto", ("auto", "dense", "sparse"),
                         doc="cell records: every cell (dense), or 8x8 blocks taken from a per-env pool when fire, "
                             "particles or water first touch them (sparse: far less memory on a big map, "
                             "~0.67x the updates per second); auto = sparse where the pool is under half the map "
                             "and the dense records of all envs would take over 1 GiB")
    parallel: str = choice("auto", ("auto", "envs", "chunks"),
                           doc="how an update spreads over CPU threads: a thread per env, each env's lists "
                               "serially (envs), or each env's particle and cell lists cut into chunks over all "
                               "threads (chunks, for fewer envs than threads on a big map); the same trajectory "
                               "bit for bit. auto = chunks on the CPU where E < threads and an env lights >= 250,000 "
                               "fires (where it measured faster)")
    block_capacity: int = num(0, 0, MAX_BLOCKS,
                              doc="8x8 blocks per env in the sparse layout; 0 = auto from the map size and "
                                        "ignition.fire_percentage (a full pool is counted as dropped_blocks)")


@dataclass(frozen=True)
class WindConfig(Section):
    """Constant wind per episode (docs/model/fire.md §6)."""

    speed: float = num(10.0, 0.0, 100.0, doc="10-m wind speed U_w (m/s)")
    direction: float = num(-1.0, -1.0, 360.0, hi_open=True,
                           doc="degrees from the row axis (south) towards the column axis (east); -1 = random")
    turbulence: float = num(0.314, 0.0, doc="turbulence ratio a (u' = a * U_w)")


@dataclass(frozen=True)
class IgnitionConfig(Section):
    """The initial fire generator (docs/model/fire.md §11): the newest code's, or the thesis era's with
    ``reseed: false``."""

    fire_percentage: float = num(0.015, 0.0, 1.0, doc="fraction of all cells to ignite")
    clusters: int = num(2, 1, INT32_MAX, doc="number of clusters (or rings)")
    spread_prob: float = num(0.5, 0.0, 1.0, doc="base probability that a cluster grows into a neighbour")
    noise: float = num(1.0, 0.0, 2.0, doc="amplitude of the perturbation of spread_prob")
    pattern: str = choice("cluster", ("cluster", "scattered", "ring", "random"),
                          doc="cluster: spreading clusters; scattered: single cells anywhere; ring: annuli around "
                              "random centres; random: one of the three, drawn per episode")
    reseed: bool = True  # newest code: re-seed a trapped cluster until it has its share; false = thesis era (a maximum)


# Energy presets: a battery of ``capacity`` joules drained by P = hover_power + speed_power * |v|^2 (+ payload_power
# times the tank's fill with the water limit), the multirotor form: induced power at hover plus a parasitic term that
# grows with airspeed. "scenario" is scaled to 35x36_Woods (350 x 360 m; the far corner is 35 s from the
# groundstation at full speed, an episode without batteries 50-120 s): a full battery lasts 88 s at full speed (170 W)
# and 125 s hovering, so every cell can be reached and flown back from, and a drone returns to swap about once or twice
# an episode. "off" is the original: drones fly forever.
# "realistic" is a named firefighting multirotor at full scale, the Skydrone M50 (its maker's published figures,
# skydronetech.com/product/m50.html: 50 kg payload of hose or extinguishing agent, 18S 62,000 mAh battery, flight time
# "25~60 mins", 8-20 m/s): 66.6 V x 62 Ah = 14.86 MJ; 60 min hovering empty gives 4,129 W, 25 min with the full 50 kg
# gives 9,909 W, so a full tank adds 5,780 W. Two figures are ours, not the maker's: the speed term (2 W s^2/m^2, +10 %
# at 14 m/s) and the swap (120 s for a spare pack; the maker states only 1-1.5 h to charge one).
ENERGY_PRESETS: dict[str, dict[str, float]] = {
    "scenario": {"capacity": 15000.0, "hover_power": 100.0, "speed_power": 0.25, "payload_power": 20.0,
                 "swap_time": 3.0},
    "realistic": {"capacity": 14_864_000.0, "hover_power": 4129.0, "speed_power": 2.0, "payload_power": 5780.0,
                  "swap_time": 120.0},
}


@dataclass(frozen=True)
class EnergyConfig(Section):
    """Flight endurance: a preset (off: unlimited, the original) and any of its values overridden here."""

    preset: str = choice("off", ("off", *ENERGY_PRESETS),
                         doc="off: drones fly forever (the original); scenario: an 88 s battery (full speed) on "
                             "35x36_Woods, swapped in 3 s; realistic: the Skydrone M50 firefighting multirotor "
                             "(25 min with its 50 kg payload, 60 min empty, a 120 s swap)")
    capacity: float | None = num(None, 0.0, lo_open=True, doc="battery energy (J)")
    hover_power: float | None = num(None, 0.0, doc="power drawn hovering with an empty tank (W)")
    speed_power: float | None = num(None, 0.0, doc="extra power per (m/s)^2 of ground speed (W s^2 / m^2)")
    payload_power: float | None = num(None, 0.0, doc="extra power with a full tank (W), scaled by the tank's fill "
                                                     "with the water limit (else always full)")
    swap_time: float | None = num(None, 0.0, doc="seconds on the groundstation cell to swap in a full battery")
    approach: float = num(2.0, 0.0, was=0.0,
                          doc="cells from the groundstation's centre within which a drone flying home (with the "
                              "landing rule of the planner level) flies the final approach straight in, out of the "
                              "others' way: like a landed drone it neither sees nor is seen by them, nor the map's "
                              "edge (0: none, the FlyAgent flies it up to the cell, where drones arriving together "
                              "can keep each other off it)")

    def __post_init__(self):
        super().__post_init__()
        if not self.enabled:  # a value of no battery would be ignored: the drones would fly forever
            for key in ENERGY_PRESETS["scenario"]:
                if getattr(self, key) is not None:
                    raise ConfigError(
                        f"EnergyConfig: drones.energy.{key} = {getattr(self, key)!r} is set but drones.energy.preset "
                        "is off (no battery: drones fly forever); choose the preset it overrides "
                        f"(drones.energy.preset={' or '.join(ENERGY_PRESETS)}) or leave {key} unset")

    @property
    def enabled(self) -> bool:
        return self.preset != "off"

    def values(self) -> dict[str, float]:
        """The preset's values with this section's overrides (empty when off)."""
        if not self.enabled:
            return {}
        preset = ENERGY_PRESETS[self.preset]
        return {k: preset[k] if getattr(self, k) is None else float(getattr(self, k)) for k in preset}


def parse_base_cells(text: str) -> tuple[tuple[int, int], ...]:
    """``drones.base_cells`` ("row,col; row,col") as cells, or a ConfigError naming the key and the bad part."""
    cells = []
    for part in text.replace(" ", "").strip(";").split(";"):
        if not part:
            continue
        try:
            row, col = (int(v) for v in part.split(","))
        except ValueError:
            raise ConfigError(f"DroneConfig: drones.base_cells = {text!r}: expected cells as 'row,col; row,col' "
                              f"(whole numbers), got {part!r}") from None
        if row < 0 or col < 0:
            raise ConfigError(f"DroneConfig: drones.base_cells = {text!r}: cell {part!r} has a negative index")
        cells.append((row, col))
    if len(set(cells)) != len(cells):
        raise ConfigError(f"DroneConfig: drones.base_cells = {text!r} names a cell twice")
    return tuple(cells)


@dataclass(frozen=True)
class DroneConfig(Section):
    """FlyAgent drones (docs/model/agents.md §1, §3, §4, §14): physics, sensing, start layout and water."""

    num_drones: int = num(4, 1, 64, doc="drones per env")
    max_speed: float = num(10.0, 0.0, lo_open=True, doc="v_max per axis (m/s)")
    view_range: int = num(10, 2, INT32_MAX, doc="view range (cells)")
    drone_size: float = num(2.0, 0.0, lo_open=True, doc="drone radius used by the collision test (m)")
    use_vel_bins: bool = True  # actions rounded to 41 levels (steps of 0.05)
    use_velocity_change: bool = False  # acceleration mode: v += a * (v_max / 2) * dt
    groundstation_start_percentage: float = num(1.0, 0.0, 1.0, doc="chance a drone starts at the groundstation")
    bases: int = num(1, 1, 4, doc="groundstations per env, each one cell inside a corner of the map: the first in a "
                                  "random corner (the drones start there), the others in the opposite corner, then "
                                  "the other corner of the first's row, then that of its column (docs/model/agents.md "
                                  "§4.1); a drone restocks at any of them and flies home to the nearest")
    base_cells: str = ""  # the bases' cells "row,col; row,col" in place of the corner rule (drones.bases of them)
    use_water_limit: bool = False  # finite tank, newest code (docs/model/agents.md §14); off in the thesis experiments
    water_capacity: float = num(4.0, 0.0, lo_open=True, doc="tank size in drops (one drop puts out one cell)")
    recharge_time: float = num(2.0, 0.0, doc="seconds an empty tank takes to refill at the groundstation")
    energy: EnergyConfig = field(default_factory=EnergyConfig)

    def __post_init__(self):
        super().__post_init__()
        cells = self.explicit_bases  # a malformed list is refused here, naming the key
        if cells and len(cells) != self.bases:
            raise ConfigError(f"DroneConfig: drones.base_cells lists {len(cells)} cell(s) ({self.base_cells!r}) but "
                              f"drones.bases = {self.bases}: set drones.bases = {len(cells)}")

    @property
    def explicit_bases(self) -> tuple[tuple[int, int], ...]:
        """The cells (row, col) of ``base_cells``, the first the drones' start; () for the corner rule."""
        return parse_base_cells(self.base_cells)

    # The keys that shape a network seeing the whole fleet in one row (the planner's): the number of drones, and
    # whether they carry a battery (a property of the section: with one the observation has an energy part whatever
    # the preset, the charge being a fraction of a full battery, so a planner trained on `scenario` serves
    # `realistic`).
    FLEET_SHAPE_KEYS = ("drones.num_drones", "drones.energy.enabled")

    def fleet_shape(self) -> dict:
        """What such a network is built for, as those keys decide it: ``num_drones``, and ``resources``: each
        drone's observation has an energy part."""
        return {"num_drones": self.num_drones, "resources": self.energy.enabled}

    def inert(self) -> list[str]:
        """Settings that change nothing here, each as a warning line: set but silent, they read as if
        they had been applied."""
        # 0 asks for no approach and the default is nobody's choice: any other value was set to be used
        if not self.energy.enabled and self.energy.approach not in (0.0, EnergyConfig().approach):
            return [f"drones.energy.approach = {self.energy.approach!r} does nothing while drones.energy.preset is "
                    "off: only a drone flying home to swap its battery makes the final approach"]
        return []

    @property
    def step_durations(self) -> dict[str, float]:
        """Dotted key -> seconds of the durations the kernels count in steps of ``fire.dt`` (a tank's refill, a
        battery swap), which the whole config checks against its step counters."""
        return {"drones.recharge_time": self.recharge_time,
                "drones.energy.swap_time": self.energy.values().get("swap_time", 0.0)}

    @property
    def failures(self) -> tuple[str, ...]:
        """The failures the drones bring to a level's (:data:`roshan.episode.REASONS`): "lost" with a battery."""
        return ("lost",) if self.energy.enabled else ()

    @property
    def counted_columns(self) -> tuple[Column, ...]:
        """The record's extra columns these drones count (:data:`roshan.episode.EXTRA_COLUMNS`, the battery's):
        all of them with a battery, none without (they stay zero)."""
        return EXTRA_COLUMNS if self.energy.enabled else ()

    def battery_reach(self) -> float | None:
        """Metres from the groundstation a full battery can take a drone and bring it back, at the speed that goes
        farthest on a joule (at most v_max on both axes) with the tank full; None without a battery. No fire
        farther than this can be put out."""
        if not self.energy.enabled:
            return None
        e = self.energy.values()
        still = e["hover_power"] + e["payload_power"]  # power at rest; the speed term grows with |v|^2
        fastest = math.sqrt(2.0) * self.max_speed
        speed = fastest if e["speed_power"] == 0 else min(fastest, math.sqrt(still / e["speed_power"]))
        power = still + e["speed_power"] * speed * speed
        return math.inf if power == 0 else e["capacity"] / power * speed / 2.0


@dataclass(frozen=True)
class MapConfig(Section):
    """Which land-cover map to simulate."""

    name: str = "35x36_Woods"  # bundled map name, "uniform", or a path to a CLC+ GeoTIFF
    band: int = num(0, 0, doc="raster band (1-based) for multi-band files; 0 = the only band")
    uniform_rows: int = num(50, 1, INT32_MAX, doc="rows of the uniform map")
    uniform_cols: int = num(50, 1, INT32_MAX, doc="columns of the uniform map")


@dataclass(frozen=True)
class SimConfig(Section):
    """Batch size, seed and where the kernels run: for every command (simulate, train, study trials)."""

    envs: int = num(1, 1, doc="environments advanced together (training: the batch the learner collects from)")
    seed: int = num(0, 0, 2**31 - 1, doc="seed of every random stream (training: also of torch and the shuffles)")
    arch: str = choice("cpu", ("cpu", "cuda", "vulkan", "auto"),
                       doc="where the kernels run (--arch): auto = CUDA where present, else the CPU; vulkan is "
                           "refused (its fire kernels run wrong)")
    threads: int = num(0, 0, doc="CPU threads; 0 = all cores")
