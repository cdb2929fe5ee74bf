"""Tests of eval/render.py: the video's camera frames each arm, and a frame shows the arm and the
tip paths. Both committed arms (the solid-disc arm, tip moves ~1.6 cm; the I-Support arm, ~14 cm)
render a 3 s program at the main job's panel size (ten frames a panel; MuJoCo C, EGL, CPU)."""

import numpy as np
import pytest

import mjx_arm  # (before jax)
from eval import pipeline, render
from mjx_arm import constants
from tracking.config import ConfigError
from tracking.held import stretch

MODELS = {"solid": constants.SOLID_MODEL_PATH, "isupport": constants.ROOT / "models/softarm.xml"}
#: A pixel is background when no channel exceeds this (the scene is cleared to black).
BACKGROUND_MAX = 12


def _traj() -> dict:
    """Chamber 0 at 3.5 bar for 3 s: the arm bends as far as it goes in that time (the
    I-Support arm's tip 14 cm, the solid arm's 1.6 cm)."""
    p = np.full((30, 3), 0.2)
    p[:, 0] = 3.5
    return {
        "pressures_s": p,
        "commands": {"stretch": stretch(p, 2), "none": p},
        "k": {"stretch": 2, "none": 1},
    }


@pytest.fixture(scope="module", params=sorted(MODELS))
def rendered(request):
    """(arm name, D_s arm, the video's frames [F, H, 3 W, 3], its cameras, its last frame
    rendered without the markers at the current target and tip) for one arm."""
    path = MODELS[request.param]
    arm_s = mjx_arm.load(path, domain="source")
    arm_c = mjx_arm.load(path, domain="constrained")
    cfg = pipeline.EvalConfig()
    frames = render.video_frames(arm_s, arm_c, _traj(), cfg)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(render, "MARKER_FRACTION", 0.0)
        unmarked = render.video_frames(arm_s, arm_c, _traj(), cfg)[-1]
    qpos, poses = render.replay(arm_s, _traj()["pressures_s"])
    views = render.video_views(arm_s, [qpos], poses[:, :3], poses[:, :3], cfg.video_panel_hw)
    return request.param, arm_s, np.asarray(frames), views, unmarked


def _panels(frame: np.ndarray) -> list[np.ndarray]:
    h, w3 = frame.shape[:2]
    return [frame[:, i * w3 // 3 : (i + 1) * w3 // 3] for i in range(3)]


def test_frame_size_and_count(rendered):
    _, _, frames, _, _ = rendered
    h, w = pipeline.EvalConfig().video_panel_hw
    # 30 source steps, one frame every round(10 Hz * 6 / 12 fps) = 5 steps: steps 4, 9, ..., 29.
    assert frames.shape == (6, h, 3 * w, 3) and frames.dtype == np.uint8
    assert min(h, w) >= 480


def test_arm_fills_the_panel_and_is_not_cut_off(rendered):
    name, _, frames, views, _ = rendered
    for panel in _panels(frames[-1]):
        h, w = panel.shape[:2]
        scene = panel[int(h * render.TITLE_FRACTION) : h - int(h * render.LEGEND_FRACTION)]
        if views.closeup is not None:  # the main view only, left of the close-up
            scene = scene[:, : w - int(h * render.CLOSEUP_FRACTION) - h // 40]
        shown = scene.max(axis=2) > BACKGROUND_MAX
        # A 480 px panel: the translucent arm, its mount and the paths fill 12-24% of the main
        # view; an empty view far less, a view from inside the arm nearly all of it.
        assert 0.05 < shown.mean() < 0.6, (name, shown.mean())
        # Framed: what is shown spans most of the view's height or width (1 / FRAME_MARGIN of
        # it in the direction that sets the camera's distance; ~0.83 here).
        rows, cols = np.nonzero(shown)
        span = max(np.ptp(rows) / shown.shape[0], np.ptp(cols) / shown.shape[1])
        assert span > 0.65, (name, span)
        # Nothing of the scene (arm, mount, paths, labels) touches the panel's edges.
        ring = np.concatenate([panel[:2].reshape(-1, 3), panel[-2:].reshape(-1, 3)])
        ring = np.concatenate([ring, panel[:, :2].reshape(-1, 3), panel[:, -2:].reshape(-1, 3)])
        assert (ring.max(axis=1) <= BACKGROUND_MAX).all(), name


def test_every_arm_pose_projects_inside_the_scene_window(rendered):
    """The camera's framing, checked geometrically: every arm geom (with its bounding radius)
    and every tip point lands between the title and legend bands, and left of the close-up."""
    name, arm, _, views, _ = rendered
    h, w = pipeline.EvalConfig().video_panel_hw
    qpos, poses = render.replay(arm, _traj()["pressures_s"])
    centres, pads = render._arm_points(arm, [qpos])
    fovy = arm.mj_model.vis.global_.fovy
    px = render.project(views.main, centres, fovy, (h, w))
    pad_px = pads / (2 * views.main.distance * np.tan(np.radians(fovy) / 2)) * h
    right = w * (1 - render.CLOSEUP_FRACTION * h / w) if views.closeup is not None else w
    assert (px[:, 0] - pad_px > 0).all() and (px[:, 0] + pad_px < right).all(), name
    assert (px[:, 1] - pad_px > h * render.TITLE_FRACTION).all(), name
    assert (px[:, 1] + pad_px < h * (1 - render.LEGEND_FRACTION)).all(), name
    tips = render.project(views.main, poses[:, :3], fovy, (h, w))
    assert ((tips > 0) & (tips < [right, h])).all(), name


def test_close_up_only_where_the_tip_moves_little(rendered):
    name, _, _, views, _ = rendered
    # 3.5 bar on one chamber moves the solid arm's tip 1.6 cm, the I-Support arm's 14 cm in 3 s.
    assert (views.closeup is not None) == (name == "solid")


def _count(image: np.ndarray, rgba: np.ndarray) -> int:
    """Pixels of image of rgba's hue: its strongest channel (red or green here) above 100 and
    over twice each other channel. The lit, blended lines are darker than rgba; the arm (tan),
    its mount (grey) and the text (white) are not counted."""
    main = int(np.argmax(rgba[:3]))
    img = image.astype(int)
    others = [c for c in range(3) if c != main]
    strong = (img[..., main] > 100) & (img[..., main] > 2 * img[..., others].max(axis=-1))
    return int(strong.sum())


def test_paths_drawn_in_their_colours(rendered):
    """Without the markers, green pixels can only be the target path and red ones the arm's."""
    name, _, _, _, unmarked = rendered
    for i, panel in enumerate(_panels(unmarked)):
        h = panel.shape[0]
        scene = panel[: h - int(h * render.LEGEND_FRACTION)]  # the legend repeats the colours
        # The target path is ~200 px long and 4 px wide; most of it is out of the arm.
        assert _count(scene, render.GREEN) > 150, (name, i, _count(scene, render.GREEN))
        if i == 0:  # the D_s panel's own path is the target
            assert _count(scene, render.RED) == 0, name
        elif name == "solid":  # D_c's slower tip: only its close-up shows its path clearly
            assert _count(scene, render.RED) > 20, (name, i, _count(scene, render.RED))


def test_markers_at_the_current_target_and_tip(rendered):
    name, _, frames, _, unmarked = rendered
    for i, (marked, bare) in enumerate(zip(_panels(frames[-1]), _panels(unmarked), strict=True)):
        scene = slice(0, marked.shape[0] - int(marked.shape[0] * render.LEGEND_FRACTION))
        # A marker of radius 480 * 0.0125 = 6 px adds up to pi 6^2 = 113 px of its colour.
        assert _count(marked[scene], render.GREEN) - _count(bare[scene], render.GREEN) > 40
        if i > 0:
            assert _count(marked[scene], render.RED) - _count(bare[scene], render.RED) > 30


def test_frame_camera_centres_and_fits_a_sphere():
    """A sphere of radius r = 0.1 m at (1, 2, 3), seen head-on (azimuth 90, elevation 0: screen
    right +x, up +z, the camera on the -y side) with a 45 deg field of view.

    A point at angle a on the sphere's great circle through screen-right and the camera sits
    r cos a across and r sin a nearer, so it needs D >= r cos a * m / tan(22.5 deg) + r sin a
    (m = FRAME_MARGIN = 1.12); the largest need, over a, is D = r sqrt((m / tan 22.5)^2 + 1)
    = 0.1 * sqrt(2.70392^2 + 1) = 0.28829 m. That is the exact silhouette fit: sin of the
    sphere's half-angle r / D equals sin(atan(tan(22.5 deg) / m)).
    """
    a = np.linspace(0, 2 * np.pi, 3601)
    c, s = 0.1 * np.cos(a), 0.1 * np.sin(a)
    zero = np.zeros_like(a)
    points = np.array([1.0, 2.0, 3.0]) + np.concatenate(
        [np.stack([c, s, zero], 1), np.stack([zero, s, c], 1), np.stack([c, zero, s], 1)]
    )
    cam = render.frame_camera(points, np.zeros(len(points)), 90.0, 0.0, 45.0, 1.0)
    np.testing.assert_allclose(cam.lookat, [1, 2, 3], atol=1e-9)
    expected = 0.1 * np.hypot(render.FRAME_MARGIN / np.tan(np.radians(22.5)), 1.0)
    assert expected == pytest.approx(0.28829, abs=1e-5)
    assert cam.distance == pytest.approx(expected, rel=1e-6)
    px = render.project(cam, points, 45.0, (100, 100))
    assert px.min() > 0 and px.max() < 100
    # A window: the lower-left quarter of the image holds the points instead.
    quarter = (0.0, 0.5, 0.0, 0.5)
    cam = render.frame_camera(points, np.zeros(len(points)), 90.0, 0.0, 45.0, 1.0, quarter)
    px = render.project(cam, points, 45.0, (100, 100))
    assert px[:, 0].min() > 0 and px[:, 0].max() < 50
    assert px[:, 1].min() > 50 and px[:, 1].max() < 100


def test_view_azimuth_puts_the_long_axis_across_the_screen():
    t = np.linspace(0, 2 * np.pi, 100)
    for angle in (0.0, 60.0, 90.0, 150.0):
        a = np.radians(angle)
        ellipse = np.stack([np.cos(t), 0.3 * np.sin(t)], axis=1)
        xy = ellipse @ np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]])
        az = render.view_azimuth(xy)
        assert 0 <= az <= 180  # from the -y side, where the light is
        screen_right = np.array([np.sin(np.radians(az)), -np.cos(np.radians(az))])
        long_axis = np.array([np.cos(a), np.sin(a)])
        turn = np.degrees(np.arccos(abs(screen_right @ long_axis)))
        assert turn == pytest.approx(render.THREE_QUARTER_DEG, abs=1.0)


def test_panel_size_may_be_square_but_not_empty():
    assert pipeline.EvalConfig(video_panel_hw=(480, 480)).video_panel_hw == (480, 480)
    for bad in ((0, 480), (480,), (480.0, 480)):
        with pytest.raises(ConfigError, match="video_panel_hw"):
            pipeline.EvalConfig(video_panel_hw=bad)


def test_video_plan_puts_the_best_translator_first():
    """The main job's videos: the distilled translator, CCGAN-GP and stretch only beside D_s; a
    run without the distilled translator shows CCGAN-GP first; room left goes to untranslated."""
    cfg = pipeline.EvalConfig()
    p = np.zeros((30, 3))
    every = ("none", "stretch", "ccgan", "ccgan_sim", "wcgan", "oracle")

    def plan(methods):
        return render.video_plan({"pressures_s": p, "commands": dict.fromkeys(methods)}, cfg)[1]

    assert plan(every) == ["ccgan_sim", "ccgan", "stretch"]
    assert plan(("none", "stretch", "ccgan", "wcgan")) == ["ccgan", "stretch", "none"]
    assert plan(("none", "stretch", "wcgan")) == ["wcgan", "stretch", "none"]
    assert plan(("none", "stretch")) == ["stretch", "none"]
