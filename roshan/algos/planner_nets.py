"""The PlannerAgent's networks: attention over fire candidates that assigns every drone a candidate goal
(docs/model/learning.md §3). The joint action of N drones is one sample (log-prob and entropy summed over drones); the
PPO that trains them is :class:`roshan.algos.ppo.PPO` with :class:`roshan.algos.policies.PlannerPolicy`.

A planner observation is a dict of float tensors with the batch first: ``drones`` (B, N, 2), ``goals`` (B, N, 2),
``water`` (B, N, 1), with a battery ``energy`` (B, N, 2) (the charge and the charge the flight home needs),
``fires`` (B, K, 2) (index 0 = the groundstation, then fire cells, zero padding after the valid prefix),
``fires_mask`` (B, K) (1 = valid) and ``globals`` (B, 5) (fire count, centroid (2), wind (2)).
An action is (B, N) long: one candidate index per drone.
"""

import math

import torch
import torch.nn.functional as F
from torch import nn

from roshan.algos.linear import Linear
from roshan.algos.networks import layer_init

HIDDEN = 64
HEADS = 4
PROB_EPS = 1e-8  # attention weights are clamped to this before the log, so a valid candidate keeps a finite log-prob


def trim_candidates(obs: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """``obs`` with ``fires`` and ``fires_mask`` cut to the longest valid prefix in the batch (at least 1).

    Masked candidates never change a network's output, so this only saves work (K is up to 1261 in the env,
    while few cells burn at a time). Action indices are unchanged because the valid entries are a prefix.
    """
    mask = obs["fires_mask"]
    position = torch.arange(1, mask.shape[-1] + 1, device=mask.device)
    k = max(1, int(((mask > 0) * position).max())) if mask.numel() else 1
    out = dict(obs)
    out["fires"], out["fires_mask"] = obs["fires"][:, :k], mask[:, :k]
    return out


def fleet_features(obs: dict[str, torch.Tensor]) -> torch.Tensor:
    """Drone positions, goals, water (and energy, with a battery) with the global fire context, flat: (B, 5 N + 5),
    or (B, 7 N + 5) with energy (:func:`fleet_features_dim`). The candidate list has no fixed length, so it enters
    only through the globals (count, centroid, wind). What RND reads at the planner level."""
    energy = [obs["energy"].flatten(1)] if "energy" in obs else []
    return torch.cat([obs["drones"].flatten(1), obs["goals"].flatten(1), obs["water"].flatten(1), *energy,
                      obs["globals"]], dim=-1)


def fleet_features_dim(num_drones: int, resources: bool) -> int:
    """The width of :func:`fleet_features` for ``num_drones`` drones; ``resources``: with the energy part."""
    return (7 if resources else 5) * num_drones + 5


def candidate_validity(fires_mask: torch.Tensor, bases: int = 1) -> torch.Tensor:
    """(B, K) bool, True = selectable; the bases (the first ``bases`` candidates, 0 the groundstation) always are."""
    valid = fires_mask > 0
    valid[:, :bases] = True
    return valid


def sample_rows(logits: torch.Tensor, deterministic: bool, generator: torch.Generator | None) -> torch.Tensor:
    """One index per row of (..., K) logits (-inf = masked): argmax, or a categorical sample. A masked entry has
    probability exactly 0 and is never drawn."""
    if deterministic:
        return logits.argmax(-1)
    probs = torch.softmax(logits, -1)
    flat = probs.reshape(-1, probs.shape[-1])
    return torch.multinomial(flat, 1, generator=generator).view(probs.shape[:-1])


def score(logits: torch.Tensor, actions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Joint log-prob and entropy of per-drone categoricals.

    Args:
        logits: (B, N, K) per-drone logits, -inf where a candidate is masked.
        actions: (B, N) long candidate indices.

    Returns:
        (log_prob, entropy), both (B,): sums over the N drones.
    """
    logp = torch.log_softmax(logits, -1)
    allowed = torch.isfinite(logits)
    # -p log p with 0 for masked entries (0 * -inf would be NaN); the where keeps the gradient finite as well
    entropy = -(logp.exp() * torch.where(allowed, logp, torch.zeros_like(logp))).sum(-1)
    log_prob = logp.gather(-1, actions.unsqueeze(-1)).squeeze(-1)
    return log_prob.sum(-1), entropy.sum(-1)


def init_weights(module: nn.Module) -> None:
    """Orthogonal weights with the ReLU gain and zero biases on every Linear, including the output projection
    inside ``nn.MultiheadAttention`` (docs/model/learning.md §1); embeddings, LayerNorms and attention input projections
    keep PyTorch's defaults. Value output layers are re-initialised with gain 1.0 by their owners."""
    for m in module.modules():
        if isinstance(m, nn.Linear):
            layer_init(m)


# ---------------------------------------------------------------------------------------------- thesis-era net


class DistancePrior(nn.Module):
    """-w |f_j - p_i| (B, N, K) for drone i and candidate j in normalised map units, with w > 0 learned from ``weight``
    (``planner.distance_prior``; beyond the thesis). The thesis net's score of a candidate is linear in its position
    (:meth:`ThesisPlannerNet.attend`), so its argmax is always a corner of the candidates' hull: "the nearest fire",
    the greedy heuristic's choice, is not one it can express. With the prior it is the starting point."""

    def __init__(self, weight: float):
        super().__init__()
        self.log_weight = nn.Parameter(torch.tensor([math.log(weight)]))

    def forward(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        gap = obs["fires"].unsqueeze(1) - obs["drones"].unsqueeze(2)  # (B, N, K, 2)
        return -self.log_weight.exp() * (gap.pow(2).sum(-1) + 1e-12).sqrt()


def make_distance_prior(weight: float) -> DistancePrior | None:
    """The prior for ``planner.distance_prior`` (made after a net's own layers, so their initial draws stay the
    same), or None when it is 0."""
    return DistancePrior(weight) if weight > 0 else None


def without_taken(row: torch.Tensor, taken: torch.Tensor) -> torch.Tensor:
    """Logits (..., K) with the ``taken`` fires masked; a row left with nothing keeps all its candidates (a drone
    with no free fire shares one, as the greedy heuristic's drones do)."""
    masked = row.masked_fill(taken, float("-inf"))
    return torch.where(torch.isfinite(masked).any(-1, keepdim=True), masked, row)


def distinct_rows(logits: torch.Tensor, actions: torch.Tensor, bases: int = 1) -> torch.Tensor:
    """Teacher-forced (B, N, K) logits of drones choosing in id order: drone i's row without the fires drones
    0..i-1 took in ``actions`` (the bases, the first ``bases`` candidates, may repeat)."""
    onehot = F.one_hot(actions, logits.shape[-1])
    taken = (onehot.cumsum(1) - onehot) > 0
    taken[..., :bases] = False
    return without_taken(logits, taken)


RESTOCK_BELOW = 0.5  # with a battery: the fill of battery or tank below which a net may send a drone home


def offer_bases_to_restock(allowed: torch.Tensor, obs: dict[str, torch.Tensor], bases: int) -> torch.Tensor:
    """(B, N, K) per drone from ``allowed`` (B, K): the bases (the first ``bases`` candidates) only for a drone whose
    battery or tank is below half (:data:`RESTOCK_BELOW`), or for every drone when no fire is listed."""
    no_fire = ~allowed[:, bases:].any(-1)
    restock = (obs["energy"][..., 0] < RESTOCK_BELOW) | (obs["water"][..., 0] < RESTOCK_BELOW)  # (B, N)
    out = allowed.unsqueeze(1).repeat(1, restock.shape[1], 1)
    out[..., :bases] = (restock | no_fire[:, None]).unsqueeze(-1)
    return out


class ThesisPlannerNet(nn.Module):
    """Thesis-era planner (docs/model/learning.md §3.1): one attention layer from drones to fire candidates whose
    head-averaged weights are the per-drone categorical probabilities; the value is the mean over drones of a linear
    head on the attention output.

    Deviation from the reference: the reference masks only the groundstation when acting and only the padding
    during the update, so the update evaluates a different distribution than the one that sampled the action.
    Here acting and updating use the same mask: padding is masked, and index 0 (groundstation) is masked whenever
    at least one fire is valid, so it is chosen only when no fire is listed (which is what acting does in the
    reference).

    With ``resources`` (drones with a battery, issue 33) the drone queries also embed the tank's fill and the
    ``energy`` pair, and the groundstation is a candidate of its own for each drone whose battery or tank is below
    half (:data:`RESTOCK_BELOW`): sending it home to swap its battery or refill is a decision. Other drones get it
    only when no fire is listed, as without a battery. Offered always, the planner parked stocked drones at the
    base (~150 s an episode against greedy's 18 s); offered for any shortfall, it sent drones home after nearly
    every drop (a third of their decisions spent restocking), which also dodged the same-goal penalty. The return
    rule (planner.planner_resources) brings a drone home before its battery or tank runs out in any case.
    """

    def __init__(self, num_drones: int, hidden: int = HIDDEN, heads: int = HEADS,
                 temperature: float = 1.0, resources: bool = False, distance_prior: float = 0.0,
                 distinct_goals: bool = False, bases: int = 1):
        super().__init__()
        self.pos_emb = Linear(2, hidden)
        self.goal_emb = Linear(2, hidden)
        self.fire_emb = Linear(2, hidden)
        self.id_emb = nn.Embedding(num_drones, hidden)
        self.attn = nn.MultiheadAttention(hidden, heads, batch_first=True)
        self.value_head = Linear(hidden, 1)
        self.resources = resources
        if resources:  # without a battery the network (and its initial draws) is the thesis net's
            self.water_emb, self.energy_emb = Linear(1, hidden), Linear(2, hidden)
        init_weights(self)
        layer_init(self.value_head, gain=1.0)
        self.register_buffer("drone_ids", torch.arange(num_drones), persistent=False)
        self.temperature = temperature  # planner.temperature: logits / T, so p ~ weights^(1/T)
        self.prior = make_distance_prior(distance_prior)
        self.distinct_goals = distinct_goals  # planner.distinct_goals: drones choose in id order, a fire once
        self.bases = bases  # drones.bases: the first candidates are the bases (a setting of the env, not a weight)

    def allowed(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        """(B, 1, K) bool, the same for every drone: valid fires, or only the bases when no fire is valid; with
        resources (B, N, K): the bases also for each drone whose battery or tank is below half."""
        b = self.bases
        allowed = obs["fires_mask"] > 0
        allowed[:, :b] = ~allowed[:, b:].any(-1, keepdim=True)
        return offer_bases_to_restock(allowed, obs, b) if self.resources else allowed.unsqueeze(1)

    def queries(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        """(B, N, H) drone queries: position, goal and id (with resources: water and energy too)."""
        query = self.pos_emb(obs["drones"]) + self.goal_emb(obs["goals"]) + self.id_emb(self.drone_ids)
        if self.resources:
            query = query + self.water_emb(obs["water"]) + self.energy_emb(obs["energy"])
        return query

    def attend(self, obs: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Attention weights averaged over heads (B, N, K), attention output (B, N, H) and the mask (B, 1 or N, K).

        The same function as ``self.attn(query, fires, fires, key_padding_mask=...)`` on the embedded fires,
        computed in the fires' 2 coordinates instead of H: the fire embedding and the key and value projections
        are affine with nothing between them, so a head's score is q.(A x + c) = (A^T q).x + q.c, whose second
        term is the same for every candidate and cancels in the softmax, and its output is A_v (sum_j w_j x_j)
        + c_v because the weights sum to 1. That is H/2 = 32x less work over the candidate list, which dominated
        a planner update. The parameters (and checkpoints) are nn.MultiheadAttention's; the outputs agree with
        it to float rounding (tests/algos/test_planner_algo.py).
        """
        allowed = self.allowed(obs)
        query = self.queries(obs)
        B, N, H = query.shape
        heads = self.attn.num_heads
        size = H // heads
        w_q, w_k, w_v = self.attn.in_proj_weight.chunk(3)
        b_q, _, b_v = self.attn.in_proj_bias.chunk(3)
        w_f, b_f = self.fire_emb.weight, self.fire_emb.bias  # (H, 2), (H,)
        q = F.linear(query, w_q, b_q).view(B, N, heads, size) / math.sqrt(size)
        key_map = (w_k @ w_f).view(heads, size, 2)  # fire coordinates -> each head's keys
        value_map, value_bias = (w_v @ w_f).view(heads, size, 2), (w_v @ b_f + b_v).view(heads, size)
        scores = torch.einsum("bnhc,bkc->bhnk", torch.einsum("bnhs,hsc->bnhc", q, key_map), obs["fires"])
        weights = torch.softmax(scores.masked_fill(~allowed[:, None], float("-inf")), -1)
        pooled = torch.einsum("bhnk,bkc->bnhc", weights, obs["fires"])  # each head's mean candidate
        out = self.attn.out_proj(
            (torch.einsum("bnhc,hsc->bnhs", pooled, value_map) + value_bias).reshape(B, N, H))
        return weights.mean(1), out, allowed

    def probs(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        """(B, N, K) per-drone probabilities as the reference defines them (exactly 0 where masked)."""
        return self.attend(obs)[0]

    def heads(self, obs: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        """Per-drone logits (B, N, K) (-inf where masked) and the value (B,)."""
        weights, out, allowed = self.attend(obs)
        # the clamp keeps the log finite where a weight underflows; log_softmax renormalises after it
        logits = weights.clamp_min(PROB_EPS).log()
        if self.prior is not None:
            logits = logits + self.prior(obs)
        logits = (logits / self.temperature).masked_fill(~allowed, float("-inf"))
        return logits, self.value_head(out).squeeze(-1).mean(-1)

    def forward_act(self, obs: dict[str, torch.Tensor], deterministic: bool = False,
                    generator: torch.Generator | None = None):
        """Actions (B, N), joint log-prob (B,), entropy (B,) and value (B,); drones choose independently, or with
        ``distinct_goals`` one after another, each from the fires no earlier drone took."""
        logits, value = self.heads(obs)
        if not self.distinct_goals:
            actions = sample_rows(logits, deterministic, generator)
            return (actions, *score(logits, actions), value)
        B, N, K = logits.shape
        actions = torch.empty(B, N, dtype=torch.long, device=logits.device)
        taken = torch.zeros(B, K, dtype=torch.bool, device=logits.device)
        with torch.no_grad():
            for i in range(N):
                actions[:, i] = sample_rows(without_taken(logits[:, i], taken), deterministic, generator)
                taken.scatter_(1, actions[:, i:i + 1], (actions[:, i:i + 1] >= self.bases))
        # scored with the teacher-forced rows evaluate() builds, so both agree exactly
        return (actions, *score(distinct_rows(logits, actions, self.bases), actions), value)

    def evaluate(self, obs: dict[str, torch.Tensor], actions: torch.Tensor):
        """Joint log-prob (B,), entropy (B,) and value (B,) of given actions (B, N)."""
        logits, value = self.heads(obs)
        if self.distinct_goals:
            logits = distinct_rows(logits, actions, self.bases)
        return (*score(logits, actions), value)

    def value(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        _, out, _ = self.attend(obs)
        return self.value_head(out).squeeze(-1).mean(-1)

    def critic_parameters(self) -> list[nn.Parameter]:
        """The value head: the encoder is shared with the actor (thesis Table 5.8)."""
        return list(self.value_head.parameters())


# ---------------------------------------------------------------------------------------------- newest net


def embed(in_features: int, hidden: int = HIDDEN) -> nn.Sequential:
    return nn.Sequential(Linear(in_features, hidden), nn.ReLU())


class PlannerEncoder(nn.Module):
    """Drone tokens from position, goal, id, velocity and water, plus the global fire context; self-attention
    among drones, then cross-attention to the fire candidates, each with a residual and LayerNorm
    (docs/model/learning.md §3.2). Without ``ids`` a drone is told apart by its own state alone: nothing depends on
    the number of drones or their order (:class:`FleetPlannerNet`)."""

    def __init__(self, num_drones: int, hidden: int = HIDDEN, heads: int = HEADS, resources: bool = False,
                 ids: bool = True):
        super().__init__()
        self.pos_emb, self.goal_emb, self.vel_emb = embed(2), embed(2), embed(2)
        self.water_emb, self.fire_emb = embed(1), embed(2)
        self.count_emb, self.centroid_emb, self.wind_emb = embed(1), embed(2), embed(2)
        self.id_emb = nn.Embedding(num_drones, hidden) if ids else None
        parts = 5 if ids else 4
        self.fusion = nn.Sequential(Linear(parts * hidden, 2 * hidden), nn.ReLU(), Linear(2 * hidden, hidden),
                                    nn.ReLU())
        self.self_attn = nn.MultiheadAttention(hidden, heads, batch_first=True)
        self.self_norm = nn.LayerNorm(hidden)
        self.cross_attn = nn.MultiheadAttention(hidden, heads, batch_first=True)
        self.cross_norm = nn.LayerNorm(hidden)
        if ids:
            self.register_buffer("drone_ids", torch.arange(num_drones), persistent=False)
        # with a battery, each drone's energy pair is added to its fused token (without one the encoder is the
        # one before)
        self.energy_emb = embed(2) if resources else None

    def forward(self, obs: dict[str, torch.Tensor], bases: int = 1) -> tuple[torch.Tensor, torch.Tensor,
                                                                             torch.Tensor]:
        """Drone representations (B, N, H), fire embeddings (B, K, H) and candidate validity (B, K) (the first
        ``bases`` candidates are the bases)."""
        pos, g = obs["drones"], obs["globals"]
        valid = candidate_validity(obs["fires_mask"], bases)
        # velocity = pos_t - pos_{t-1}: always 0, the planner keeps one frame (docs/model/learning.md §3.2)
        ids = [] if self.id_emb is None else [self.id_emb(self.drone_ids).expand(pos.shape[0], -1, -1)]
        tokens = torch.cat([self.pos_emb(pos), self.goal_emb(obs["goals"]), *ids,
                            self.vel_emb(torch.zeros_like(pos)), self.water_emb(obs["water"])], dim=-1)
        context = self.count_emb(g[:, 0:1]) + self.centroid_emb(g[:, 1:3]) + self.wind_emb(g[:, 3:5])
        d = self.fusion(tokens) + context.unsqueeze(1)
        if self.energy_emb is not None:
            d = d + self.energy_emb(obs["energy"])
        d = self.self_norm(d + self.self_attn(d, d, d, need_weights=False)[0])
        fires = self.fire_emb(obs["fires"])
        cross = self.cross_attn(d, fires, fires, key_padding_mask=~valid, need_weights=False)[0]
        return self.cross_norm(d + cross), fires, valid


class PointerPlannerNet(nn.Module):
    """Newest planner (docs/model/learning.md §3.2): the encoder above, a pointer actor decoded autoregressively over
    drones (each fire at most once per decision, the bases any number of times, a learnable soft penalty on
    repeats) and an attention-pooled critic on the shared encoder."""

    knows_ids = True  # each drone's id is embedded: the net flies the fleet size it was built for

    def __init__(self, num_drones: int, hidden: int = HIDDEN, heads: int = HEADS,
                 temperature: float = 1.0, resources: bool = False, distance_prior: float = 0.0, bases: int = 1):
        super().__init__()
        self.bases = bases  # drones.bases: the first candidates are the bases (a setting of the env, not a weight)
        self.resources = resources
        self.encoder = PlannerEncoder(num_drones, hidden, heads, resources, ids=self.knows_ids)
        self.query_proj = Linear(hidden, hidden)
        self.key_proj = Linear(hidden, hidden)
        self.log_temperature = nn.Parameter(torch.zeros(1))
        self.temperature = temperature  # planner.temperature, on top of the learned one
        self.log_penalty = nn.Parameter(torch.tensor([1.6]))  # c = e^1.6 ~ 4.95
        self.pool_query = nn.Parameter(torch.randn(1, 1, hidden))
        self.pool_attn = nn.MultiheadAttention(hidden, heads, batch_first=True)
        self.value_head = nn.Sequential(Linear(hidden, 2 * hidden), nn.ReLU(), Linear(2 * hidden, 1))
        init_weights(self)
        layer_init(self.value_head[-1], gain=1.0)
        self.prior = make_distance_prior(distance_prior)

    def base_logits(self, d: torch.Tensor, fires: torch.Tensor, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        """(Wq d_i) . (Wk f_j) / (sqrt(H) T), shape (B, N, K); with the distance prior, plus its term / T."""
        temperature = self.log_temperature.clamp(-3.0, 3.0).exp()
        scale = math.sqrt(d.shape[-1]) * temperature * self.temperature
        base = torch.bmm(self.query_proj(d), self.key_proj(fires).transpose(1, 2)) / scale
        return base if self.prior is None else base + self.prior(obs) / self.temperature

    def penalty(self) -> torch.Tensor:
        return self.log_penalty.clamp(-3.0, 3.0).exp()

    def blocked(self, invalid: torch.Tensor, used: torch.Tensor) -> torch.Tensor:
        """Invalid or already taken candidates; a row with nothing left falls back to the bases."""
        blocked = invalid | used
        blocked[..., :self.bases] &= ~blocked.all(-1, keepdim=True)
        return blocked

    def selectable(self, obs: dict[str, torch.Tensor], valid: torch.Tensor) -> torch.Tensor:
        """(B, 1, K) the valid candidates, the same for every drone; with resources (B, N, K): the bases only for a
        drone whose battery or tank is below half, or when no fire is listed, as the thesis net offers them. Offered
        always, a drone's nearest candidate at the start is its own base, and the distance prior would keep it there."""
        return offer_bases_to_restock(valid, obs, self.bases) if self.resources else valid.unsqueeze(1)

    def decode_logits(self, base: torch.Tensor, selectable: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """Teacher-forced per-drone logits (B, N, K): drone i sees the choices of drones 0..i-1 in ``actions``;
        ``selectable`` (B, 1 or N, K) from :meth:`selectable`."""
        onehot = F.one_hot(actions, base.shape[-1]).to(base.dtype)
        counts = onehot.cumsum(1) - onehot  # how many earlier drones chose j
        used = counts > 0
        used[..., :self.bases] = False  # the bases may repeat
        blocked = self.blocked(~selectable, used)
        return (base - self.penalty() * counts).masked_fill(blocked, float("-inf"))

    def critic(self, d: torch.Tensor) -> torch.Tensor:
        pooled = self.pool_attn(self.pool_query.expand(d.shape[0], -1, -1), d, d, need_weights=False)[0]
        return self.value_head(pooled.squeeze(1)).squeeze(-1)

    def forward_act(self, obs: dict[str, torch.Tensor], deterministic: bool = False,
                    generator: torch.Generator | None = None):
        """Actions (B, N), joint log-prob (B,), entropy (B,) and value (B,), decoding drones in id order."""
        d, fires, valid = self.encoder(obs, self.bases)
        base = self.base_logits(d, fires, obs)
        selectable = self.selectable(obs, valid)
        B, N, K = base.shape
        c = self.penalty()
        counts = base.new_zeros(B, K)
        used = torch.zeros(B, K, dtype=torch.bool, device=base.device)
        actions = torch.empty(B, N, dtype=torch.long, device=base.device)
        with torch.no_grad():
            for i in range(N):
                allowed = selectable[:, min(i, selectable.shape[1] - 1)]
                row = (base[:, i] - c * counts).masked_fill(self.blocked(~allowed, used), float("-inf"))
                a = sample_rows(row, deterministic, generator)
                actions[:, i] = a
                counts.scatter_add_(1, a.unsqueeze(1), torch.ones_like(counts[:, :1]))
                used.scatter_(1, a.unsqueeze(1), (a >= self.bases).unsqueeze(1))
        # score the chosen actions with the same teacher-forced computation as evaluate(), so both agree exactly
        log_prob, entropy = score(self.decode_logits(base, selectable, actions), actions)
        return actions, log_prob, entropy, self.critic(d)

    def evaluate(self, obs: dict[str, torch.Tensor], actions: torch.Tensor):
        """Joint log-prob (B,), entropy (B,) and value (B,) of given actions (B, N), teacher-forced."""
        d, fires, valid = self.encoder(obs, self.bases)
        logits = self.decode_logits(self.base_logits(d, fires, obs), self.selectable(obs, valid), actions)
        return (*score(logits, actions), self.critic(d))

    def value(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        return self.critic(self.encoder(obs, self.bases)[0])

    def critic_parameters(self) -> list[nn.Parameter]:
        """Pooling query, pooling attention and value MLP: the encoder is shared with the actor."""
        return [self.pool_query, *self.pool_attn.parameters(), *self.value_head.parameters()]


class FleetPlannerNet(PointerPlannerNet):
    """The pointer net for any fleet: no drone ids, so a drone is told apart by its own state (position, goal, tank,
    battery) and one set of weights flies any number of drones. The encoder is permutation-equivariant: permuting the
    drones permutes their representations and their goal scores. Decoding still goes in index order (each fire at
    most once per decision), so where two drones want the same fire, the earlier index gets it."""

    knows_ids = False


PLANNER_NETS = {"thesis": ThesisPlannerNet, "pointer": PointerPlannerNet, "fleet": FleetPlannerNet}
