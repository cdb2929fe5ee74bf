"""Off-screen videos: the D_s arm, the D_c arm under translation, the D_c arm untranslated.

Frames come from a MuJoCo C replay of each program (same valve law and per-substep pressures as
`mjx_arm.Arm.rollout`), rendered with `mujoco.Renderer`; tip paths are line geoms added to the
scene with `mujoco.mjv_connector`; panels are labelled with Pillow and written with mediapy.

Every panel of a video shares one camera (`video_views`): a three-quarter view from slightly
below, turned so the target path's long axis runs across the screen, and framed
(`frame_camera`) on every arm pose and tip point the video shows, so the solid-disc arm (tip
moves ~1-2 cm) and the I-Support arm (~25 cm) both fill the panel. Where the tip paths are small
beside the arm (the solid-disc arm), a close-up of them with a scale bar is inset. The arm is
drawn translucent: its tip sits inside the end cap, and the paths must show through; the
current target and tip are marked over the image (`project`).

MUJOCO_GL is chosen in one place, `mjx_arm` at import (EGL without a display where libEGL exists;
`eval` imports `mjx_arm` first); `_ensure_offscreen_gl` moves to EGL at render time where mujoco
was imported without it and there is no display.
"""

from __future__ import annotations

import contextlib
import functools
import os
from pathlib import Path
from typing import NamedTuple

import mediapy
import mujoco
import numpy as np
from PIL import Image, ImageDraw, ImageFont

from eval.plots import LABELS

#: The D_s target tip path (drawn up to the current frame) and the target's current point.
GREEN = np.array([0.1, 0.85, 0.2, 1.0], dtype=np.float32)
#: The panel's own tip path and its current tip.
RED = np.array([1.0, 0.15, 0.15, 1.0], dtype=np.float32)
#: The whole target path, faint, so the path ahead is visible.
GREEN_FAINT = np.array([0.1, 0.85, 0.2, 0.3], dtype=np.float32)
MAX_TRAIL_SEGMENTS = 150
#: Camera elevation (deg): positive looks up from below the hanging arm, so the tip path (a
#: near-horizontal curve) shows as an ellipse and nothing sits between the camera and the tip.
ELEVATION_DEG = 25.0
#: Azimuth turned (deg) from the side view square to the target path's long axis.
THREE_QUARTER_DEG = 35.0
#: Frame margin: the framed points fill 1 / FRAME_MARGIN of the panel's half-width and height.
FRAME_MARGIN = 1.12
#: Opacity of the arm's geoms, low enough for the tip paths inside the end cap to show.
ARM_ALPHA = 0.4
#: Bands kept clear of the scene, as fractions of the panel height: the title at the top, the
#: legend at the bottom.
TITLE_FRACTION = 0.08
LEGEND_FRACTION = 0.12
#: A tip close-up is inset when every tip point fits in this fraction of the main view's height
#: (the solid-disc arm's ~2 cm paths under its 0.23 m arm, not the I-Support arm's), unless
#: they span less than CLOSEUP_MIN_M (an arm at rest: nothing to enlarge).
CLOSEUP_BELOW = 0.25
CLOSEUP_MIN_M = 1e-3
#: The close-up's side, as a fraction of the panel height, and its elevation (deg, from below:
#: nearer the tip path's plane than the main view, so the path keeps its shape).
CLOSEUP_FRACTION = 0.42
CLOSEUP_ELEVATION_DEG = 60.0
#: The close-up's top and bottom bands, kept for its name and scale bar (fractions of its side).
CLOSEUP_LABEL_FRACTION = 0.15
#: Radius of the markers at the current target and tip, as a fraction of the panel height.
MARKER_FRACTION = 0.0125
#: Opacity of the arm in the close-up, where it only locates the end cap.
CLOSEUP_ARM_ALPHA = 0.15


def replay(arm, commands_bar: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """MuJoCo C replay from rest of commands [T, 3] (bar, one per 0.1 s period).

    Returns:
      (qpos [T, nq], poses [T, 6] tip position (m) + d3), at the instants `arm.rollout` reads.
    """
    return arm.rollout_with_qpos(commands_bar)


def _add_trail(scene, points: np.ndarray, rgba: np.ndarray, width: float = 3.0) -> None:
    """Appends points [N, 3] (m) as a polyline of at most MAX_TRAIL_SEGMENTS line geoms."""
    if len(points) < 2:
        return
    idx = np.unique(np.linspace(0, len(points) - 1, MAX_TRAIL_SEGMENTS + 1).astype(int))
    for a, b in zip(idx[:-1], idx[1:], strict=True):
        if scene.ngeom >= scene.maxgeom:
            return
        g = scene.geoms[scene.ngeom]
        mujoco.mjv_initGeom(
            g, mujoco.mjtGeom.mjGEOM_LINE, np.zeros(3), np.zeros(3), np.eye(3).ravel(), rgba
        )
        mujoco.mjv_connector(g, mujoco.mjtGeom.mjGEOM_LINE, width, points[a], points[b])
        scene.ngeom += 1


def _arm_points(arm, qpos_sets) -> tuple[np.ndarray, np.ndarray]:
    """(centres [N, 3] m, bounding radii [N] m) of the arm's geoms (all but the world body's)
    over every joint state [T, nq] of every set: what the camera must keep in the frame."""
    m = arm.mj_model
    d = mujoco.MjData(m)
    ids = np.flatnonzero(m.geom_bodyid > 0)
    centres = []
    for qpos in qpos_sets:
        for q in qpos:
            d.qpos[:] = q
            mujoco.mj_kinematics(m, d)
            centres.append(d.geom_xpos[ids].copy())
    centres = np.concatenate(centres)
    return centres, np.resize(m.geom_rbound[ids], len(centres))


def view_azimuth(target_xy: np.ndarray) -> float:
    """Camera azimuth (deg) for a target path [N, 2] (m): the path's principal axis across the
    screen, turned THREE_QUARTER_DEG towards a three-quarter view, from the -y side (where the
    models' light comes from)."""
    xy = target_xy - target_xy.mean(axis=0)
    _, _, vt = np.linalg.svd(xy, full_matrices=False)
    axis_deg = np.degrees(np.arctan2(vt[0, 1], vt[0, 0]))
    # Screen-right of a free camera at azimuth a is (sin a, -cos a): a = axis + 90 puts the axis
    # across the screen.
    azimuth = (axis_deg + 90.0 + THREE_QUARTER_DEG) % 360.0
    return azimuth if azimuth <= 180.0 else azimuth - 180.0


def _camera_basis(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """[3, 3] rows: a free camera's screen right, screen up and backward (towards the camera)
    unit vectors in world coordinates (MuJoCo's mjv_updateCamera convention)."""
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    forward = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    up = np.array([-np.sin(el) * np.cos(az), -np.sin(el) * np.sin(az), np.cos(el)])
    return np.stack([np.cross(forward, up), up, -forward])


def project(camera: mujoco.MjvCamera, points_m: np.ndarray, fovy_deg: float, hw) -> np.ndarray:
    """Pixel coordinates [N, 2] (x right, y down) of points [N, 3] (m) in an image of hw
    (height, width) pixels rendered from a free camera with vertical field of view fovy_deg."""
    basis = _camera_basis(camera.azimuth, camera.elevation)
    local = (points_m - np.asarray(camera.lookat)) @ basis.T
    depth = camera.distance - local[:, 2]
    tan_y = np.tan(np.radians(fovy_deg) / 2)
    tan_x = tan_y * hw[1] / hw[0]
    x = (local[:, 0] / (depth * tan_x) + 1) / 2 * hw[1]
    y = (1 - local[:, 1] / (depth * tan_y)) / 2 * hw[0]
    return np.stack([x, y], axis=1)


def frame_camera(
    points_m: np.ndarray,
    pad_m: np.ndarray,
    azimuth_deg: float,
    elevation_deg: float,
    fovy_deg: float,
    aspect: float,
    window: tuple[float, float, float, float] = (0.0, 1.0, 0.0, 1.0),
) -> mujoco.MjvCamera:
    """A free camera at the given angles whose view holds every point with its pad.

    Args:
      points_m: [N, 3] points (m) to keep in view.
      pad_m: [N] radius (m) around each point that must be in view too.
      fovy_deg: the model's vertical field of view (deg); aspect: width / height.
      window: (left, right, bottom, top), the part of the image (fractions of its width and
        height, from the bottom left) the points must stay in; the rest is left for labels.

    Returns:
      The camera: the centre of the points' extent on the screen at the window's centre, from
      the nearest distance at which no padded point leaves the window (with FRAME_MARGIN),
      perspective included.
    """
    basis = _camera_basis(azimuth_deg, elevation_deg)
    local = points_m @ basis.T
    lo, hi = (local - pad_m[:, None]).min(axis=0), (local + pad_m[:, None]).max(axis=0)
    centre = (lo + hi) / 2
    local = local - centre
    left, right_edge, bottom, top = window
    tan_y = np.tan(np.radians(fovy_deg) / 2)
    tan_x = tan_y * aspect
    # A point at depth D in front of the camera (D = distance - its offset towards the camera)
    # projects at x / (D tan) in [-1, 1] image units: in the window when
    # (|x| + pad) * margin <= tan * window half-width * D.
    half_x, half_y = tan_x * (right_edge - left), tan_y * (top - bottom)
    need_x = (np.abs(local[:, 0]) + pad_m) * FRAME_MARGIN / half_x + local[:, 2] + pad_m
    need_y = (np.abs(local[:, 1]) + pad_m) * FRAME_MARGIN / half_y + local[:, 2] + pad_m
    distance = float(max(need_x.max(), need_y.max()))
    # Look away from the points' centre so that it lands on the window's centre.
    shift = np.array([tan_x * (left + right_edge - 1), tan_y * (bottom + top - 1), 0.0])
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.lookat[:] = (centre - shift * distance) @ basis
    cam.distance = distance
    cam.azimuth = float(azimuth_deg)
    cam.elevation = float(elevation_deg)
    return cam


class Views(NamedTuple):
    """The cameras a video's panels share."""

    main: mujoco.MjvCamera
    """The whole arm and every tip point (`frame_camera`)."""
    closeup: mujoco.MjvCamera | None
    """The tip paths alone, inset where they are small in the main view (CLOSEUP_BELOW)."""


def video_views(arm, qpos_sets, tips_m: np.ndarray, target_m: np.ndarray, hw) -> Views:
    """The cameras for panels of size hw (height, width) pixels showing the arm at every joint
    state [T, nq] of qpos_sets and the tip points tips_m [N, 3] (m; target and achieved), turned
    to the target path target_m [T, 3] (`view_azimuth`)."""
    fovy = arm.mj_model.vis.global_.fovy
    azimuth = view_azimuth(target_m[:, :2])
    centres, pads = _arm_points(arm, qpos_sets)
    points = np.concatenate([centres, tips_m])
    pads = np.concatenate([pads, np.zeros(len(tips_m))])

    def main_view(right_edge: float) -> mujoco.MjvCamera:
        window = (0.0, right_edge, LEGEND_FRACTION, 1.0 - TITLE_FRACTION)
        return frame_camera(points, pads, azimuth, ELEVATION_DEG, fovy, hw[1] / hw[0], window)

    main = main_view(1.0)
    view_height_m = 2 * main.distance * np.tan(np.radians(fovy) / 2)
    span_m = np.ptp(tips_m, axis=0).max()
    if not CLOSEUP_MIN_M <= span_m < CLOSEUP_BELOW * view_height_m:
        return Views(main, None)
    closeup = frame_camera(
        tips_m,
        np.zeros(len(tips_m)),
        azimuth,
        CLOSEUP_ELEVATION_DEG,
        fovy,
        1.0,
        window=(0.0, 1.0, CLOSEUP_LABEL_FRACTION, 1.0 - CLOSEUP_LABEL_FRACTION),
    )
    # The arm moves over to leave the close-up (at the right) its own strip.
    inset_width = CLOSEUP_FRACTION * hw[0] / hw[1]
    return Views(main_view(1.0 - inset_width - 0.02), closeup)


@functools.cache
def _font(size_px: int) -> ImageFont.ImageFont:
    """Pillow's scalable default font at size_px pixels (loaded once per size)."""
    try:
        return ImageFont.load_default(size=size_px)
    except (TypeError, OSError):  # Pillow < 10.1 or without FreeType: the fixed bitmap font
        return ImageFont.load_default()


def _scale_bar(span_m: float) -> tuple[float, str]:
    """(length m, label) of a 1-2-5 scale bar no longer than span_m."""
    exponent = np.floor(np.log10(span_m))
    for mantissa in (5.0, 2.0, 1.0):
        length = mantissa * 10.0**exponent
        if length <= span_m:
            break
    return length, f"{length * 1e3:g} mm" if length < 0.01 else f"{length * 1e2:g} cm"


def _overlay(
    frame: np.ndarray,
    title: str,
    time_s: float,
    own_path: bool,
    closeup: np.ndarray | None = None,
    closeup_m_per_px: float = 0.0,
) -> np.ndarray:
    """The panel's title and time at the top, the colour legend in the bottom band, and the
    tip close-up (with a scale bar) inset at the right."""
    h, w = frame.shape[:2]
    img = Image.fromarray(frame)
    draw = ImageDraw.Draw(img)
    big, small = _font(max(10, h // 20)), _font(max(9, h // 28))
    pad = max(3, h // 80)
    draw.text((pad, pad), title, fill=(255, 255, 255), font=big)
    draw.text((w - pad, pad), f"t = {time_s:.1f} s", fill=(220, 220, 220), font=small, anchor="ra")
    entries = [(GREEN, "target tip path (D_s)")]
    if own_path:
        entries.append((RED, "this arm's tip path"))
    band = int(h * LEGEND_FRACTION)
    row = band // 2
    swatch = max(12, w // 16)
    for i, (rgba, text) in enumerate(entries):
        y = h - band + row * i + row // 2
        colour = tuple(int(255 * c) for c in rgba[:3])
        draw.line((pad, y, pad + swatch, y), fill=colour, width=max(2, h // 120))
        draw.text((2 * pad + swatch, y), text, fill=colour, font=small, anchor="lm")
    if closeup is not None:
        side = closeup.shape[0]
        x0, y0 = w - side - pad, int(h * TITLE_FRACTION)
        img.paste(Image.fromarray(closeup), (x0, y0))
        draw.rectangle((x0, y0, x0 + side, y0 + side), outline=(150, 150, 150))
        band = int(side * CLOSEUP_LABEL_FRACTION / 2)
        draw.text(
            (x0 + pad, y0 + band), "tip close-up", fill=(220, 220, 220), font=small, anchor="lm"
        )
        y = y0 + side - band
        length_m, text = _scale_bar(0.3 * side * closeup_m_per_px)
        bar_px = length_m / closeup_m_per_px
        draw.line((x0 + pad, y, x0 + pad + bar_px, y), fill=(255, 255, 255), width=2)
        draw.text((x0 + 2 * pad + bar_px, y), text, fill=(255, 255, 255), font=small, anchor="lm")
    return np.asarray(img)


def _ensure_offscreen_gl() -> None:
    """Uses EGL when mujoco was imported before MUJOCO_GL was set and there is no display.

    mujoco picks its GL backend at import; a process that imported it first (e.g. through
    mjx_arm) without MUJOCO_GL would try GLFW, which needs an X display.
    """
    from mujoco.rendering.classic import gl_context

    if os.environ.get("DISPLAY") or os.environ.get("MUJOCO_GL", "egl") != "egl":
        return
    if gl_context.GLContext is None or gl_context.GLContext.__module__ != "mujoco.egl":
        os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
        from mujoco.egl import GLContext

        gl_context.GLContext = GLContext


def _draw_scene(renderer, data, camera, option, arm_alpha, paths) -> np.ndarray:
    """Renders data from camera with the arm at arm_alpha, paths drawn in the scene, and a
    marker at the last point of each path that has one.

    paths: (points [n, 3] m, rgba, line width px, marker radius px or 0) per polyline. Markers
    are drawn over the image (`project`): in the scene they would sit inside the end cap.
    """
    renderer.update_scene(data, camera=camera, scene_option=option)
    for g in range(renderer.scene.ngeom):
        renderer.scene.geoms[g].rgba[3] = arm_alpha
    for points, rgba, width, _ in paths:
        _add_trail(renderer.scene, points, rgba, width)
    image = renderer.render()
    marked = [(p[-1], rgba, r) for p, rgba, _, r in paths if r > 0 and len(p)]
    if not marked:
        return image
    img = Image.fromarray(image)
    draw = ImageDraw.Draw(img)
    fovy = renderer.model.vis.global_.fovy
    hw = (renderer.height, renderer.width)
    pixels = project(camera, np.stack([p for p, _, _ in marked]), fovy, hw)
    for (x, y), (_, rgba, r) in zip(pixels, marked, strict=True):
        colour = tuple(int(255 * c) for c in rgba[:3])
        draw.ellipse((x - r, y - r, x + r, y + r), fill=colour, outline=(255, 255, 255), width=1)
    return np.asarray(img)


def render_panel(
    arm,
    qpos: np.ndarray,
    own_path: np.ndarray | None,
    target_path: np.ndarray,
    label: str,
    hw,
    views: Views,
    times_s: np.ndarray,
    on_frame=None,
) -> list[np.ndarray]:
    """Frames [N, H, W, 3] uint8 of one arm at the given joint states.

    Args:
      qpos: [N, nq] joint states, one per frame.
      own_path: [N, 3] the tip position (m) at each frame, drawn in red up to the frame; None
        where the target is the arm's own path (the D_s panel).
      target_path: [N, 3] the D_s target tip (m), drawn in green up to the frame (the whole path
        faintly).
      hw: (height, width) pixels.
      views: the cameras (`video_views`), shared by a video's panels.
      times_s: [N] the source time (s) of each frame, shown on it.
      on_frame: called with no arguments after each frame (e.g. a progress bar's update).
    """
    m = arm.mj_model
    d = mujoco.MjData(m)
    option = mujoco.MjvOption()
    option.sitegroup[:] = 0  # the tip site (a red 4 mm sphere) would double the tip marker
    frames = []
    _ensure_offscreen_gl()
    max_geom = m.ngeom + 4 * MAX_TRAIL_SEGMENTS + 8
    side = int(hw[0] * CLOSEUP_FRACTION)
    fovy = np.radians(m.vis.global_.fovy)
    marker_px = MARKER_FRACTION * hw[0]
    with contextlib.ExitStack() as stack:
        main = stack.enter_context(mujoco.Renderer(m, hw[0], hw[1], max_geom))
        near, near_m_per_px = None, 0.0  # the close-up's metres per pixel at its look-at
        if views.closeup is not None:
            near = stack.enter_context(mujoco.Renderer(m, side, side, max_geom))
            near_m_per_px = 2 * views.closeup.distance * np.tan(fovy / 2) / side
        for r in (main, near):
            if r is not None:
                # No floor to cast shadows on; the 4096^2 shadow map took 85% of a frame's time.
                r.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
                r.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
        for i, q in enumerate(qpos):
            d.qpos[:] = q
            mujoco.mj_forward(m, d)
            paths = [
                (target_path, GREEN_FAINT, 2.0, 0.0),
                (target_path[: i + 1], GREEN, 4.0, marker_px),
            ]
            if own_path is not None:
                paths.append((own_path[: i + 1], RED, 3.0, 0.8 * marker_px))
            frame = _draw_scene(main, d, views.main, option, ARM_ALPHA, paths)
            closeup = None
            if near is not None:
                closeup = _draw_scene(near, d, views.closeup, option, CLOSEUP_ARM_ALPHA, paths)
            frames.append(
                _overlay(
                    frame,
                    label,
                    times_s[i],
                    own_path is not None,
                    closeup,
                    near_m_per_px,
                )
            )
            if on_frame is not None:
                on_frame()
    return frames


def _ensure_ffmpeg() -> None:
    """Points mediapy at the ffmpeg binary shipped by imageio-ffmpeg when none is on PATH."""
    import shutil

    if shutil.which("ffmpeg") is None:
        import imageio_ffmpeg

        mediapy.set_ffmpeg(imageio_ffmpeg.get_ffmpeg_exe())


#: The translated panel's method: the first of these a run has (the best translator first).
VIDEO_BEST = ("ccgan_sim", "ccgan_range", "ccgan", "wcgan", "oracle", "stretch")
#: D_c panels of a video at most (each costs as much rendering as the D_s panel).
VIDEO_DC_PANELS = 3


def video_plan(traj: dict, cfg) -> tuple[np.ndarray, list[str]]:
    """(source steps [F] shown as frames, D_c panels' methods) of one shape's video.

    The D_c panels, left to right: the best translator the run has (`VIDEO_BEST`), then
    CCGAN-GP and stretch only where the run has them and they are not that one, then the
    untranslated program while there is room (`VIDEO_DC_PANELS`). The main job's videos show
    the distilled translator, CCGAN-GP and stretch only beside the D_s arm.
    """
    n_steps = traj["pressures_s"].shape[0]
    frame_every = max(1, int(round(10.0 * cfg.video_speedup / cfg.video_fps)))
    frames_at = np.arange(frame_every - 1, n_steps, frame_every)
    have = traj["commands"]
    best = next((m for m in VIDEO_BEST if m in have), None)
    methods = []
    for m in (best, "ccgan", "stretch", "none"):
        if m is not None and m in have and m not in methods and len(methods) < VIDEO_DC_PANELS:
            methods.append(m)
    return frames_at, methods


def video_frames(arm_s, arm_c, traj: dict, cfg, mark: str | None = None, on_frame=None):
    """Frames [F, H, P W, 3] uint8 of one shape's video (`write_video`): P = 1 + the D_c
    panels of `video_plan`."""
    from mjx_arm import programs

    frames_at, methods = video_plan(traj, cfg)
    tag = " [quick run]" if mark else ""
    qpos_s, poses_s = replay(arm_s, traj["pressures_s"])
    target = poses_s[frames_at, :3]
    times_s = (frames_at + 1) / programs.CONTROL_HZ
    # (arm, label, qpos [n, nq], own tip path [n, 3] or None) per panel.
    panels = [(arm_s, "D_s", qpos_s[frames_at], None)]
    for method in methods:
        k = traj["k"][method]
        qpos_c, poses_c = replay(arm_c, traj["commands"][method])
        n = min(len(frames_at), poses_c.shape[0] // k)
        at = (frames_at[:n] + 1) * k - 1
        label = f"D_c {LABELS.get(method, method)}"
        panels.append((arm_c, label, qpos_c[at], poses_c[at, :3]))
    hw = cfg.video_panel_hw
    tips = np.concatenate([target] + [p for _, _, _, p in panels if p is not None])
    views = video_views(arm_s, [q for _, _, q, _ in panels], tips, target, hw)
    rendered = []
    for arm, label, qpos, own in panels:
        n = len(qpos)
        panel = render_panel(
            arm, qpos, own, target[:n], label + tag, hw, views, times_s[:n], on_frame
        )
        # A D_c program that ends early holds its last frame.
        panel += [panel[-1]] * (len(frames_at) - n)
        if on_frame is not None:
            for _ in range(len(frames_at) - n):
                on_frame()
        rendered.append(panel)
    return [np.concatenate(row, axis=1) for row in zip(*rendered, strict=True)]


def write_video(
    arm_s, arm_c, traj: dict, cfg, path: Path, mark: str | None = None, on_frame=None
) -> Path:
    """MP4 for one shape: D_s | the D_c panels of `video_plan` (the best translator first).

    D_c panels are sampled at the end of each source step's k periods, so all panels share the
    source time axis, and one camera (`frame_camera`). `mark` (a quick run's,
    `eval.report.run_mark`) is added to every panel's label; `on_frame` is called after each
    rendered panel frame. Returns the path.
    """
    frames = video_frames(arm_s, arm_c, traj, cfg, mark, on_frame)
    _ensure_ffmpeg()
    mediapy.write_video(str(path), frames, fps=cfg.video_fps)
    return path


def write_all(
    arm_s, arm_c, trajectories: dict, cfg, out_dir: Path, mark: str | None = None
) -> list[str]:
    """One video per shape under out_dir, with a progress bar over rendered panel frames (the
    main job's five 60 s videos take minutes); returns the file names."""
    from tqdm import tqdm

    plans = {shape: video_plan(traj, cfg) for shape, traj in trajectories.items()}
    total = sum(len(at) * (1 + len(methods)) for at, methods in plans.values())
    names = []
    with tqdm(total=total, desc="rendering videos", unit="frame") as bar:
        for shape, traj in trajectories.items():
            name = f"video_{shape}.mp4"
            write_video(arm_s, arm_c, traj, cfg, Path(out_dir) / name, mark, bar.update)
            names.append(name)
    return names
