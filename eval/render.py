"""Off-screen videos: the D_s arm, the D_c arm under translation, the D_c arm untranslated.

Frames come from a MuJoCo C replay of each program (same valve law and per-substep pressures as
`mjx_arm.Arm.rollout`), rendered with `mujoco.Renderer`; tip paths are line geoms added to the
scene with `mujoco.mjv_connector`; panels are labelled with Pillow and written with mediapy.

MUJOCO_GL is chosen in one place, `mjx_arm` at import (EGL without a display where libEGL exists;
`eval` imports `mjx_arm` first); `_ensure_offscreen_gl` moves to EGL at render time where mujoco
was imported without it and there is no display.
"""

from __future__ import annotations

import os
from pathlib import Path

import mediapy
import mujoco
import numpy as np
from PIL import Image, ImageDraw

GREEN = np.array([0.1, 0.8, 0.2, 1.0], dtype=np.float32)
RED = np.array([0.9, 0.1, 0.1, 1.0], dtype=np.float32)
MAX_TRAIL_SEGMENTS = 150
#: Tip paths are drawn this far (m) below the arm's lowest tip position.
TRAIL_DROP_M = 0.04


def replay(arm, commands_bar: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """MuJoCo C replay from rest of commands [T, 3] (bar, one per 0.1 s period).

    Returns:
      (qpos [T, nq], poses [T, 6] tip position (m) + d3), at the instants `arm.rollout` reads.
    """
    return arm.rollout_with_qpos(commands_bar)


def _add_trail(scene, points: np.ndarray, rgba: np.ndarray, width: float = 3.0) -> None:
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


def _camera() -> mujoco.MjvCamera:
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.lookat[:] = (0.0, 0.0, -0.2)
    cam.distance = 0.3
    cam.azimuth = 90.0
    cam.elevation = 60.0  # from below, so the XY path is visible under the hanging arm
    return cam


def _label(frame: np.ndarray, text: str) -> np.ndarray:
    img = Image.fromarray(frame)
    ImageDraw.Draw(img).text((6, 4), text, fill=(255, 255, 255))
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


def render_panel(
    arm,
    qpos: np.ndarray,
    own_path: np.ndarray,
    target_path: np.ndarray,
    label: str,
    hw,
    on_frame=None,
) -> list[np.ndarray]:
    """Frames [N, H, W, 3] uint8 of one arm at the given joint states.

    Args:
      qpos: [N, nq] joint states, one per frame.
      own_path: [N, 3] the tip position (m) at each frame; its XY drawn in red up to the frame.
      target_path: [N, 3] the D_s target tip (m); its XY drawn in green up to the frame.
      hw: (height, width) pixels.
      on_frame: called with no arguments after each frame (e.g. a progress bar's update).
    """
    m = arm.mj_model
    d = mujoco.MjData(m)
    cam = _camera()
    frames = []
    # The tip sits inside the arm's end cap (radius 3 cm > the ~2 cm deflections), so the paths
    # are drawn on a plane TRAIL_DROP_M below the lowest target point, where the camera sees them.
    plane_z = target_path[:, 2].min() - TRAIL_DROP_M
    own_path = np.concatenate([own_path[:, :2], np.full((len(own_path), 1), plane_z)], axis=1)
    target_path = np.concatenate(
        [target_path[:, :2], np.full((len(target_path), 1), plane_z)], axis=1
    )
    _ensure_offscreen_gl()
    max_geom = m.ngeom + 4 * MAX_TRAIL_SEGMENTS
    with mujoco.Renderer(m, height=hw[0], width=hw[1], max_geom=max_geom) as r:
        for i, q in enumerate(qpos):
            d.qpos[:] = q
            mujoco.mj_forward(m, d)
            r.update_scene(d, camera=cam)
            _add_trail(r.scene, target_path[: i + 1], GREEN)
            _add_trail(r.scene, own_path[: i + 1], RED)
            frames.append(_label(r.render(), label))
            if on_frame is not None:
                on_frame()
    return frames


def _ensure_ffmpeg() -> None:
    """Points mediapy at the ffmpeg binary shipped by imageio-ffmpeg when none is on PATH."""
    import shutil

    if shutil.which("ffmpeg") is None:
        import imageio_ffmpeg

        mediapy.set_ffmpeg(imageio_ffmpeg.get_ffmpeg_exe())


def video_plan(traj: dict, cfg) -> tuple[np.ndarray, list[str]]:
    """(source steps [F] shown as frames, D_c panels' methods) of one shape's video.

    The translated panel uses the first available translator, else the oracle, else stretch;
    the untranslated panel follows it.
    """
    n_steps = traj["pressures_s"].shape[0]
    frame_every = max(1, int(round(10.0 * cfg.video_speedup / cfg.video_fps)))
    frames_at = np.arange(frame_every - 1, n_steps, frame_every)
    translated = next(
        (m for m in ("ccgan", "wcgan", "oracle", "stretch") if m in traj["commands"]), None
    )
    methods = [m for m in (translated, "none") if m is not None and m in traj["commands"]]
    return frames_at, methods


def write_video(
    arm_s, arm_c, traj: dict, cfg, path: Path, mark: str | None = None, on_frame=None
) -> Path:
    """Three-panel MP4 for one shape: D_s | D_c translated | D_c untranslated (`video_plan`).

    D_c panels are sampled at the end of each source step's k periods, so all panels share the
    source time axis. `mark` (a quick run's, `eval.report.run_mark`) is added to every
    panel's label; `on_frame` is called after each rendered panel frame. Returns the path.
    """
    frames_at, methods = video_plan(traj, cfg)
    tag = " [quick run]" if mark else ""
    qpos_s, poses_s = replay(arm_s, traj["pressures_s"])
    target = poses_s[frames_at, :3]
    panels = [
        render_panel(
            arm_s, qpos_s[frames_at], target, target, "D_s" + tag, cfg.video_panel_hw, on_frame
        )
    ]
    for method in methods:
        label = "D_c untranslated" if method == "none" else f"D_c {method}"
        k = traj["k"][method]
        qpos_c, poses_c = replay(arm_c, traj["commands"][method])
        n = min(len(frames_at), poses_c.shape[0] // k)
        at = (frames_at[:n] + 1) * k - 1
        panel = render_panel(
            arm_c,
            qpos_c[at],
            poses_c[at, :3],
            target[:n],
            label + tag,
            cfg.video_panel_hw,
            on_frame,
        )
        panel += [panel[-1]] * (len(frames_at) - n)
        if on_frame is not None:
            for _ in range(len(frames_at) - n):
                on_frame()
        panels.append(panel)
    frames = [np.concatenate(row, axis=1) for row in zip(*panels, strict=True)]
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
