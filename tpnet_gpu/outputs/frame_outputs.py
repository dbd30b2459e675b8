"""One frame's results as files (docs/outputs.md): the raw float TIFFs, depth, the point cloud, the texture, and a
labelled figure (``tpnet_gpu.outputs.figures``) beside each map. ``tpnet process`` and ``tpnet demo`` write through
``write`` into the folder ``tpnet_gpu.outputs.output_folder`` gives them (whole or not at all).

Files (tile maps are ``(ceil(h / 8), ceil(w / 8))``, one value per tile, for inputs of h x w pixels):

* ``disparity.tif`` float32 px (NaN: unmeasured), ``confidence.tif`` float32 (0: none, unitless),
  ``depth.tif`` float32 metres (NaN: unmeasured, +inf: disparity <= 0) - each with its figure ``NAME.png``;
* ``points.ply``: one point per tile of finite positive disparity, metres, rig axes (``tpnet_gpu.outputs.pointcloud``);
* ``texture.tif`` float32 ``(channels, h, w)`` (R, G, B, alpha or Y, alpha; the frames' units), ``texture.png``
  its 8-bit picture (pixels, RGBA) and ``texture_figure.png`` that picture with axes and a title;
* ``disparity_px.tif`` float32 ``(h, w)`` px per pixel (NaN: none) and its figure, where the pipeline made one
  (mono frames of a stereo pair, ``PipelineConfig.per_pixel``), ``measured_px.png`` (255: the pixel passed the
  left-right check, 0: background fill) where that check ran; with ``per_pixel`` (``tpnet process --per-pixel``)
  also ``depth_px.tif`` and ``points_px.ply`` (a point per measured pixel);
* with ``tpnet process --two-surface`` (``write_surfaces``): ``foreground.tif``, ``background.tif`` float32 px and
  ``w_foreground.tif`` (the foreground's weight), NaN where the tile shows one surface.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from tpnet_gpu.outputs import pointcloud
from tpnet_gpu.camera import Rig

log = logging.getLogger(__name__)

MAPS = ("disparity", "confidence", "depth")  # the tile maps written as TIFF + figure


@dataclass(frozen=True, eq=False)
class FrameMaps:
    """A frame's results on the host, cut to the inputs' size.

    Attributes:
        disparity: ``(tiles_y, tiles_x)`` float32 px, NaN where unmeasured.
        confidence: ``(tiles_y, tiles_x)`` float32, 0 where none.
        texture: ``(channels, h, w)`` float32 (R, G, B, alpha or Y, alpha) or None.
        rig: the rig whose virtual camera the tile grid is in (depth and points go through it).
        white: the texture level drawn as white in the 8-bit pictures and the points' colours (frames' units).
        pixels: ``(h, w)`` float32 disparity per pixel, px, NaN where none; or None.
        measured: ``(h, w)`` bool, the pixels of ``pixels`` the per-pixel left-right check kept (the rest is
            the background fill, disparity.md §10); or None (no check ran: every value is a match).
    """

    disparity: np.ndarray
    confidence: np.ndarray
    texture: np.ndarray | None
    rig: Rig
    white: float
    pixels: np.ndarray | None = None
    measured: np.ndarray | None = None

    @property
    def size(self) -> tuple[int, int]:
        """``(h, w)`` pixels of the inputs: the texture's, else the tiles' * 8."""
        if self.texture is not None:
            return self.texture.shape[1:]
        return self.disparity.shape[0] * 8, self.disparity.shape[1] * 8


def from_result(result, rig: Rig, *, frames=None, white: float | None = None) -> FrameMaps:
    """``FrameMaps`` of a ``pipeline.FrameResult``, cut by ``frames`` (``stereo_io.Frames``; None: uncut);
    ``white`` None: the 99.5th percentile of the texture's colours (an automatic exposure)."""
    def host(t):
        return None if t is None else t.detach().cpu().numpy().astype(np.float32)

    disparity, confidence, texture = host(result.disparity), host(result.confidence), host(result.texture)
    pixels = host(result.pixels)
    measured = None if result.pixels_measured is None else result.pixels_measured.detach().cpu().numpy()
    if frames is not None:
        disparity, confidence = frames.crop_tiles(disparity), frames.crop_tiles(confidence)
        texture = None if texture is None else frames.crop_image(texture)
        pixels = None if pixels is None else frames.crop_image(pixels)
        measured = None if measured is None else frames.crop_image(measured)
    if white is None:
        white = float(np.nanpercentile(texture[:-1], 99.5)) if texture is not None else 1.0
    return FrameMaps(disparity, confidence, texture, rig, max(white, 1e-9), pixels, measured)


def method(pipeline) -> str:
    """What made the disparity, for titles: TPNET and its weights' file name, or the engine alone."""
    return "disparity engine" if pipeline.weights is None else f"TPNET, weights {pipeline.weights.name}"


def texture_rgba(texture: np.ndarray, white: float) -> np.ndarray:
    """``(C, H, W)`` R, G, B, alpha (or Y, alpha; raw units) -> ``(H, W, 4)`` uint8, gamma ``pointcloud.GAMMA``."""
    colour = texture[:-1] if texture.shape[0] == 4 else np.repeat(texture[:1], 3, axis=0)
    rgb = np.clip(np.nan_to_num(colour) / max(white, 1e-9), 0, 1) ** (1 / pointcloud.GAMMA)
    alpha = np.clip(np.nan_to_num(texture[-1]), 0, 1)
    return (np.concatenate([rgb, alpha[None]], axis=0).transpose(1, 2, 0) * 255 + 0.5).astype(np.uint8)


def map_panels(maps: FrameMaps, what: str, *, low: float | None = None, high: float | None = None) -> dict:
    """The figure panels of the tile maps (name -> ``figures.Panel``); ``low`` / ``high``: the disparity's
    colour scale (default: its percentiles)."""
    from tpnet_gpu.outputs.figures import Panel  # noqa: PLC0415 - matplotlib on use

    return {
        "disparity": Panel(maps.disparity, f"disparity: {what}", "disparity", "px", "turbo", low, high),
        # where the per-pixel check ran, a tile's confidence is the share of its window backing it (disparity.md §10)
        "confidence": (Panel(maps.confidence, "confidence: per-pixel check", "share of the window backing the answer",
                             "0..1", "magma", 0.0, 1.0) if maps.measured is not None else
                       Panel(maps.confidence, "confidence: disparity engine", "correlation peak strength",
                             "unitless", "magma", 0.0)),
        "depth": Panel(pointcloud.depth(maps.disparity, maps.rig), f"depth: {what}", "depth Z", "m", "turbo_r",
                       log=True),
    }


def write(folder, maps: FrameMaps, *, scene: str, what: str, figures: bool = True, per_pixel: bool = False) -> list[str]:
    """Write the files of the module docstring into ``folder``; ``figures`` False: no figures (no matplotlib);
    ``per_pixel``: also depth and points per pixel (``maps.pixels`` must exist). ``scene`` and ``what`` (the
    method) go into the titles and the PLY header. Returns the files' names."""
    if per_pixel and maps.pixels is None:
        raise ValueError("per_pixel: these results have no per-pixel disparity (mono images of a stereo pair)")
    import tifffile  # noqa: PLC0415

    from tpnet_gpu.io.images import save_png  # noqa: PLC0415

    written = []
    values = {"disparity": maps.disparity, "confidence": maps.confidence,
              "depth": pointcloud.depth(maps.disparity, maps.rig)}
    for name in MAPS:
        tifffile.imwrite(folder / f"{name}.tif", values[name].astype(np.float32))
        written.append(f"{name}.tif")
    points, mask = pointcloud.tile_points(maps.disparity, maps.rig)
    colours = None if maps.texture is None else pointcloud.tile_colours(maps.texture, maps.white)[mask]
    pointcloud.write_ply(folder / "points.ply", points, colours, scalars={"confidence": maps.confidence[mask]},
                         comments=(f"tpnet-gpu {scene}, {what}: one point per measured tile",
                                   "metres; rig axes: x right, y up, z toward the viewer (points in front: z < 0)",
                                   f"colours: the texture's alpha-weighted mean over the tile's 8x8 cell / white "
                                   f"{maps.white:.9g}, gamma {pointcloud.GAMMA}"))
    written.append("points.ply")
    log.info("%s: %d points of %d tiles", "points.ply", len(points), mask.size)
    if maps.pixels is not None:
        written += _write_pixels(folder, maps, scene=scene, what=what, per_pixel=per_pixel)
    if maps.texture is not None:
        tifffile.imwrite(folder / "texture.tif", maps.texture.astype(np.float32), photometric="minisblack")
        save_png(folder / "texture.png", texture_rgba(maps.texture, maps.white))
        written += ["texture.tif", "texture.png"]
    if figures:
        written += _figures(folder, maps, scene=scene, what=what)
    log.debug("wrote %s", ", ".join(written))
    return written


def _write_pixels(folder, maps: FrameMaps, *, scene: str, what: str, per_pixel: bool) -> list[str]:
    """``disparity_px.tif`` (and ``measured_px.png`` where the left-right check ran); with ``per_pixel`` also
    ``depth_px.tif`` and ``points_px.ply`` (measured pixels only: no point for a filled one)."""
    import tifffile  # noqa: PLC0415

    from tpnet_gpu.io.images import save_png  # noqa: PLC0415

    tifffile.imwrite(folder / "disparity_px.tif", maps.pixels.astype(np.float32))
    written = ["disparity_px.tif"]
    if maps.measured is not None:
        save_png(folder / "measured_px.png", np.where(maps.measured, 255, 0).astype(np.uint8))
        written.append("measured_px.png")
    if not per_pixel:
        return written
    tifffile.imwrite(folder / "depth_px.tif", pointcloud.depth(maps.pixels, maps.rig))
    matched = maps.pixels if maps.measured is None else np.where(maps.measured, maps.pixels, np.nan)
    points, mask = pointcloud.pixel_points(matched, maps.rig)
    colours = None
    if maps.texture is not None:  # the texture's own pixel, gamma-encoded as texture.png
        colours = texture_rgba(maps.texture, maps.white)[..., :3][mask]
    pointcloud.write_ply(folder / "points_px.ply", points, colours,
                         comments=(f"tpnet-gpu {scene}, {what}: one point per matched pixel with a disparity",
                                   "metres; rig axes: x right, y up, z toward the viewer (points in front: z < 0)"))
    return written + ["depth_px.tif", "points_px.ply"]


def _figures(folder, maps: FrameMaps, *, scene: str, what: str) -> list[str]:
    from tpnet_gpu.outputs import figures  # noqa: PLC0415 - matplotlib on use

    written = []
    panels = map_panels(maps, what)
    for name, panel in panels.items():
        figures.save(folder / f"{name}.png", panel, title=f"scene {scene}", size=maps.size)
        written.append(f"{name}.png")
    if maps.pixels is not None:  # beside the tile map, on its colour scale
        low, high = figures.scale(panels["disparity"])
        panel = figures.Panel(maps.pixels, f"disparity per pixel: {what}", "disparity", "px", "turbo", low, high,
                              step=1)
        figures.save(folder / "disparity_px.png", panel, title=f"scene {scene}", size=maps.size)
        written.append("disparity_px.png")
    if maps.texture is not None:
        panel = figures.Panel(texture_rgba(maps.texture, maps.white), f"texture at the final disparity: {what}")
        figures.save(folder / "texture_figure.png", panel, title=f"scene {scene}")
        written.append("texture_figure.png")
    return written


SURFACES = ("foreground", "background", "w_foreground")  # FrameResult.surfaces' tile maps


def write_surfaces(folder, surfaces, frames=None) -> list[str]:
    """The two-surface maps of ``surfaces`` (``FrameResult.surfaces``, tensors ``(tiles_y, tiles_x)``) as float32
    TIFFs, cut by ``frames`` (``stereo_io.Frames``; None: uncut); returns their names."""
    import tifffile  # noqa: PLC0415

    for name in SURFACES:
        values = getattr(surfaces, name).detach().cpu().numpy().astype(np.float32)
        tifffile.imwrite(folder / f"{name}.tif", values if frames is None else frames.crop_tiles(values))
    return [f"{name}.tif" for name in SURFACES]
