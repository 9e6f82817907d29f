"""The learning sections: the training loop and each algorithm's hyperparameters."""

from dataclasses import dataclass, field

from roshan.config.levels import ALGO_LEVELS, ALGO_SECTIONS, Level, level_of
from roshan.config.schema import Section, choice, num

OPTIMIZER_NAMES = ("adam", "adamw", "sgd", "rmsprop", "radam")
SCHEDULERS = ("cosine", "cosine_restarts", "step", "exponential", "constant", "none")


@dataclass(frozen=True)
class TrainConfig(Section):
    """The training loop: budget, evaluation and repetitions (the batch of envs and the seed are ``sim.envs`` /
    ``sim.seed``, as for every command)."""

    algo: str = choice("ppo", tuple(ALGO_LEVELS), doc="planner: PPO on the PlannerAgent level")
    total_steps: int = num(1_000_000, 0, doc="env steps (each moves every drone once; planner: decisions); "
                                                "0 = no limit")
    max_updates: int = num(0, 0, doc="updates; 0 = no limit")
    max_minutes: float = num(0.0, 0.0, doc="wall-clock budget of one run; 0 = no limit")
    objective_window: int = num(100, 1, doc="training episodes in the success-rate objective")
    eval_every: int = num(0, 0, doc="evaluate every K updates; 0 = only at the end")
    eval_episodes: int = num(200, 1, doc="episodes of each evaluation (periodic and at the end of training)")
    eval_envs: int = num(50, 1, doc="envs stepped together in an evaluation (and `roshan eval`'s default --envs)")
    eval_video_frames: int = num(30, 0, doc="periodic evaluation: frames of env 0's first episode logged to "
                                            "TensorBoard as a video (every k-th step, to fit); 0 = no video")
    auto_train: int = num(1, 1, doc="independent runs (seeds seed, seed+1, ...) in sequence, then evaluation")
    torch_threads: int = num(0, 0, doc="torch intra-op threads; 0 = torch's default in training, 1 in roshan eval and "
                                       "roshan watch (small batches between Taichi kernels)")
    buffer_path: str = ""  # IQL: the replay buffer to learn from (``roshan eval --save-buffer``)
    init_from: str = ""  # start from these network weights (a run folder's best or a checkpoint): fine-tuning

    @property
    def level(self) -> Level:
        """The level ``algo`` trains (:mod:`roshan.config.levels`)."""
        return level_of(self.algo)

    @property
    def section(self) -> str:
        """The config section of ``algo``'s hyperparameters (``ppo`` for the planner too)."""
        return ALGO_SECTIONS[self.algo]


@dataclass(frozen=True)
class OptimConfig(Section):
    """Optimiser and schedule. Defaults are the thesis-era ones: Adam(0.9, 0.999, eps 1e-5) with a cosine
    schedule of T_max 1e6 steps, stepped per gradient step (effectively constant over a run)."""

    name: str = choice("adam", OPTIMIZER_NAMES, doc="the torch optimiser")
    beta1: float = num(0.9, 0.0, 1.0, hi_open=True, doc="Adam-family first-moment decay")
    beta2: float = num(0.999, 0.0, 1.0, hi_open=True, doc="Adam-family second-moment decay")
    eps: float = num(1e-5, 0.0, lo_open=True, doc="added to the denominator (Adam, RMSprop)")
    weight_decay: float = num(0.0, 0.0, doc="L2 penalty (adamw: decoupled)")
    momentum: float = num(0.0, 0.0, 1.0, doc="SGD / RMSprop momentum")
    scheduler: str = choice("cosine", SCHEDULERS, doc="learning-rate schedule, stepped per gradient step; "
                                                        "constant / none keep the rate")
    t_max: int = num(1_000_000, 1, doc="cosine: steps per half period")
    step_size: int = num(10_000, 1, doc="step: steps between decays")
    decay: float = num(0.99, 0.0, 1.0, lo_open=True, doc="step / exponential: factor per decay")
    min_lr: float = num(0.0, 0.0, doc="cosine: eta_min")


@dataclass(frozen=True)
class PPOConfig(Section):
    """PPO hyperparameters of either level (``train.algo`` ppo: the FlyAgent; planner: the PlannerAgent). Defaults
    are thesis Table 5.2 (E1, FlyAgent); the planner's Table 5.8 values are set in configs/planner*.yaml. The keys
    in :data:`roshan.config.levels.FLY_ONLY_PPO_KEYS` shape the FlyAgent policy and are refused for the planner."""

    lr: float = num(1.575e-4, 0.0, lo_open=True, doc="learning rate")
    horizon: int = num(1200, 1, doc="transitions collected per update (FlyAgent: all drones' steps; planner: "
                                    "all envs' decisions)")
    batch_size: int = num(300, 1, doc="minibatch size in transitions")
    k_epochs: int = num(3, 1, doc="passes over each rollout per update")
    gamma: float = num(0.9635, 0.0, 1.0, doc="discount")
    lam: float = num(0.9, 0.0, 1.0, doc="GAE lambda")
    eps_clip: float = num(0.2, 0.0, 1.0, lo_open=True, doc="clip range of the probability ratio")
    value_loss_coef: float = num(0.5, 0.0, doc="weight of the value loss")
    entropy_coeff: float = num(0.01, 0.0, doc="weight of the entropy bonus")
    max_grad_norm: float = num(0.5, 0.0, doc="per parameter group; 0 = off (the thesis-era code never clipped)")
    kl_early_stop: bool = False  # skip the rest of an epoch once the approx KL reaches kl_target
    kl_target: float = num(0.03, 0.0, lo_open=True, doc="approx KL that stops an epoch (with kl_early_stop)")
    kl_estimator: str = choice("k1", ("k1", "k2"), doc="approx KL estimator: k1 = mean(old - new log p), "
                                                      "k2 = mean((r - 1) - log r)")
    log_std: str = choice("learned", ("learned", "train_step_decay", "log_step_decay"),
                          doc="FlyAgent policy's log std: learned, or a fixed schedule per update "
                              "(docs/model/learning.md §4)")
    decay_rate: float = num(0.9999, 0.0, 1.0, lo_open=True, doc="per-update factor of the log_std decay schedules")
    share_encoder: bool = False  # actor and critic read one encoder
    use_tanh_dist: bool = False  # TanhNormal policy; false: a Gaussian around tanh(mu)
    tanh_entropy: str = choice("base", ("base", "squashed"),
                               doc="TanhNormal's entropy bonus: base = of the pre-tanh Normal (the reference; blind "
                                   "to saturation, so the mean drifts into tanh's tails), squashed = of the actions")
    mean_bound: float = num(0.0, 0.0, doc="TanhNormal: penalise pre-tanh means beyond +-B (squared excess), so "
                                          "samples keep leaving tanh's flat tails and carry a gradient; 0 = off "
                                          "(the reference)")
    mean_bound_coef: float = num(1.0, 0.0, doc="weight of the mean_bound penalty in the PPO loss")
    separate_optimizers: bool = False  # one optimiser for the actor, one for the critic (needs share_encoder false)
    ema_decay: float = num(0.0, 0.0, 1.0, hi_open=True,
                           doc="> 0: deterministic actions (evaluation, best_eval, the saved policy) come from an "
                               "exponential moving average of the weights, decayed by this factor once per update "
                               "(0.9: about the last 10 updates); training samples with the live weights; 0 = off")
    reward_eps: float = num(1e-8, 0.0, doc="added to the running variance (thesis-era 1e-8, newest 1e-4)")
    bootstrap_truncated: bool = True  # False: a timeout ends the trace like a terminal (the reference)
    minibatch: str = choice("samples", ("samples", "sequences"),
                            doc="samples: shuffled transitions (the reference); sequences: shuffled drones with "
                                "their whole rollout, so each stacked frame is encoded once (about 3x cheaper)")
    optim: OptimConfig = field(default_factory=OptimConfig)


@dataclass(frozen=True)
class TD3Config(Section):
    """TD3 hyperparameters; defaults are thesis Table 5.2 (docs/model/learning.md §14.1)."""

    lr: float = num(1e-4, 0.0, lo_open=True, doc="learning rate of actor and critic")
    batch_size: int = num(512, 1, doc="transitions per gradient iteration")
    memory_size: int = num(1_000_000, 1, doc="replay capacity (transitions, all drones together)")
    min_memory_size: int = num(30_000, 0, doc="stored transitions before the first update")
    k_epochs: int = num(1, 1, doc="gradient iterations per update call (one call per env step)")
    gamma: float = num(0.99, 0.0, 1.0, doc="discount")
    tau: float = num(0.005, 0.0, 1.0, lo_open=True, doc="soft target update rate")
    exploration_noise: float = num(0.15, 0.0, doc="std of the Gaussian action noise while collecting")
    policy_noise: float = num(0.2, 0.0, doc="std of the target policy smoothing noise")
    noise_clip: float = num(0.5, 0.0, doc="the smoothing noise is clipped to +-noise_clip")
    policy_freq: int = num(2, 1, doc="critic iterations per actor (and target) update")
    share_encoder: bool = False  # both Q heads read the actor's encoder (docs/model/learning.md §1, §2.3)
    broadcast_defect: bool = False  # reproduce the reference's (B,1)-vs-(B,) critic MSE (docs/model/learning.md §7)
    optim: OptimConfig = field(default_factory=OptimConfig)


@dataclass(frozen=True)
class IQLConfig(Section):
    """IQL hyperparameters; defaults are thesis Table 5.2 and the newest config
    (docs/model/learning.md §14.1, §14.5)."""

    lr: float = num(1.575e-4, 0.0, lo_open=True, doc="learning rate of actor, critic and value")
    batch_size: int = num(250, 1, doc="transitions per minibatch")
    gamma: float = num(0.99, 0.0, 1.0, doc="discount")
    expectile: float = num(0.7, 0.0, 1.0, lo_open=True, hi_open=True, doc="expectile tau of the value loss")
    temperature: float = num(3.0, 0.0, doc="inverse temperature beta of the advantage weights")
    tau: float = num(0.005, 0.0, 1.0, lo_open=True, doc="soft update rate of the target critic")
    offline_updates: int = num(10, 0, doc="full passes over the saved dataset")
    online_updates: int = num(0, 0, doc="online update calls after the offline phase")
    policy_freq: int = num(50, 1, doc="online: env steps between update calls")
    k_epochs: int = num(1, 1, doc="online: minibatches per update call")
    share_encoder: bool = True  # critic and value read the actor's encoder (docs/model/learning.md §1, §2.3)
    use_tanh_dist: bool = True  # TanhNormal policy around mu; False: Gaussian around tanh(mu), clipped
    broadcast_defect: bool = False  # reproduce the reference's (B, B) Q target (docs/model/learning.md §8)
    max_weight: float = num(100.0, 0.0, lo_open=True, doc="upper clip of the advantage weights")
    optim: OptimConfig = field(default_factory=OptimConfig)


@dataclass(frozen=True)
class RNDConfig(Section):
    """RND switches; off in every reference experiment (docs/model/learning.md §15)."""

    enabled: bool = False  # add the scaled intrinsic reward to the scaled extrinsic one
    lr: float = num(1e-4, 0.0, lo_open=True, doc="predictor learning rate")
    coef: float = num(1.0, 0.0, doc="weight of the scaled intrinsic reward in the sum")
    hidden: int = num(256, 1, doc="hidden width of target and predictor")
    out: int = num(256, 1, doc="embedding width of target and predictor")
