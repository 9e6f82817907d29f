"""What a training run leaves in TensorBoard besides the scalars: the config (text tab and HParams), a video of an
evaluation episode at every periodic evaluation, the thesis metrics of each evaluation, and why training stopped."""

import io
from pathlib import Path

import pytest
from click.testing import CliRunner
from PIL import Image
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
from tensorboard.plugins.hparams import plugin_data_pb2

from roshan.cli import main

ROOT = Path(__file__).resolve().parents[2]
TINY = ["--set", "map.name=21x21_Field", "--set", "sim.envs=2", "--set", "ppo.horizon=64", "--set", "ppo.batch_size=32",
        "--set", "train.total_steps=0", "--set", "train.max_minutes=0", "--set", "train.max_updates=2",
        "--set", "train.eval_every=1", "--set", "train.eval_episodes=2", "--set", "train.eval_envs=2",
        "--set", "train.eval_video_frames=3"]


def events(folder: Path) -> EventAccumulator:
    acc = EventAccumulator(str(folder), size_guidance={"images": 0, "tensors": 0, "scalars": 0})
    acc.Reload()
    return acc


@pytest.mark.slow
def test_a_tiny_run_logs_config_hparams_video_and_evaluation_metrics(tmp_path):
    res = CliRunner().invoke(main, ["train", str(ROOT / "configs/fly_simple.yaml"), "--root", str(tmp_path),
                                    "--name", "tb", "--no-eval", *TINY], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    assert "training stopped: train.max_updates = 2 reached" in res.output
    acc = events(tmp_path / "tb" / "tb")
    tags = acc.Tags()
    # one evaluation episode of env 0 as a video (an animated GIF image summary) per periodic evaluation
    videos = acc.Images("Evaluation/episode_env0")
    assert [v.step for v in videos] == [e.step for e in acc.Scalars("Evaluation/Success_rate")]
    assert len(videos) == 2
    with Image.open(io.BytesIO(videos[0].encoded_image_string)) as gif:
        assert gif.format == "GIF" and 2 <= gif.n_frames <= 3
    # the config in the text tab, and the budget that stopped the run
    config = acc.Tensors("Run/config/text_summary")[0].tensor_proto.string_val[0].decode()
    assert "eval_video_frames: 3" in config and "algo: ppo" in config
    assert "max_updates" in acc.Tensors("Run/stopped/text_summary")[0].tensor_proto.string_val[0].decode()
    # the thesis metrics of each evaluation
    for name in ("Success_rate", "Collision_rate", "Boundary_rate", "Timeout_rate", "Time_mean"):
        assert len(acc.Scalars(f"Evaluation/{name}")) == 2, name
    assert "Episodes/burnout_rate" not in tags["scalars"]  # a FlyAgent episode cannot burn out
    # the hyperparameters with the final metrics (the HParams tab)
    hp = events(tmp_path / "tb" / "tb" / "hparams")
    start = plugin_data_pb2.HParamsPluginData.FromString(
        hp.PluginTagToContent("hparams")["_hparams_/session_start_info"]).session_start_info
    assert start.hparams["train.eval_video_frames"].number_value == 3
    assert start.hparams["train.algo"].string_value == "ppo"
    assert {"hparam/best_eval_success", "hparam/last_eval_success", "hparam/last_eval_timeout_rate"} <= set(
        hp.Tags()["scalars"])
