"""The agents' sections: the FlyAgent task, the planner level and the reward coefficients of both.

Reward presets are data (thesis Tables 5.3-5.5, 5.7, 5.9); the ``ti.func``s that pay them live in
:mod:`roshan.kernels.rewards`.
"""

from dataclasses import dataclass, field, replace

from roshan.config.levels import ANY_FLEET_NETWORKS
from roshan.config.schema import INT32_MAX, ConfigError, Section, choice, num
from roshan.config.sim import DroneConfig, EnergyConfig

# Thesis Table 5.3 (defaults), Table 5.4 (best single Optuna trial), Table 5.5 (mean of the top-10 trials).
PRESETS: dict[str, dict[str, float]] = {
    "thesis": {"goal": 1.0, "boundary": -1.0, "extinguish": 0.01, "timeout": -1.0, "collision": -1.0,
               "progress": 0.1, "proximity": -0.05},
    "optuna_best": {"goal": 0.230, "boundary": -4.737, "extinguish": 0.0128, "timeout": -3.050,
                    "collision": -4.737, "progress": 0.278, "proximity": -0.189},
    "optuna_top10": {"goal": 0.8785929835, "boundary": -4.3280085652, "extinguish": 0.0072352109,
                     "timeout": -3.7322366112, "collision": -4.3280085652, "progress": 0.2955909834,
                     "proximity": -0.1150000819},
}


@dataclass(frozen=True)
class RewardConfig(Section):
    """A preset of coefficients; any field set here overrides the preset's value."""

    preset: str = choice("thesis", tuple(PRESETS),
                         doc="coefficients: thesis (Table 5.3), optuna_best (5.4) or optuna_top10 (5.5)")
    goal: float | None = None  # GoalReached
    boundary: float | None = None  # BoundaryTerminal
    extinguish: float | None = None  # Extinguish (complex policy)
    timeout: float | None = None  # TimeOut
    collision: float | None = None  # Collision (collision mode)
    progress: float | None = num(None, 0.0, doc="DistanceImprovement per grid unit of progress")
    proximity: float | None = None  # ProximityPenalty (collision mode)


@dataclass(frozen=True)
class FlyConfig(Section):
    """The FlyAgent task (docs/model/agents.md §5-9)."""

    policy: str = choice("simple", ("simple", "complex"))  # simple: reach the goal; complex: put every fire out
    collision: bool = False  # collisions terminate (and the collision reward terms apply)
    time_limit: str = choice("newest", ("newest", "thesis"))  # T_max formulas of docs/model/agents.md §5
    k_turn: float = num(1.5, 0.0, lo_open=True, doc="detour factor of T_phys")
    fire_goal_percentage: float = num(1.0, 0.0, 1.0, doc="chance an initial goal is a fire (else a corner)")
    frames: int = num(3, 1, 8, doc="stacked observation frames (index 0 = newest)")
    # True reproduces the original's sticky Extinguish reward flag (docs/model/agents.md §7.1)
    sticky_extinguish: bool = False  # true: the reference's defect, the Extinguish flag stays set after its step
    frame_skips: int = num(1, 1, 16, doc="physics steps per action; only the last one's reward is returned")
    rewards: RewardConfig = field(default_factory=RewardConfig)


# docs/model/agents.md §13.5: thesis Table 5.7 (best Optuna trial, P1 "Default") and Table 5.9 (mean of the top-10
# trials, the thesis-era and newest configs). The newest code's extra terms have one default set.
PLANNER_PRESETS: dict[str, dict[str, float]] = {
    "optuna_best": {"goal": 4.656, "burned": -0.886, "ground": -0.236, "timeout": -0.435, "same": -1.913,
                    "extinguish": 0.523, "fast": 0.523},
    "optuna_top10": {"goal": 3.9105863581302542, "burned": -2.1999479401238373, "ground": -0.29328248592328265,
                     "timeout": -2.3843039593546047, "same": -1.552461776799054, "extinguish": 0.6054212968617818,
                     "fast": 0.21654104693212245},
}
PLANNER_NEWEST_TERMS = {"distance": 0.1, "spread": 0.05, "refill": 0.5, "empty": -0.05}
# paid only with a battery (drones.energy): per drone that came down in the decision, about the TimeOut penalty
PLANNER_RESOURCE_TERMS = {"lost": -2.0}


@dataclass(frozen=True)
class PlannerRewardConfig(Section):
    """Planner reward: a preset of the thesis terms (any field set here overrides it); ``version = newest`` adds
    DistanceProgress, SpreadPrevention (and with the water limit WaterRefill, EmptyTank) and makes the
    groundstation and same-goal terms per drone as in the newest code."""

    preset: str = choice("optuna_top10", tuple(PLANNER_PRESETS),
                         doc="coefficients: optuna_best (Table 5.7) or optuna_top10 (Table 5.9)")
    version: str = choice("thesis", ("thesis", "newest"),
                          doc="thesis: the thesis-era terms; newest: adds DistanceProgress, SpreadPrevention and "
                              "the water terms, per-drone groundstation and same-goal terms")
    goal: float | None = None  # GoalReached
    burned: float | None = None  # MapBurnedTooMuch
    ground: float | None = None  # FlyingTowardsGroundStation
    timeout: float | None = None  # TimeOut
    same: float | None = None  # SameGoalPenalty
    extinguish: float | None = None  # ExtinguishFires, per cell
    fast: float | None = None  # FastExtinguish, times the remaining fraction of the step limit
    distance: float | None = None  # DistanceProgress (newest)
    spread: float | None = None  # SpreadPrevention (newest)
    refill: float | None = None  # WaterRefill (newest, water limit)
    empty: float | None = None  # EmptyTank (newest, water limit)
    lost: float | None = None  # DroneLost, per drone whose battery ran empty (drones.energy; default -2.0)


CONTROLLERS = ("planner", "greedy")  # who picks the planner drones' goals


@dataclass(frozen=True)
class PlannerConfig(Section):
    """The planner level (docs/model/agents.md §11, §13): timing, explorers, low-level policies, candidates, rewards."""

    interval: int = num(5, 1, 100, doc="hierarchy_timesteps: low-level steps per planner decision")
    fly_model: str = "models/fly_collision"  # frozen FlyAgent run folder or checkpoint for the planner drones
    explorer_model: str = "models/fly_simple"  # frozen FlyAgent for the explorers
    num_explorers: int = num(12, 1, 64, doc="ExploreFlyAgents (thesis 12; the root configs say 3)")
    explorer_speed: float = num(20.0, 0.0, lo_open=True, doc="explorer max speed (m/s)")
    explorer_view_range: int = num(20, 2, INT32_MAX, doc="explorer view range (cells); also the meander spacing")
    meander: str = choice("newest", ("newest", "thesis"),
                          doc="explorer sweep: newest (the last stripe reaches the map edge) or thesis (capped "
                              "stripe, docs/model/agents.md §11.1)")
    explorer_index_bound: str = choice("longest", ("first", "longest"),
                                       doc="longest: every explorer flies its whole path, so every cell is seen; "
                                           "first: the reference (explorer 0's path bounds the shared index)")
    train_fires: str = choice("true", ("true", "detected"), doc="candidates in training: all burning cells "
                                                                "(centralised) or the fire map")
    eval_fires: str = choice("detected", ("true", "detected"), doc="candidates in evaluation")
    time_limit: str = choice("newest", ("newest", "thesis"))  # T_max formulas of docs/model/agents.md §5
    burnout: float = num(0.30, 0.0, 1.0, doc="burned-out fraction that fails the episode")
    greedy_home: str = choice("fixed", ("original", "fixed"), was="original",
                              doc="greedy heuristic: fixed = a drone whose fire is on the groundstation cell drops "
                                  "on it; original = it re-takes that fire every step and never drops, the "
                                  "original's defect (docs/model/agents.md §10.2; the thesis configs keep it)")
    greedy_resources: bool = True  # with a battery (drones.energy): the heuristic watches battery and tank
    greedy_energy_margin: float = num(0.25, 0.0, doc="resource-aware greedy: a drone flies home once its battery "
                                                    "holds at most (1 + margin) x the energy of the flight home, "
                                                    "plus the energy of waiting there for every other drone's turn")
    return_queue: str = choice("waiting", ("waiting", "all", "none"), was="all",
                               doc="the return rule's reserve for waiting at the base: the turns of the drones "
                                   "flying home or waiting there now (waiting), every other drone's turn, the worst "
                                   "case, which with many drones is more than a battery holds (all), or none "
                                   "(landed drones swap side by side)")
    planner_resources: bool = False  # with a battery: planner drones go home on the aware greedy's rule by themselves
    max_candidates: int = num(0, 0, 1 << 24,
                              doc="candidate list length K (the bases included, first); 0 = every cell + drones.bases")
    temperature: float = num(1.0, 0.0, 10.0, lo_open=True,
                             doc="the planner's categorical is p^(1/T), renormalised (logits / T): T < 1 sharpens "
                                 "the sampled goals so training episodes can end in success; argmax is unchanged")
    distance_prior: float = num(0.0, 0.0, 1000.0,
                                doc="beyond the thesis: w0 > 0 adds -w |fire - drone| (normalised map units) to each "
                                    "drone's logits, w learned from w0 (a closer fire likelier); 0 = off")
    distinct_goals: bool = False  # thesis net: drones choose in id order, each from the fires no earlier one took
    network: str = choice("thesis", ("thesis", "pointer", "fleet"),
                          doc="the planner network: docs/model/learning.md §3.1 (thesis), §3.2 (pointer, newest), or "
                              "fleet: the pointer net without drone ids, whose weights fly any number of drones")
    fleet_sizes: str = ""  # e.g. "4,8,16": training takes these fleets in turn, an update each (fleet network only)
    base_counts: str = ""  # e.g. "1,2": training also takes these drones.bases in turn, with each fleet
    rewards: PlannerRewardConfig = field(default_factory=PlannerRewardConfig)

    def __post_init__(self):
        super().__post_init__()
        sizes = self.fleet_sizes.replace(" ", "").split(",") if self.fleet_sizes.strip() else []
        if not all(s.isdigit() and int(s) >= 1 for s in sizes):
            raise ConfigError(f"PlannerConfig: planner.fleet_sizes = {self.fleet_sizes!r}: expected positive drone "
                              "counts separated by commas, such as '4,8,16' (or '' to train one fleet)")
        counts = self.base_counts.replace(" ", "").split(",") if self.base_counts.strip() else []
        if not all(c.isdigit() and 1 <= int(c) <= 4 for c in counts):
            raise ConfigError(f"PlannerConfig: planner.base_counts = {self.base_counts!r}: expected base counts from 1 "
                              "to 4 (drones.bases) separated by commas, such as '1,2' (or '' for drones.bases)")
        if sizes and self.network not in ANY_FLEET_NETWORKS:
            raise ConfigError(f"PlannerConfig: planner.fleet_sizes = {self.fleet_sizes!r} needs a network that flies "
                              f"any fleet (planner.network: {' or '.join(ANY_FLEET_NETWORKS)}); the {self.network} "
                              "net embeds drone ids and flies one fleet size")

    @property
    def bases_in_turn(self) -> tuple[int, ...]:
        """The base counts training takes in turn (``base_counts``); () for ``drones.bases`` alone."""
        return tuple(int(c) for c in self.base_counts.replace(" ", "").split(",")) if self.base_counts.strip() else ()

    @property
    def fleets(self) -> tuple[int, ...]:
        """The fleet sizes training takes in turn (``fleet_sizes``); () for one fleet, ``drones.num_drones``."""
        return tuple(int(s) for s in self.fleet_sizes.replace(" ", "").split(",")) if self.fleet_sizes.strip() else ()

    def explorer_drones(self, drones: DroneConfig) -> DroneConfig:
        """The explorers' drone section: the planner drones' physics with the explorers' count, speed and view range,
        and no battery (the scouts keep flying: the battery is the fire-fighting drones' constraint)."""
        return replace(drones, num_drones=self.num_explorers, max_speed=self.explorer_speed,
                       view_range=self.explorer_view_range, energy=EnergyConfig())

    def inert(self, drones: DroneConfig) -> list[str]:
        """Settings that change nothing (or nothing useful) with ``drones``, each as a warning line."""
        out = []
        if self.planner_resources and not drones.energy.enabled:
            out.append("planner.planner_resources = true does nothing while drones.energy.preset is off: the return "
                       "rule watches the drones' batteries")
        if self.max_candidates == 1 == drones.bases:
            out.append("planner.max_candidates = 1 lists the groundstation alone (candidate 0): the planner can choose "
                       "no fire; 0 lists every cell")
        elif self.max_candidates == drones.bases:
            b = drones.bases
            out.append(f"planner.max_candidates = {b} lists the bases alone (candidates 0-{b - 1}, drones.bases): "
                       "the planner can choose no fire; 0 lists every cell")
        return out
