"""A motion case's animated GIF: each frame a display render of that frame's camera pose and
light, drawn after every timed measurement, in the report's time.

The measurement keeps, for at most GIF_FRAMES frames of each motion case (evenly spaced, the
first and the last among them), the frame's class image and the map's V per camera pixel
(:class:`GifFrames`, in the run record, so a Ray task hands it to the driver). After the
measurement each frame is rendered again as dsm.experiment.display renders a still: a G-buffer
of the frame's pose at a whole multiple k of the camera's resolution (at least DISPLAY_MIN a
side), the frame's light set up on it with its exact visibility V*, shaded with the kit's own
Lambert term. A GIF frame is three panels of that size, labelled above:

- the frame's classes, each camera pixel k x k display pixels (nearest-neighbour), tinted over
  the N.L render as report.html tints a still's (multiply at 0.85: shade x (0.15 + 0.85 x colour));
- the exact shading (the display render under V*);
- the shading under the map: the display render's N.L times the case's V of the camera pixel
  (the map's answer where the measurement asked it); where the camera measured nothing (not a
  receiver there) the exact shading, so the two panels differ only where the map answered.

One fixed palette of 256 colours (PALETTE: 32 greys, 28 levels of each class's tint) keeps the
file small and its colours exact: a frame's tinted pixels give its classes back.
"""
from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import numpy as np

from .. import pipeline
from ..report import io as report_io
from ..report.figures import CLASSES_GIF_COMMENT
from ..report.sections import cache as cache_report
from ..report.tables import receiver_cosines, shade
from ..scenes.camera import Camera, sensor_at
from ..truth import metrics
from .display import display_scale

GIF_FRAMES = 12           # frames a GIF shows at most (evenly spaced over the path, first and last included)
FRAME_MS = 250            # each frame's time on screen
GREYS = 32                # grey levels of the palette (the exact and mapped panels, the labels)
TINT_LEVELS = 28          # levels of each class's tint (32 + 8 x 28 = 256 colours)
TINT_OPACITY = 0.85       # report.html's tint: multiply at this opacity
FONT_PX = 13              # the labels' em size in pixels: 9.75 points at one GIF pixel a CSS pixel
HEADER_PX = 36            # the strip above the panels: two lines of labels
GAP_PX = 6                # between panels


@dataclasses.dataclass
class GifFrames:
    """What one motion case's GIF needs from the measurement (plain data: it travels from a Ray task)."""
    path: str                 # the GIF, relative to the run's folder
    scene: str                # the scene's label
    light_label: str          # the plan's light label ("0:directional")
    motion: str               # the [[motion]] path's label
    title: str                # the case as the GIF's first line names it
    frames: int               # frames of the path
    index: list               # the frames shown
    poses: list               # (origin, target, up) of each frame shown (world units)
    lights: list              # LightSpec of each frame shown
    classes: list             # (H, W) uint8 class image of each frame shown
    v: list | None            # (H, W) uint8 round(255 V) of each frame shown; None: no display render wanted
    cache: list | None = None  # (H, W) uint8 ghost / missing image of each frame shown (dsm.report.sections.cache);
                               # None: no caster moves


def shown_frames(frames: int) -> list:
    """The frames a GIF shows: all of them up to GIF_FRAMES, else GIF_FRAMES evenly spaced."""
    return sorted({int(round(x)) for x in np.linspace(0, frames - 1, min(frames, GIF_FRAMES))})


def v_image(shape, pixels: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The map's V per camera pixel as round(255 V), 0 where no receiver (its class says which)."""
    out = np.zeros(shape[0] * shape[1], np.uint8)
    out[pixels] = np.round(np.clip(np.asarray(v, float), 0, 1) * 255).astype(np.uint8)
    return out.reshape(shape)


# ---------------------------------------------------------------- the palette

def _palette() -> np.ndarray:
    """(256, 3) uint8: GREYS greys from black to white, then TINT_LEVELS levels of each class's tint."""
    grey = np.round(np.linspace(0, 255, GREYS))[:, None].repeat(3, 1)
    tint = 1 - TINT_OPACITY + TINT_OPACITY * metrics.CLASS_COLORS / 255.0
    level = np.linspace(0, 1, TINT_LEVELS)
    tints = np.round(255 * level[None, :, None] * tint[:, None, :]).reshape(-1, 3)
    return np.concatenate([grey, tints]).astype(np.uint8)


PALETTE = _palette()


def grey_index(img: np.ndarray) -> np.ndarray:
    """Palette indices of a grey image in [0, 1]."""
    return np.round(np.clip(img, 0, 1) * (GREYS - 1)).astype(np.uint8)


# ---------------------------------------------------------------- a frame's display render

@dataclasses.dataclass
class FrameDisplay:
    """One frame's display render (kH x kW): its N.L and exact shadings, the receivers' cosines
    (0 elsewhere), and what every case's GIF frame reuses: the palette indices of both shadings'
    parts that do not depend on the case, and the camera pixel of each display pixel."""
    nl: np.ndarray            # in [0, 1]: every receiver lit
    exact: np.ndarray         # in [0, 1]: under V*
    cos: np.ndarray           # each receiver's cosine to the light (float32)
    receiver: np.ndarray      # bool
    k: int                    # display pixels per camera pixel, a side

    def __post_init__(self):
        self.camera_pixel = camera_pixels(*self.nl.shape, self.k)
        self.nl_level = np.round(np.clip(self.nl, 0, 1) * (TINT_LEVELS - 1)).astype(np.uint8)
        self.exact_index = grey_index(self.exact)


@functools.lru_cache(maxsize=8)
def camera_pixels(height: int, width: int, k: int) -> np.ndarray:
    """(height, width) int32: the row-major index of the camera pixel each display pixel lies in."""
    rows, cols = np.arange(height) // k, np.arange(width) // k
    return (rows[:, None] * (width // k) + cols[None, :]).astype(np.int32)


def frame_display(data, base: Camera, k: int, pose, light, label: str, seed: int, gb=None) -> FrameDisplay:
    """The display render of one frame: camera ``pose`` (origin, target, up) at k times the base
    camera's resolution (``gb``: its G-buffer, when made already), ``light`` set up on it with its
    exact visibility."""
    gb = gb or pose_gbuffer(data, base, k, pose)
    setup = pipeline.light_setup(data, gb, light, label, 0, seed)
    shape = (gb.height, gb.width)
    positional = pipeline.is_positional(light)
    receiver = np.zeros(gb.width * gb.height, bool)
    cos_img = np.zeros(gb.width * gb.height, np.float32)
    cos = None
    if setup.n is not None:
        cos = receiver_cosines(setup, positional)
        receiver[setup.pixels] = True
        cos_img[setup.pixels] = cos
    nl, exact = (shade(shape, gb, setup, v, positional, cos)
                 for v in (np.ones(len(setup.pixels)), np.asarray(setup.v_star, float)))
    return FrameDisplay(nl, exact, cos_img.reshape(shape), receiver.reshape(shape), k)


def pose_gbuffer(data, base: Camera, k: int, pose):
    """The G-buffer of camera ``pose`` at k times the base camera's resolution."""
    return pipeline.gbuffer(data, base.width * k, base.height * k, sensor=sensor_at(base, *pose))


def mapped_index(fd: FrameDisplay, up_classes: np.ndarray, up_v8: np.ndarray) -> np.ndarray:
    """Palette indices of the shading under the map: N.L times the camera pixel's V where the camera
    measured a receiver and the display pixel is one, else the exact shading (``up_``: per display pixel)."""
    measured = (up_classes != metrics.OUTSIDE) & fd.receiver
    out = fd.exact_index.copy()
    out[measured] = grey_index(0.12 + 0.88 * fd.cos[measured] * (up_v8[measured] / np.float32(255)))
    return out


def compose(fd: FrameDisplay, classes: np.ndarray, v8: np.ndarray, lines: tuple) -> np.ndarray:
    """One GIF frame as palette indices: the labels' strip over the three panels (the classes
    tinted over N.L, the exact shading, the shading under the map)."""
    up_classes = classes.reshape(-1)[fd.camera_pixel]
    h, w = up_classes.shape
    frame = np.full((HEADER_PX + h, 3 * w + 2 * GAP_PX), GREYS - 1, np.uint8)
    frame[:HEADER_PX] = _header(frame.shape[1], w, lines)
    body = frame[HEADER_PX:]
    body[:, :w] = GREYS + up_classes.astype(np.uint8) * np.uint8(TINT_LEVELS) + fd.nl_level
    body[:, w + GAP_PX:2 * w + GAP_PX] = fd.exact_index
    body[:, 2 * (w + GAP_PX):] = mapped_index(fd, up_classes, v8.reshape(-1)[fd.camera_pixel])
    return frame


PANEL_TITLES = ("classes over N.L", "exact shading (V*)", "shading under the map (V)")


@functools.lru_cache(maxsize=1)
def _font():
    """DejaVu Sans, matplotlib's own font file (the report's figures use it too), FONT_PX pixels."""
    import matplotlib
    from PIL import ImageFont
    return ImageFont.truetype(str(Path(matplotlib.get_data_path()) / "fonts" / "ttf" / "DejaVuSans.ttf"), FONT_PX)


@functools.lru_cache(maxsize=4096)
def _text(text: str) -> np.ndarray:
    """A label as palette indices, black on white, HEADER_PX / 2 high (each string drawn once)."""
    from PIL import Image, ImageDraw
    width = int(np.ceil(_font().getlength(text))) + 4
    img = Image.new("L", (width, HEADER_PX // 2), 255)
    ImageDraw.Draw(img).text((2, 1), text, fill=0, font=_font())
    return grey_index(np.asarray(img, np.float32) / 255)


def _header(width: int, panel: int, lines: tuple) -> np.ndarray:
    """The labels' strip: ``lines`` (left, right) on the first line, the panels' titles on the second."""
    strip = _titles(width, panel).copy()
    for x, text in ((0, lines[0]), (None, lines[1])):
        _blit(strip, 0, width - _text(text).shape[1] if x is None else x, _text(text))
    return strip


@functools.lru_cache(maxsize=8)
def _titles(width: int, panel: int) -> np.ndarray:
    """The strip with the panels' titles alone (the same on every frame)."""
    strip = np.full((HEADER_PX, width), GREYS - 1, np.uint8)
    for i, text in enumerate(PANEL_TITLES):
        _blit(strip, HEADER_PX // 2, i * (panel + GAP_PX), _text(text))
    return strip


def _blit(strip: np.ndarray, y: int, x: int, img: np.ndarray):
    """``img`` into ``strip`` at (y, x), cut at the strip's right edge."""
    cut = img[:, :max(0, min(img.shape[1], strip.shape[1] - x))]
    strip[y:y + img.shape[0], x:x + cut.shape[1]] = cut


# ---------------------------------------------------------------- writing

def write_gifs(out: Path, cfg, pending: list, display: bool) -> list:
    """Every pending motion GIF into ``out``: frames of display renders (``display``: a complete
    run writing every image), else the frames' class images; returns notes on what failed."""
    notes = []
    for g in pending:                 # moving casters: the frames' ghosts and missing shadows over their classes
        if g.cache is not None:
            cache_report.write_gif(Path(out) / cache_report.gif_path(g.path), g.classes, g.cache)
    if not display or any(g.v is None for g in pending):
        for g in pending:
            _write_classes_gif(Path(out) / g.path, g.classes)
        return notes
    order = sorted(pending, key=lambda g: (g.scene, g.motion, g.light_label))
    for spec in cfg.scenes:
        mine = [g for g in order if g.scene == spec.label]
        if not mine:
            continue
        try:
            data = pipeline.load_scene(spec, cfg.camera_resolution, cfg.camera)
        except Exception as e:        # the measurement ran; a display render is never worth failing it
            notes.append(f"motion GIFs of scene {spec.label}: {type(e).__name__}: {e}; class images instead")
            for g in mine:
                _write_classes_gif(Path(out) / g.path, g.classes)
            continue
        _write_scene(Path(out), data, mine, cfg.seed)
    return notes


def _write_scene(out: Path, data, mine: list, seed: int):
    """One scene's display GIFs; a path and light's frames rendered once for all its cases."""
    base = Camera.from_sensor(data.sensor)
    k = display_scale(base.width, base.height)
    gbs, renders, key = {}, {}, None
    for g in mine:
        if (g.motion, g.light_label) != key:                  # the renders of one path and light at a time
            gbs = gbs if key is not None and key[0] == g.motion else {}     # G-buffers: per pose of a path
            key, renders = (g.motion, g.light_label), {}
        frames = []
        for t, pose, light, classes, v8 in zip(g.index, g.poses, g.lights, g.classes, g.v):
            pk = tuple(np.round(np.concatenate(pose), 12))
            if pk not in gbs:
                gbs[pk] = pose_gbuffer(data, base, k, pose)
            if (t, light) not in renders:
                renders[(t, light)] = frame_display(data, base, k, pose, light, g.light_label, seed, gbs[pk])
            frames.append(compose(renders[(t, light)], classes, v8, (g.title, f"frame {t + 1} of {g.frames}")))
        _save(out / g.path, frames)


def _save(path: Path, frames: list):
    """Palette frames as an animated GIF (Pillow), FRAME_MS a frame, looping."""
    from PIL import Image
    images = []
    for f in frames:
        im = Image.fromarray(f, "P")
        im.putpalette(PALETTE.tobytes())
        images.append(im)
    path.parent.mkdir(parents=True, exist_ok=True)
    with report_io.atomic(path) as tmp:
        images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:], duration=FRAME_MS, loop=0,
                       optimize=False)


def _write_classes_gif(path: Path, images: list):
    """The frames' class images alone as an animated GIF (no display render: [report] images =
    "errors", or a run that did not complete)."""
    from PIL import Image
    frames = [Image.fromarray(metrics.CLASS_COLORS[c]) for c in images]
    path.parent.mkdir(parents=True, exist_ok=True)
    with report_io.atomic(path) as tmp:
        frames[0].save(tmp, format="GIF", save_all=True, append_images=frames[1:], duration=FRAME_MS, loop=0,
                       comment=CLASSES_GIF_COMMENT)      # report.html's caption tells the two kinds by it
