"""Seeing a trained policy: an animated GIF of a saved model on a few fixed episodes.

Rendered offscreen from the SB3 model file (and its VecNormalize statistics, if it was trained
with them) and the environment settings the run was trained with, by the env's adapter
([`kraby_study.env`][]): the leg reaching its first fixed targets, a Gymnasium env's first episodes
of the fixed set (the same for every GIF, so that GIFs of two values show the same starts; a run's
score comes from episodes of its own). Actions are deterministic, so a rerun
draws the same GIF.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from kraby_study.env import adapter_for, saved_normalizer

FRAME_SIZE = (160, 120)
"""Width and height of a frame (pixels), before the caption strip."""
CAPTION_HEIGHT = 16
PALETTE_COLOURS = 64


def _font(size: int) -> Any:
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)
    except (TypeError, OSError):  # Pillow without FreeType: the small bitmap font
        return ImageFont.load_default()


def _captioned(frame: np.ndarray, size: tuple[int, int], text: str, font: Any,
               view: tuple[float, float, float]) -> Any:
    """The frame cropped to the adapter's ``view`` (fraction kept, centre x, centre y),
    shrunk to ``size`` and captioned below."""
    from PIL import Image, ImageDraw

    zoom, centre_x, centre_y = view
    height, width = frame.shape[:2]
    crop_w, crop_h = width * zoom, height * zoom
    left = min(max(centre_x * width - crop_w / 2, 0), width - crop_w)
    top = min(max(centre_y * height - crop_h / 2, 0), height - crop_h)
    image = Image.fromarray(np.ascontiguousarray(frame[..., :3]))
    image = image.crop((round(left), round(top), round(left + crop_w), round(top + crop_h)))
    image = image.resize(size, Image.Resampling.LANCZOS)
    canvas = Image.new("RGB", (size[0], size[1] + CAPTION_HEIGHT), (255, 255, 255))
    canvas.paste(image, (0, 0))
    ImageDraw.Draw(canvas).text((4, size[1] + 2), text, fill=(30, 30, 30), font=font)
    return canvas


def render_policy(model_path: str, settings: dict[str, Any], path: Path,
                  size: tuple[int, int] = FRAME_SIZE) -> Path:
    """Write an animated GIF of a saved policy's first evaluation episodes.

    Args:
        model_path: The SB3 PPO zip file (a ``.vecnormalize.pkl`` beside it is used).
        settings: The run's resolved settings; ``settings["env"]`` configures the env.
        path: Where to write the GIF.
        size: Frame width and height (pixels).

    Returns:
        The GIF's path.
    """
    from stable_baselines3 import PPO

    env = dict(settings.get("env") or {})
    adapter = adapter_for(env)
    model = PPO.load(model_path, device="cpu")
    normalizer = saved_normalizer(model_path)
    font = _font(11)
    frames, durations = [], []
    for frame in adapter.frames(model, env, size, normalizer):
        frames.append(_captioned(frame.image, size, frame.caption, font, adapter.view))
        durations.append(frame.duration_ms)
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
