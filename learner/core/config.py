"""Every knob of a training run, with its default and a one-line reason.

``PPOConfig`` holds the algorithm's hyperparameters; ``TrainConfig`` holds how the run is laid out
(workers, budget, teacher, logging). Both are plain frozen dataclasses so a checkpoint can store
them and ``--resume`` can rebuild the run exactly.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields, replace
from typing import TYPE_CHECKING, Any, Literal

from common.client.schemas import TEACHER_KIND_PATTERN, TEACHER_LABELS
from common.client.task_space import MAX_LEVELS, Task, TaskSpace
from common.families import TaskFamily, family_for, listed_env_ids
from common.families.base import EVALUATION_SEED_SCHEMES, EvaluationSeeds
from common.families.kuka import EDGE_PLACEMENT_SHARE
from common.kuka import ENV_ID
from common.levels import DEFAULT_LEVELS
from common.policy.noise import LOG_STD_BOUNDS

if TYPE_CHECKING:
    from common.client.schemas import TeacherKind


LevelScore = Literal["positive_value_loss", "value_l1"]
LEVEL_SCORES: tuple[LevelScore, ...] = ("positive_value_loss", "value_l1")
"""The episode scores the rollout workers can send a level teacher (``rollout_worker.sampler.EPISODE_SCORES``):
the mean of max(GAE advantage, 0), robust PLR's, and the mean of |GAE advantage|, the PLR paper's."""


@dataclass(frozen=True)
class PPOConfig:
    """PPO's hyperparameters. Finished episodes per update are about batch / episode length (5 at the
    default 4,096 steps and ~800-step grasps): ``TrainConfig.envs_per_worker`` raises them without
    longer rollouts, and ``update_epochs`` x batch / ``minibatch_size`` is how many Adam steps reuse
    them (80 by default)."""

    rollout_length: int = 512
    """Steps each environment collects per iteration; batch = workers x envs per worker x this."""
    gamma: float = 0.999
    """Discount; the grasp bonus comes ~800 steps in (0.999 keeps 45% of it, 0.995 2%: PPO then hits the tray early)."""
    gae_lambda: float = 0.99
    """GAE trade-off (1 = Monte Carlo, 0 = one-step TD); 0.99 credits the early wrist turn with the late grasp."""
    learning_rate: float = 3e-4
    """Adam step size at the start of the run."""
    anneal_lr: bool = True
    """Decay the learning rate linearly over the step budget, to ``lr_final_fraction`` of it."""
    lr_final_fraction: float = 0.0
    """Where annealing ends, as a share of ``learning_rate``; 0 stops learning at the end of the budget."""
    adam_eps: float = 1e-5
    """Adam epsilon; larger than torch's default for stability, as in the PPO reference code."""
    update_epochs: int = 10
    """Passes over each batch."""
    minibatch_size: int = 512
    """Steps per gradient step."""
    clip_coef: float = 0.2
    """Policy ratio clipping range (the 'proximal' in PPO)."""
    clip_value_loss: bool = False
    """Clip value updates to +-clip_coef around the rollout's estimates (slows critics of unscaled returns)."""
    value_coef: float = 0.5
    """Weight of the value loss against the policy loss."""
    entropy_coef: float = 0.0
    """Weight of the entropy bonus; the learned log-std already explores."""
    max_grad_norm: float = 0.5
    """Global gradient-norm clip."""
    normalize_advantages: bool = True
    """Standardise advantages per minibatch."""
    normalize_values: bool = False
    """The critic learns returns standardised by their running mean and std (PopArt); GAE gets them unscaled."""
    target_kl: float | None = None
    """Stop the epoch loop early when the approximate KL exceeds this (None = never)."""
    hidden_sizes: tuple[int, ...] = (64, 64)
    """Hidden layer widths of the actor and of the critic (separate tanh MLPs)."""
    init_log_std: float = -0.5
    """Initial log standard deviation of the Gaussian policy (actions live in [-1, 1])."""
    state_dependent_std: bool = False
    """The actor outputs the log-std per state (clamped to [-5, 1]), so it can be quiet where precision matters."""
    min_log_std: float | None = None
    """Floor of the log-std (None = none); -2.3 keeps std >= 0.1 on actions in [-1, 1]."""
    angle_features: bool = True
    """Feed observed angles to the networks as (sin, cos): the gripper's roll wraps at +-pi every few steps."""
    world_block_offset: bool = False
    """Also feed the networks the block's offset from the gripper in the world frame, the frame actions move in."""
    half_turn_block_yaw: bool = False
    """Feed the block's yaw as (sin 2a, cos 2a): a block turned half a turn is the same, so the wrist can turn less."""
    critic_task_inputs: bool = False
    """The critic also reads the episode's task, each parameter in [0, 1]; the actor, deployed, does not."""
    level_score: LevelScore = "positive_value_loss"
    """Each episode's score for its teacher (PLR ranks by it): positive_value_loss, robust PLR's, or value_l1, PLR's."""
    obs_clip: float = 10.0
    """Normalised observations are clipped to +-this."""
    torch_threads: int = 1
    """Threads for the learner's update; small networks gain nothing from more on a busy machine."""

    def __post_init__(self) -> None:
        _require(self.rollout_length >= 1, "rollout_length must be at least 1")
        _require(0.0 <= self.gamma <= 1.0, "gamma must be in [0, 1]")
        _require(0.0 <= self.gae_lambda <= 1.0, "gae_lambda must be in [0, 1]")
        _require(self.learning_rate > 0, "learning_rate must be positive")
        _require(0.0 <= self.lr_final_fraction <= 1.0, "lr_final_fraction must be in [0, 1]")
        _require(
            self.min_log_std is None or LOG_STD_BOUNDS[0] <= self.min_log_std <= self.init_log_std,
            f"min_log_std must be None or in [{LOG_STD_BOUNDS[0]}, init_log_std]",
        )
        _require(self.update_epochs >= 1, "update_epochs must be at least 1")
        _require(self.minibatch_size >= 1, "minibatch_size must be at least 1")
        _require(self.clip_coef > 0, "clip_coef must be positive")
        _require(self.max_grad_norm > 0, "max_grad_norm must be positive")
        _require(len(self.hidden_sizes) >= 1 and min(self.hidden_sizes) >= 1, "hidden_sizes must be positive widths")
        _require(self.torch_threads >= 1, "torch_threads must be at least 1")
        _require(self.angle_features or not self.half_turn_block_yaw, "half_turn_block_yaw needs angle_features")
        for name in ("normalize_values", "critic_task_inputs"):
            _require(isinstance(getattr(self, name), bool), f"{name} must be true or false")
        _require(
            self.level_score in LEVEL_SCORES,
            f"level_score must be one of {', '.join(LEVEL_SCORES)}, got {self.level_score!r}",
        )

    def with_overrides(self, values: Mapping[str, Any]) -> PPOConfig:
        """This config with some fields replaced by values from the command line or JSON, checked by
        name and type (a float field takes an int; ``hidden_sizes`` takes a list)."""
        known = {f.name: f for f in fields(self)}
        unknown = sorted(set(values) - set(known))
        _require(not unknown, f"unknown PPO hyperparameter(s) {', '.join(unknown)}; known: {', '.join(known)}")
        checked: dict[str, Any] = {}
        for name, value in values.items():
            current = getattr(self, name)
            if name == "hidden_sizes" and isinstance(value, (list, tuple)):
                value = tuple(value)
                fits = all(isinstance(width, int) and not isinstance(width, bool) for width in value)
            elif isinstance(current, bool):
                fits = isinstance(value, bool)
            elif isinstance(current, str):
                fits = isinstance(value, str)
            elif isinstance(current, int):
                fits = isinstance(value, int) and not isinstance(value, bool)
            else:  # floats, and the float-or-None ones
                fits = (value is None and name in _OPTIONAL_FLOATS) or (
                    isinstance(value, (int, float)) and not isinstance(value, bool)
                )
            _require(fits, f"PPO hyperparameter {name} cannot be {value!r}")
            is_float = isinstance(current, float) or name in _OPTIONAL_FLOATS
            checked[name] = float(value) if is_float and value is not None else value
        return replace(self, **checked)


_OPTIONAL_FLOATS = ("target_kl", "min_log_std")
"""``PPOConfig`` fields that take a number or None."""

TEACHERS: tuple[TeacherKind, ...] = tuple(TEACHER_LABELS)
"""Every teacher kind the service ships, as the client's schemas list them (``GET /api/v1/teachers`` says the
same of a running service; a test holds the two equal). ``train`` takes any kind's name and lets the service,
which registers the curriculum before anything starts, refuse one it does not know: a kind added to the
service is one module and one line there, and trains at once."""
LOOPS: tuple[Literal["async", "sync"], ...] = ("async", "sync")
PolicyChoice = Literal["final", "validated"]
POLICY_CHOICES: tuple[PolicyChoice, ...] = ("final", "validated")
BudgetSteps = Literal["played", "trained"]
BUDGET_STEPS: tuple[BudgetSteps, ...] = ("played", "trained")
"""What ``TrainConfig.total_steps`` counts: every step the workers played, or only the steps the updates
trained on (the steps of score-only episodes, robust PLR's explorations, then cost nothing)."""
LISTED_ENV_IDS: tuple[str, ...] = listed_env_ids()
"""The ids ``train --env`` lists: the KUKA families, then the MiniGrid level families; it also takes any
gymnasium environment with a task space as ``module:EnvId`` (``common.families``)."""


@dataclass(frozen=True)
class TrainConfig:
    teacher: TeacherKind = "alp-gmm"
    """Curriculum teacher, a kind of the service (``TEACHERS``): manual is the book's lesson plan, fixed the hardest."""
    env: str = ENV_ID
    """The environment: a KUKA family, a MiniGrid level family (levels = reset seeds) or module:EnvId."""
    levels: int = DEFAULT_LEVELS
    """A MiniGrid level family's training set: the reset seeds 0 to levels - 1 (other families ignore it)."""
    total_steps: int = 2_000_000
    """Environment steps to train for (the run stops after the iteration that reaches it)."""
    budget_steps: BudgetSteps = "played"
    """Which steps ``total_steps`` counts (``BUDGET_STEPS``): every step played, or only those trained on."""
    workers: int = 2
    """Rollout actors, one CPU each."""
    envs_per_worker: int = 4
    """Environments each actor steps in lockstep; more amortise the batched policy call."""
    seed: int = 0
    """Seeds the network, the workers' environments and the teacher."""
    max_episode_steps: int = 1000
    """Episode step limit (truncation)."""
    checkpoint_every: int = 20
    """Iterations between checkpoints (one is always written at the end)."""
    eval_every: int = 25
    """Iterations between evaluations on the hardest task (0 = never); 25 keeps their cost near 5%."""
    eval_episodes: int = 10
    """Evaluation episodes, one per fixed seed, shared out over the workers."""
    eval_seeds: EvaluationSeeds = "stratified"
    """A KUKA family's evaluation seeds: placements spread as the final evaluation's, or consecutive from 10,000."""
    loop: Literal["async", "sync"] = "async"
    """async: workers sample the next batch, one update behind, while the learner updates; sync: on-policy, paused."""
    edge_placement_share: float = 0.0
    """Share of a hard KUKA family's far training placements drawn beyond the arm's x clamp (never evaluations')."""
    policy_choice: PolicyChoice = "final"
    """The run's policy: its last checkpoint, or its second half's best on validation episodes (``selection``)."""
    teacher_overrides: dict[str, Any] = field(default_factory=dict)
    """Teacher parameters on top of the family's (``TaskFamily.teacher_params``); the service validates them."""
    ppo: PPOConfig = field(default_factory=PPOConfig)
    """Algorithm hyperparameters."""

    def __post_init__(self) -> None:
        _require(
            re.fullmatch(TEACHER_KIND_PATTERN, self.teacher) is not None,
            f"teacher must be a kind's name such as {', '.join(TEACHERS[:3])}, got {self.teacher!r}",
        )
        family = family_for(self.env)  # an UnusableEnvironment, a ValueError, for an id no family owns
        _require(1 <= self.levels <= MAX_LEVELS, f"levels must be between 1 and {MAX_LEVELS:,}, got {self.levels}")
        _require(self.total_steps >= 1, "total_steps must be at least 1")
        _require(
            self.budget_steps in BUDGET_STEPS,
            f"budget_steps must be one of {', '.join(BUDGET_STEPS)}, got {self.budget_steps!r}",
        )
        _require(self.workers >= 1, "workers must be at least 1")
        _require(self.envs_per_worker >= 1, "envs_per_worker must be at least 1")
        _require(self.max_episode_steps >= 1, "max_episode_steps must be at least 1")
        _require(self.checkpoint_every >= 1, "checkpoint_every must be at least 1")
        _require(self.eval_every >= 0, "eval_every must be 0 (never) or more")
        _require(self.eval_episodes >= 1, "eval_episodes must be at least 1")
        _require(
            self.eval_seeds in EVALUATION_SEED_SCHEMES,
            f"eval_seeds must be one of {', '.join(EVALUATION_SEED_SCHEMES)}, got {self.eval_seeds!r}",
        )
        family.check_evaluation(self.env, self.eval_episodes, self.eval_seeds)
        _require(self.loop in LOOPS, f"loop must be one of {', '.join(LOOPS)}, got {self.loop!r}")
        _require(
            self.policy_choice in POLICY_CHOICES,
            f"policy_choice must be one of {', '.join(POLICY_CHOICES)}, got {self.policy_choice!r}",
        )
        _require(
            0.0 <= self.edge_placement_share <= 1.0,
            f"edge_placement_share must be between 0 and 1, got {self.edge_placement_share}",
        )
        family.check_options(self.env, self.env_options)

    @property
    def family(self) -> TaskFamily:
        return family_for(self.env)

    @property
    def env_options(self) -> dict[str, Any]:
        """The family's training-only options that this run sets (``TaskFamily.options``)."""
        return {EDGE_PLACEMENT_SHARE: self.edge_placement_share} if self.edge_placement_share else {}

    @property
    def teacher_params(self) -> dict[str, Any]:
        """What the curriculum is registered with: the overrides on the family's parameters for the kind
        (``TaskFamily.teacher_params``: KUKA's ``KUKA_TEACHER_PARAMS``, the kind's own defaults elsewhere)."""
        return self.family.teacher_params(self.teacher, self.teacher_overrides)

    def task_space(self) -> TaskSpace:
        """The space the run's curriculum draws tasks from."""
        return self.family.task_space(self.env, self.levels)

    def evaluation_task(self) -> Task:
        """The task the in-run evaluations play: the hardest, or none (held-out levels)."""
        return self.family.evaluation_task(self.env, self.levels)

    def evaluation_seeds(self) -> list[int]:
        """The in-run evaluations' seeds, the same all run long."""
        return self.family.evaluation_seeds(self.env, self.levels, self.eval_episodes, self.eval_seeds)

    @property
    def batch_size(self) -> int:
        return self.workers * self.envs_per_worker * self.ppo.rollout_length

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TrainConfig:
        known = {f.name for f in fields(cls)}
        values = {key: value for key, value in data.items() if key in known and key != "ppo"}
        ppo = dict(data.get("ppo", {}))
        # Runs from before ``loop`` existed were synchronous, and resume as they started.
        values.setdefault("loop", "sync")
        # Runs from before ``eval_seeds`` existed evaluated on consecutive seeds, and resume so: one curve, one set.
        values.setdefault("eval_seeds", "consecutive")
        # Checkpoints from before ``angle_features`` existed were trained on raw angles.
        ppo.setdefault("angle_features", False)
        if "hidden_sizes" in ppo:
            ppo["hidden_sizes"] = tuple(ppo["hidden_sizes"])
        return cls(**values, ppo=PPOConfig(**ppo))


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise ValueError(message)
