"""Seeing a trained policy: an animated GIF of a saved model reaching a few fixed targets.

Rendered offscreen (PyBullet's tiny renderer) from the SB3 model file and the environment
settings the run was trained with; actions are deterministic, so a rerun draws the same GIF.
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from kraby_study.config.schema import EnvConfig
from kraby_study.config.validate import env_kwargs

FRAME_SIZE = (160, 120)
"""Width and height of a rendered frame (pixels), before the caption strip."""
ZOOM = 0.7
"""Fraction of the environment's camera view kept (centred on the leg's workspace): the frames
are rendered larger, cropped and shrunk, so the leg fills more of a small, anti-aliased frame."""
CROP_CENTRE = (0.48, 0.45)
CAPTION_HEIGHT = 16
PALETTE_COLOURS = 64
STEPS_PER_TARGET = 32
HOLD_MS = 700
"""How long the last frame of each target stays on screen."""
TARGETS = 3
"""Episodes drawn: the first of the fixed targets a search's evaluation scores."""


def _font(size: int) -> Any:
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)
    except (TypeError, OSError):  # Pillow without FreeType: the small bitmap font
        return ImageFont.load_default()


def _captioned(frame: np.ndarray, size: tuple[int, int], text: str, font: Any) -> Any:
    from PIL import Image, ImageDraw

    height, width = frame.shape[:2]
    crop_w, crop_h = width * ZOOM, height * ZOOM
    left = min(max(CROP_CENTRE[0] * width - crop_w / 2, 0), width - crop_w)
    top = min(max(CROP_CENTRE[1] * height - crop_h / 2, 0), height - crop_h)
    view = Image.fromarray(frame).crop(
        (round(left), round(top), round(left + crop_w), round(top + crop_h)))
    view = view.resize(size, Image.Resampling.LANCZOS)
    canvas = Image.new("RGB", (size[0], size[1] + CAPTION_HEIGHT), (255, 255, 255))
    canvas.paste(view, (0, 0))
    ImageDraw.Draw(canvas).text((4, size[1] + 2), text, fill=(30, 30, 30), font=font)
    return canvas


def render_policy(model_path: str, settings: dict[str, Any], path: Path,
                  steps: int = STEPS_PER_TARGET, size: tuple[int, int] = FRAME_SIZE) -> Path:
    """Write an animated GIF of a saved policy reaching the first :data:`TARGETS` fixed targets
    (:func:`kraby_envs.rollout.fixed_targets`).

    Args:
        model_path: The SB3 PPO zip file.
        settings: The run's resolved settings; ``settings["env"]`` configures the leg.
        path: Where to write the GIF.
        steps: Environment steps per target.
        size: Frame width and height (pixels).

    Returns:
        The GIF's path.
    """
    import gymnasium as gym
    from omegaconf import OmegaConf
    from stable_baselines3 import PPO

    import kraby_envs  # noqa: F401 - registers KrabyOneLeg-v0
    from kraby_envs.rollout import fixed_targets, rollout

    env_settings = {**asdict(EnvConfig()), **dict(settings.get("env") or {})}
    kwargs = env_kwargs(OmegaConf.create(env_settings))
    model = PPO.load(model_path, device="cpu")

    def act(observation: Any) -> Any:
        return model.predict(observation, deterministic=True)[0]

    render = (round(2 * size[0]), round(2 * size[1]))
    env = gym.make(kraby_envs.ENV_ID, render_mode="rgb_array", render_width=render[0],
                   render_height=render[1], max_episode_steps=steps, **kwargs)
    font = _font(11)
    frames, durations = [], []
    period_ms = int(round(1000 * kwargs["time_step"] * kwargs["frameskip"]))
    try:
        targets = fixed_targets(TARGETS, float(kwargs["delta"]))
        for index, target in enumerate(targets):
            for moment in rollout(env, act, target, seed=index):
                label = (f"target {index + 1}/{len(targets)}  "
                         f"t={moment.step * period_ms / 1000:.2f} s  "
                         f"{100 * moment.info['distance']:.1f} cm")
                frames.append(_captioned(env.render(), size, label, font))
                durations.append(HOLD_MS if moment.ended else max(period_ms, 20))
    finally:
        env.close()
    path.parent.mkdir(parents=True, exist_ok=True)
    frames = _on_shared_palette(frames)
    frames[0].save(path, save_all=True, append_images=frames[1:], duration=durations, loop=0,
                   optimize=True, disposal=1)
    return path


def _on_shared_palette(frames: list[Any], colours: int = PALETTE_COLOURS) -> list[Any]:
    """The frames on one small palette drawn from a sample of them: a GIF a third the size."""
    from PIL import Image

    sample = frames[:: max(1, len(frames) // 12)]
    width, height = sample[0].size
    sheet = Image.new("RGB", (width, height * len(sample)))
    for index, frame in enumerate(sample):
        sheet.paste(frame, (0, height * index))
    # Octree keeps small saturated regions (the green target) that median cut merges away.
    palette = sheet.quantize(colors=colours, method=Image.Quantize.FASTOCTREE)
    return [frame.quantize(palette=palette, dither=Image.Dither.NONE) for frame in frames]
