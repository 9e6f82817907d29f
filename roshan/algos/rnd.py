"""Random network distillation (Burda et al. 2018, arXiv:1810.12894): an intrinsic reward (docs/model/learning.md §15).

A frozen random target MLP and a trained predictor MLP read the same flattened feature vector (for FlyAgents
``obs["agent"]`` flattened); the prediction error is large on rarely seen inputs.
"""


import torch

from roshan.algos.networks import mlp
from roshan.algos.normalize import RewardScaler
from roshan.config import RNDConfig


class RND:
    """Target and predictor ``Linear(D, hidden) - ReLU - Linear(hidden, hidden) - ReLU - Linear(hidden, out)``."""

    def __init__(self, input_dim: int, cfg: RNDConfig, device: str | torch.device = "cpu"):
        self.cfg = cfg
        self.device = torch.device(device)
        sizes = [input_dim, cfg.hidden, cfg.hidden, cfg.out]
        self.target = mlp(sizes, final_activation=False).to(self.device).requires_grad_(False)
        self.predictor = mlp(sizes, final_activation=False).to(self.device)
        self.optimizer = torch.optim.Adam(self.predictor.parameters(), lr=cfg.lr, betas=(0.9, 0.999), eps=1e-5)
        self.scaler = RewardScaler()

    def _error(self, x: torch.Tensor) -> torch.Tensor:
        """Per-sample mean squared prediction error: (B, ...) flattened to (B, D) -> (B,)."""
        x = x.to(self.device).flatten(1)
        return (self.target(x) - self.predictor(x)).pow(2).mean(-1)

    @torch.no_grad()
    def intrinsic_reward(self, x: torch.Tensor) -> torch.Tensor:
        """Raw intrinsic reward mean_f (f_target(x) - f_pred(x))^2: (B, ...) -> (B,)."""
        return self._error(x)

    @torch.no_grad()
    def scaled_intrinsic(self, x: torch.Tensor) -> torch.Tensor:
        """The intrinsic reward divided by its own running std, which first merges this batch (as the extrinsic
        rewards are scaled, docs/model/learning.md §6.2): (B, ...) -> (B,). The caller adds ``cfg.coef`` times this."""
        rewards = self._error(x)
        self.scaler.update(rewards)
        return self.scaler.scale(rewards)

    def update(self, x: torch.Tensor, batch_size: int, generator: torch.Generator | None = None) -> float:
        """One pass of predictor training (MSE to the target) over ``x`` (N, ...) in shuffled minibatches;
        returns the mean minibatch loss."""
        device = generator.device if generator is not None else self.device
        order = torch.randperm(x.shape[0], generator=generator, device=device).to(x.device)
        losses = []
        for start in range(0, x.shape[0], batch_size):
            loss = self._error(x[order[start:start + batch_size]]).mean()
            self.optimizer.zero_grad()
            loss.backward()
            self.optimizer.step()
            losses.append(loss.detach())
        return torch.stack(losses).mean().item() if losses else 0.0

    def state_dict(self) -> dict:
        return {"target": self.target.state_dict(), "predictor": self.predictor.state_dict(),
                "optimizer": self.optimizer.state_dict(), "scaler": self.scaler.state_dict()}

    def load_state_dict(self, state: dict) -> None:
        self.target.load_state_dict(state["target"])
        self.predictor.load_state_dict(state["predictor"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.scaler.load_state_dict(state["scaler"])
