"""``roshan watch RUN``: a trained FlyAgent or planner flying live in a GGUI window (RL-Zoo's ``enjoy``), or,
where no display exists, env 0's first episode written as a GIF.

One env runs with the run's deterministic policy and its evaluation setting. The window shows the frames of
``env.render()`` (caption, map, legend): every step, including the final state of each episode before the next
one starts; it runs until ``steps`` env steps are done or the window is closed.
"""

import os
import time
from pathlib import Path

import numpy as np
import torch

from roshan.algos.frozen import load_for_acting, policy_fn
from roshan.algos.networks import flatten_drones
from roshan.ggui import open_shown_window
from roshan.io import prepare_output, refuse_overwrite, write_gif, writing
from roshan.runs.envs import caption_name, make_env
from roshan.runtime import ensure_taichi, torch_device, use_acting_threads


def has_display() -> bool:
    """Whether a window could be shown: an X11 or Wayland display is named in the environment."""
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


DEFAULT_GIF = Path("out") / "watch.gif"  # under out/ (gitignored): a checkout stays clean after the README's commands


@torch.no_grad()
def watch(target: str | Path, steps: int | None = None, seed: int = 0, which: str = "best", fps: float = 10.0,
          gif_path: Path = DEFAULT_GIF, screenshot: Path | None = None,
          overrides: list[str] | tuple[str, ...] = (), replace: bool = False) -> str:
    """Fly the run's policy in one env and show it; returns a line saying what was shown or written.

    Args:
        target: a run folder or checkpoint (FlyAgent or planner).
        steps: env steps to run (planner: decisions); None = until the window is closed, or, without a
            window, until env 0's first episode ends.
        seed: env seed (the fire layouts and wind of ``roshan eval --seed``).
        fps: at most this many frames a second in the window.
        gif_path: where env 0's frames go when no window can be shown.
        screenshot: save the last frame as this PNG: the window's (read back from GGUI), or without a window the
            GIF's last frame (the same picture, drawn by the raster renderer).
        replace: overwrite an existing ``gif_path`` or ``screenshot``; without it they are refused before anything
            runs.
    """
    refuse_overwrite(screenshot, "the screenshot", replace)
    if not has_display():  # the GIF will be written: refuse an existing one before any work
        refuse_overwrite(gif_path, "the GIF", replace)
    ensure_taichi()
    _, cfg, agent, path = load_for_acting(target, which, overrides, torch_device())
    use_acting_threads(cfg.train.torch_threads)
    run_dir = path.parent.parent if path.parent.name == "checkpoints" else path.parent
    env = make_env(cfg, 1, seed, evaluation=True, render_mode="rgb_array")  # it keeps each episode's final frame
    env.caption_name = caption_name(env.default_caption_name, run_dir)
    try:
        obs, _ = env.reset(seed=seed)
        first = env.render()
        window, why = _try_window(first.shape) if has_display() else (None, "no display (DISPLAY is not set)")
        if window is None:
            refuse_overwrite(gif_path, "the GIF", replace)  # a display without a window: before the episode
            prepare_output(gif_path, "the GIF", is_dir=False)
            if screenshot is not None:
                prepare_output(screenshot, "the screenshot", is_dir=False)
            frames = _fly(env, agent, obs, steps, first, stop_at_episode_end=True)
            with writing("the GIF", gif_path):
                write_gif(frames, gif_path, fps=max(1, round(fps)))
            said = f"{why}: wrote {len(frames)} frames of env 0 to {gif_path} instead of showing a window"
            if screenshot is not None:  # the last frame, as the window would have shown it
                _save_png(frames[-1], screenshot)
                said += f"; screenshot (its last frame): {screenshot}"
            return said
        if screenshot is not None:
            prepare_output(screenshot, "the screenshot", is_dir=False)
        shown, last = _show_live(env, agent, obs, steps, first, window, fps, screenshot)
        if screenshot is not None and steps is None:  # closed by hand: the last frame shown
            _save_png(last, screenshot)
        return f"showed {shown} frames of {run_dir.name}" + (f"; screenshot: {screenshot}" if screenshot else "")
    finally:
        env.close()


def _try_window(shape: tuple[int, ...]):
    """(window, None), or (None, why) when the display exists but GGUI cannot open a window on it."""
    try:
        return open_shown_window((shape[1], shape[0]), "roshan watch"), None
    except Exception as err:  # no Vulkan, no X server answering: fall back to the GIF
        return None, f"no window could open ({err})"


def _next_frames(env, act, obs):
    """One env step with the policy: (obs, the frames it produced, whether env 0's episode ended).

    An episode's end gives two frames: its final state and the next episode's first state."""
    actions = act(flatten_drones(obs)).view(1, env.num_drones, 2) if env.flat_drones else act(obs)
    obs, _, _, _, info = env.step(actions)
    if bool(info["_episode_stats"][0]):
        return obs, [env.final_frame, env.render()], True
    return obs, [env.render()], False


def _fly(env, agent, obs, steps, first, stop_at_episode_end: bool) -> list[np.ndarray]:
    act = policy_fn(agent)
    frames = [first]
    done = 0
    while steps is None or done < steps:
        obs, new, ended = _next_frames(env, act, obs)
        done += 1
        if ended and stop_at_episode_end:
            frames.append(new[0])
            break
        frames += new
    return frames


def _show_live(env, agent, obs, steps, first, window, fps: float, screenshot: Path | None) -> tuple[int, np.ndarray]:
    act = policy_fn(agent)
    canvas = window.get_canvas()
    shown, done, last = 0, 0, first
    pending = [first]
    while window.running and (steps is None or done < steps or pending):
        if not pending:
            obs, pending, _ = _next_frames(env, act, obs)
            done += 1
        t0 = time.perf_counter()
        last = pending.pop(0)
        canvas.set_image(np.ascontiguousarray(last[::-1].transpose(1, 0, 2)))  # GGUI: (x, y), y = 0 at the bottom
        if screenshot is not None and steps is not None and done >= steps and not pending:
            _save_window(window, screenshot)
        window.show()
        shown += 1
        time.sleep(max(0.0, 1.0 / fps - (time.perf_counter() - t0)))
    window.destroy()
    return shown, last


def _save_png(frame: np.ndarray, path: Path) -> None:
    from PIL import Image

    with writing("the screenshot", path):
        Image.fromarray(np.ascontiguousarray(frame)).save(path)


def _save_window(window, path: Path) -> None:
    """The window's current image as an RGB PNG (read back from GGUI before ``show``)."""
    from PIL import Image

    buf = window.get_image_buffer_as_numpy()  # (W, H, 4) floats in 0..1, y = 0 at the bottom
    rgb = np.rint(buf[:, ::-1, :3] * 255.0).astype(np.uint8).transpose(1, 0, 2)
    with writing("the screenshot", path):
        Image.fromarray(np.ascontiguousarray(rgb)).save(path)
