"""What a run writes to TensorBoard besides scalars: its config (text tab and HParams) and evaluation episodes as
videos. One implementation for every level (FlyAgent and planner).

``SummaryWriter.add_video`` encodes with moviepy, which is not installed (and pulls in ffmpeg); the event it
writes is an animated GIF in an image summary, so :func:`add_video` writes that same event with Pillow.
"""

import io
import math

import numpy as np
import yaml
from PIL import Image
from tensorboard.compat.proto.summary_pb2 import Summary

# An update's metrics under the original's TensorBoard tags (docs/model/learning.md §11)
UPDATE_TAGS = {"Rewards/Rewards_Raw": "rewards_raw", "Rewards/Rewards_norm": "rewards_scaled",
               "Rewards/Returns": "returns", "Rewards/Advantages": "advantages", "Rewards/Values": "values",
               "Training/Approx_KL": "approx_kl", "Training/Clip_Fraction": "clip_fraction",
               "Training/actor_loss": "actor_loss", "Training/value_loss": "value_loss",
               "Training/entropy_loss": "entropy", "Training/log_std": "std", "Training/LR": "lr",
               "Training/saturated": "saturated", "Training/mean_excess": "mean_excess",
               "Training/grad_norm_actor": "grad_norm_actor", "Training/grad_norm_critic": "grad_norm_critic",
               "Sanitylogs/Explained_Variance": "explained_variance", "Perf/steps_per_s": "steps_per_s"}


def log_update(writer, step: int, metrics: dict) -> None:
    """An update's metrics (NaN ones skipped: a metric the update could not measure)."""
    for tag, key in UPDATE_TAGS.items():
        if key in metrics and metrics[key] == metrics[key]:
            writer.add_scalar(tag, metrics[key], step)
    for key, value in metrics.items():  # TD3 / IQL metrics are named "group/name" already
        if "/" in key and value == value:
            writer.add_scalar(key, value, step)


def log_episodes(writer, step: int, ep: dict, reasons: tuple[str, ...]) -> None:
    """The training episodes that ended since the last write: success, return, length and each failure's rate
    (only the failures this level's records can hold)."""
    writer.add_scalar("Episodes/success_rate", ep["success"], step)
    writer.add_scalar("Episodes/return", ep["return"], step)
    writer.add_scalar("Sanitylogs/Episode_Steps", ep["steps"], step)
    for name in reasons:
        writer.add_scalar(f"Episodes/{name}_rate", ep[f"{name}_rate"], step)


def add_config(writer, config: dict, step: int = 0) -> None:
    """The resolved config as YAML in the text tab (``Run/config``)."""
    text = yaml.safe_dump(config, sort_keys=False)
    writer.add_text("Run/config", "```yaml\n" + text + "```", step)  # markdown: a code block keeps the layout


def flat_hparams(config: dict, prefix: str = "") -> dict:
    """A nested config as ``{"section.key": value}`` with values TensorBoard's HParams accepts (lists and None
    as text)."""
    out = {}
    for key, value in config.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(flat_hparams(value, f"{name}."))
        elif isinstance(value, bool | int | float | str):
            out[name] = value
        else:
            out[name] = str(value)
    return out


def add_hparams(writer, config: dict, metrics: dict[str, float]) -> None:
    """The config's keys as hyperparameters with the run's final / best metrics (the HParams tab); non-finite
    metrics (no evaluation ran) are left out."""
    finite = {f"hparam/{k}": float(v) for k, v in metrics.items() if v is not None and math.isfinite(v)}
    writer.add_hparams(flat_hparams(config), finite, run_name="hparams")


class EpisodeFrames:
    """Collects env 0's frames while its first episode runs, at most ``max_frames`` of them: steps 1, 1 + k,
    1 + 2k, ..., k = ceil(longest episode / max_frames). Use as ``run_episodes(..., on_step=frames.on_step)``
    (run_episodes resets the env first, so the frames start with its first step)."""

    def __init__(self, env, max_frames: int, max_steps: int):
        self.env, self.stride = env, max(1, math.ceil(max_steps / max(1, max_frames)))
        self.frames: list[np.ndarray] = []
        self.steps, self.done, self.max_frames = 0, False, max_frames

    def on_step(self, obs, actions, rewards, terms, truncs, info) -> None:
        if self.done:
            return
        self.steps += 1
        ended = bool(info["_episode_stats"][0])
        # after an end env 0 shows the next episode's first scene (same-step reset): no frame then
        if not ended and len(self.frames) < self.max_frames and (self.steps - 1) % self.stride == 0:
            self.frames.append(self.env.render())
        self.done = ended


def gif_bytes(frames: list[np.ndarray], fps: float, width: int = 360) -> bytes:
    """(H, W, 3) uint8 frames as a looping GIF, scaled down to ``width`` pixels if wider."""
    images = [Image.fromarray(np.asarray(f, np.uint8)).convert("RGB") for f in frames]
    if images[0].width > width:
        size = (width, round(images[0].height * width / images[0].width))
        images = [im.resize(size, Image.BILINEAR) for im in images]
    buf = io.BytesIO()
    images[0].save(buf, format="GIF", save_all=True, append_images=images[1:], duration=max(1, round(1000 / fps)),
                   loop=0)
    return buf.getvalue()


def add_video(writer, tag: str, frames: list[np.ndarray], step: int, fps: float = 4.0) -> None:
    """``writer.add_video`` without moviepy: the same event (a GIF image summary, shown as a video)."""
    data = gif_bytes(frames, fps)
    with Image.open(io.BytesIO(data)) as im:
        w, h = im.size
    image = Summary.Image(height=h, width=w, colorspace=3, encoded_image_string=data)
    writer._get_file_writer().add_summary(Summary(value=[Summary.Value(tag=tag, image=image)]), step)
