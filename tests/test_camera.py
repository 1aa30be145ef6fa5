"""Tests of repro.sensors.camera: GL matrices vs exact projection, detection, correspondence."""

from __future__ import annotations

import numpy as np
import pybullet as p
import pytest
from scipy.spatial.transform import Rotation

from repro.errors import ConfigError, UnknownChoiceError
from repro.sensors.camera import (
    DEFAULT_DOT_COLORS,
    Camera,
    DotTarget,
    Intrinsics,
    detect_dots,
    disc_image_centroids,
    move_dot_target,
    project_points,
    render_rgb,
    spawn_dot_target,
    view_matrix_gl,
)

MAX_PX_ERROR = 0.5

OFF_CENTRE = Intrinsics(640, 480, fu=600.0, fv=580.0, u0=300.0, v0=260.0)
CENTRED = Intrinsics.centered(640, 480, fu=600.0)

# Five dots; small discs keep the perspective bias of the blob centroid (~f (r/Z)^2) well
# below the pixel tolerance at 0.25 m and 30 deg tilt.
DOTS = np.array([[-0.05, -0.05, 0.0], [0.05, -0.05, 0.0], [0.05, 0.05, 0.0],
                 [-0.05, 0.05, 0.0], [0.0, 0.07, 0.0]])
SMALL_DOTS = DotTarget(DOTS, DEFAULT_DOT_COLORS[:5], dot_radius=0.006)

T_WORLD_TARGET = np.eye(4)
T_WORLD_TARGET[:3, :3] = Rotation.from_euler("xyz", [0.3, -0.2, 0.5]).as_matrix()
T_WORLD_TARGET[:3, 3] = [0.4, 0.1, 0.3]


@pytest.fixture
def client():
    cid = p.connect(p.DIRECT)
    yield cid
    p.disconnect(cid)


def look_at(eye: np.ndarray, centre: np.ndarray, down_hint: np.ndarray) -> np.ndarray:
    """4x4 camera pose (z towards centre, y as close as possible to down_hint)."""
    z = centre - eye
    z /= np.linalg.norm(z)
    x = np.cross(down_hint, z)
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    T[:3, 3] = eye
    return T


def random_view(rng: np.random.Generator, T_world_target: np.ndarray) -> tuple[np.ndarray, float]:
    """Camera 0.25-0.6 m from the target, optical axis within 30 deg of the target normal,
    random roll, aimed within 1 cm of the target origin. Returns (T_world_camera, tilt)."""
    d = rng.uniform(0.25, 0.6)
    tilt = np.deg2rad(rng.uniform(0.0, 30.0))
    phi = rng.uniform(0.0, 2.0 * np.pi)
    eye = d * np.array([np.sin(tilt) * np.cos(phi), np.sin(tilt) * np.sin(phi), np.cos(tilt)])
    centre = np.array([*rng.uniform(-0.01, 0.01, 2), 0.0])
    hint = rng.normal(size=3)
    return T_world_target @ look_at(eye, centre, hint), float(np.rad2deg(tilt))


# --------------------------------------------------------------------------- intrinsics


def test_intrinsics_round_trip() -> None:
    rng = np.random.default_rng(0)
    uv = rng.uniform([-0.5, -0.5], [639.5, 479.5], (50, 2))
    for intr in (OFF_CENTRE, CENTRED):
        xy = intr.to_normalized(uv)
        np.testing.assert_allclose(intr.to_pixels(xy), uv, atol=1e-12)
        homog = np.column_stack([xy, np.ones(len(xy))]) @ intr.K().T
        np.testing.assert_allclose(homog[:, :2], uv, atol=1e-12)
    np.testing.assert_allclose(OFF_CENTRE.to_normalized(np.array([300.0, 260.0])), [0.0, 0.0])
    np.testing.assert_allclose(OFF_CENTRE.to_pixels(np.array([[0.1, -0.2]])), [[360.0, 144.0]])
    assert CENTRED.u0 == 319.5 and CENTRED.v0 == 239.5


def test_intrinsics_validation() -> None:
    with pytest.raises(ConfigError):
        Intrinsics(640, 480, fu=-1.0, fv=580.0, u0=300.0, v0=260.0)
    with pytest.raises(ConfigError):
        Intrinsics(640, 480, fu=600.0, fv=580.0, u0=300.0, v0=260.0, near=1.0, far=0.5)
    with pytest.raises(UnknownChoiceError):
        CENTRED.projection_matrix_gl("vulkan")


def test_in_image_bounds() -> None:
    uv = np.array([[-0.5, -0.5], [639.5, 479.5], [-0.51, 10.0], [10.0, 479.6], [np.nan, 1.0]])
    np.testing.assert_array_equal(CENTRED.in_image(uv), [True, True, False, False, False])


# --------------------------------------------------------------------------- GL matrices


def test_view_matrix_matches_pybullet_lookat() -> None:
    eye, centre, up = np.array([0.3, -0.2, 0.8]), np.array([0.05, 0.1, 0.0]), np.array([0, 0, 1.0])
    T = look_at(eye, centre, -up)  # image y (down) along -up
    expected = p.computeViewMatrix(eye.tolist(), centre.tolist(), up.tolist())
    np.testing.assert_allclose(view_matrix_gl(T), expected, atol=1e-6)


def test_opengl_projection_matches_pybullet_fov_matrix() -> None:
    """computeProjectionMatrixFOV is the 'opengl' (pixel-centre sampling) matrix of a
    centred camera with fu = fv."""
    W, H, f = CENTRED.width, CENTRED.height, CENTRED.fu
    fov = np.rad2deg(2.0 * np.arctan(H / (2.0 * f)))
    expected = p.computeProjectionMatrixFOV(fov, W / H, CENTRED.near, CENTRED.far)
    np.testing.assert_allclose(CENTRED.projection_matrix_gl("opengl"), expected, atol=1e-6)
    # TinyRenderer samples pixel corners: its matrix differs by half a pixel in u and v.
    assert not np.allclose(CENTRED.projection_matrix_gl("tiny"), expected, atol=1e-6)


def test_project_points_behind_camera_is_nan() -> None:
    T = np.eye(4)
    uv, Z = project_points(CENTRED, T, np.array([[0.0, 0.0, 1.0], [0.1, 0.0, -1.0]]))
    np.testing.assert_allclose(uv[0], [319.5, 239.5])
    assert np.all(np.isnan(uv[1])) and Z[1] == -1.0


def test_disc_image_centroids_limits() -> None:
    """Ellipse centre -> projected centre for a vanishing radius or a fronto-parallel disc."""
    rng = np.random.default_rng(5)
    tiny = DotTarget(DOTS, DEFAULT_DOT_COLORS[:5], dot_radius=1e-7)
    for _ in range(5):
        T_wc, _ = random_view(rng, T_WORLD_TARGET)
        uv, _ = project_points(OFF_CENTRE, T_wc, tiny.points_world(T_WORLD_TARGET))
        np.testing.assert_allclose(disc_image_centroids(OFF_CENTRE, T_wc, tiny, T_WORLD_TARGET),
                                   uv, atol=1e-6)
    T_tc = np.eye(4)
    T_tc[:3, :3] = np.diag([1.0, -1.0, -1.0])
    T_tc[:3, 3] = [0.02, -0.01, 0.3]
    target = DotTarget(DOTS, DEFAULT_DOT_COLORS[:5])
    T_wc = T_WORLD_TARGET @ T_tc
    uv, _ = project_points(OFF_CENTRE, T_wc, target.points_world(T_WORLD_TARGET))
    np.testing.assert_allclose(disc_image_centroids(OFF_CENTRE, T_wc, target, T_WORLD_TARGET),
                               uv, atol=1e-9)


# --------------------------------------------------------------------------- rendering


@pytest.mark.parametrize("intr", [OFF_CENTRE, CENTRED], ids=["off_centre", "centred"])
def test_render_matches_exact_projection(client: int, intr: Intrinsics) -> None:
    spawn_dot_target(client, SMALL_DOTS, T_WORLD_TARGET)
    rng = np.random.default_rng(42)
    errors = []
    for _ in range(6):
        T_wc, tilt = random_view(rng, T_WORLD_TARGET)
        uv, found = detect_dots(render_rgb(client, intr, T_wc), SMALL_DOTS.colors)
        uv_exact, Z = project_points(intr, T_wc, SMALL_DOTS.points_world(T_WORLD_TARGET))
        assert found.all(), f"tilt {tilt:.1f} deg: found {found}"
        assert np.all((Z > 0.2) & (Z < 0.7))
        errors.append(np.linalg.norm(uv - uv_exact, axis=1).max())
    print(f"max render-vs-exact error ({intr}): {max(errors):.3f} px")
    assert max(errors) < MAX_PX_ERROR


def test_render_default_dots_match_disc_image_centroids(client: int) -> None:
    """12 mm dots: the blob centroid is the ellipse centre (not the projected disc centre)."""
    target = DotTarget(DOTS, DEFAULT_DOT_COLORS[:5])
    spawn_dot_target(client, target, T_WORLD_TARGET)
    rng = np.random.default_rng(43)
    for _ in range(5):
        T_wc, _ = random_view(rng, T_WORLD_TARGET)
        uv, found = detect_dots(render_rgb(client, OFF_CENTRE, T_wc), target.colors)
        assert found.all()
        uv_ellipse = disc_image_centroids(OFF_CENTRE, T_wc, target, T_WORLD_TARGET)
        assert np.linalg.norm(uv - uv_ellipse, axis=1).max() < MAX_PX_ERROR


def test_pybullet_fov_matrix_is_half_pixel_off_with_tiny_renderer(client: int) -> None:
    """Pitfall check: PyBullet's own projection matrix + TinyRenderer shifts the image by
    (+1/2, -1/2) px relative to the centred pinhole model; our 'tiny' matrix does not."""
    spawn_dot_target(client, SMALL_DOTS, T_WORLD_TARGET)
    W, H, f = CENTRED.width, CENTRED.height, CENTRED.fu
    proj = p.computeProjectionMatrixFOV(np.rad2deg(2.0 * np.arctan(H / (2.0 * f))), W / H,
                                        CENTRED.near, CENTRED.far)
    rng = np.random.default_rng(44)
    offsets = []
    for _ in range(3):
        T_wc, _ = random_view(rng, T_WORLD_TARGET)
        rgba = p.getCameraImage(W, H, view_matrix_gl(T_wc), proj, renderer=p.ER_TINY_RENDERER,
                                shadow=0, physicsClientId=client)[2]
        rgb = np.asarray(rgba, dtype=np.uint8).reshape(H, W, 4)[:, :, :3].copy()
        uv, found = detect_dots(rgb, SMALL_DOTS.colors)
        assert found.all()
        uv_exact, _ = project_points(CENTRED, T_wc, SMALL_DOTS.points_world(T_WORLD_TARGET))
        offsets.append(uv - uv_exact)
    np.testing.assert_allclose(np.concatenate(offsets).mean(axis=0), [0.5, -0.5], atol=0.1)


def test_correspondence_follows_colours(client: int) -> None:
    perm = np.array([3, 0, 4, 1, 2])
    colors = tuple(DEFAULT_DOT_COLORS[i] for i in perm)
    target = DotTarget(DOTS, colors, dot_radius=0.006)
    spawn_dot_target(client, target, T_WORLD_TARGET)
    rng = np.random.default_rng(45)
    for _ in range(3):
        T_wc, _ = random_view(rng, T_WORLD_TARGET)
        rgb = render_rgb(client, OFF_CENTRE, T_wc)
        uv_exact, _ = project_points(OFF_CENTRE, T_wc, target.points_world(T_WORLD_TARGET))
        uv, found = detect_dots(rgb, target.colors)
        assert found.all()
        assert np.linalg.norm(uv - uv_exact, axis=1).max() < MAX_PX_ERROR
        # Looking the dots up with the unpermuted colour list assigns them wrongly.
        uv_wrong, _ = detect_dots(rgb, DEFAULT_DOT_COLORS[:5])
        assert np.all(np.linalg.norm(uv_wrong - uv_exact, axis=1) > 20.0)


def lost_dot_view() -> np.ndarray:
    """Fronto-parallel view at 0.3 m, rolled 45 deg, aimed so dot 0 is ~40 px left of the
    image while the other dots are well inside."""
    c = 0.0993 * np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
    T_tc = np.eye(4)
    x = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
    z = np.array([0.0, 0.0, -1.0])
    T_tc[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    T_tc[:3, 3] = c + np.array([0.0, 0.0, 0.3])
    return T_WORLD_TARGET @ T_tc


def test_lost_feature(client: int) -> None:
    spawn_dot_target(client, SMALL_DOTS, T_WORLD_TARGET)
    T_wc = lost_dot_view()
    uv_exact, Z = project_points(OFF_CENTRE, T_wc, SMALL_DOTS.points_world(T_WORLD_TARGET))
    r_px = OFF_CENTRE.fu * SMALL_DOTS.dot_radius / Z
    assert uv_exact[0, 0] < -0.5 - r_px[0] - 5.0  # precondition: dot 0 entirely out
    inside = ((uv_exact[1:] > r_px[1:, None] + 5.0)
              & (uv_exact[1:] < np.array([639.5, 479.5]) - r_px[1:, None] - 5.0))
    assert inside.all()

    uv, found = detect_dots(render_rgb(client, OFF_CENTRE, T_wc), SMALL_DOTS.colors)
    np.testing.assert_array_equal(found, [False, True, True, True, True])
    assert np.all(np.isnan(uv[0]))
    assert np.linalg.norm(uv[1:] - uv_exact[1:], axis=1).max() < MAX_PX_ERROR

    uv_x, found_x, _ = Camera(OFF_CENTRE, mode="exact").measure(client, T_wc, SMALL_DOTS,
                                                                T_WORLD_TARGET)
    np.testing.assert_array_equal(found_x, found)
    assert np.all(np.isnan(uv_x[0]))


# --------------------------------------------------------------------------- Camera


def test_camera_modes_agree(client: int) -> None:
    ids = spawn_dot_target(client, SMALL_DOTS, np.eye(4))
    assert len(ids) == 1 + SMALL_DOTS.n_points
    move_dot_target(client, ids, SMALL_DOTS, T_WORLD_TARGET)
    T_link_camera = np.eye(4)
    T_link_camera[:3, 3] = [0.0, 0.0, 0.05]
    rng = np.random.default_rng(46)
    T_wc, _ = random_view(rng, T_WORLD_TARGET)
    T_world_link = T_wc @ np.linalg.inv(T_link_camera)
    render = Camera(OFF_CENTRE, T_link_camera, mode="render")
    exact = Camera(OFF_CENTRE, T_link_camera, mode="exact")
    np.testing.assert_allclose(render.pose(T_world_link), T_wc, atol=1e-12)
    uv_r, found_r, Z_r = render.measure(client, T_wc, SMALL_DOTS, T_WORLD_TARGET)
    uv_e, found_e, Z_e = exact.measure(client, T_wc, SMALL_DOTS, T_WORLD_TARGET)
    assert found_r.all() and found_e.all()
    np.testing.assert_array_equal(Z_r, Z_e)
    assert np.linalg.norm(uv_r - uv_e, axis=1).max() < MAX_PX_ERROR


def test_camera_exact_mode_behind_camera() -> None:
    T_wc = np.eye(4)  # camera looks along world +z; target 0.4 m behind it
    T_wt = np.eye(4)
    T_wt[:3, 3] = [0.0, 0.0, -0.4]
    uv, found, Z = Camera(CENTRED, mode="exact").measure(-1, T_wc, SMALL_DOTS, T_wt)
    assert not found.any() and np.all(np.isnan(uv)) and np.all(Z < 0)


def test_camera_unknown_mode() -> None:
    with pytest.raises(UnknownChoiceError, match="camera mode"):
        Camera(CENTRED, np.eye(4), mode="magic")


def test_dot_target_validation() -> None:
    with pytest.raises(ConfigError):  # one colour short
        DotTarget(DOTS, DEFAULT_DOT_COLORS[:4])
    with pytest.raises(ConfigError):  # not planar
        DotTarget(DOTS + np.array([0.0, 0.0, 0.01]), DEFAULT_DOT_COLORS[:5])
    with pytest.raises(ConfigError):  # grey is not a detectable hue
        DotTarget(DOTS[:2], ((255, 0, 0), (128, 128, 128)))
    with pytest.raises(ConfigError):  # two reds
        DotTarget(DOTS[:2], ((255, 0, 0), (250, 10, 0)))


@pytest.mark.parametrize(("renderer", "sample_offset"), [("tiny", 0.0), ("opengl", 0.5)])
def test_gl_matrices_map_points_to_the_sampled_pixel(renderer: str, sample_offset: float) -> None:
    """View x projection matrices, followed by the viewport transform, put each point on the
    pixel ``project_points`` predicts, given where the renderer samples a pixel (its corner
    for TinyRenderer, its centre for hardware OpenGL). Pure algebra: no renderer needed; the
    TinyRenderer case is also checked on real images by the render tests above."""
    rng = np.random.default_rng(47)
    W, H = OFF_CENTRE.width, OFF_CENTRE.height
    P = np.array(OFF_CENTRE.projection_matrix_gl(renderer)).reshape(4, 4, order="F")
    for _ in range(5):
        T_wc, _ = random_view(rng, T_WORLD_TARGET)
        V = np.array(view_matrix_gl(T_wc)).reshape(4, 4, order="F")
        pts = SMALL_DOTS.points_world(T_WORLD_TARGET)
        clip = (P @ V @ np.c_[pts, np.ones(len(pts))].T).T
        ndc = clip[:, :3] / clip[:, 3:4]
        assert np.all(np.abs(ndc[:, 2]) < 1.0)  # between the clipping planes
        x_win = (ndc[:, 0] + 1.0) / 2.0 * W
        y_win = (ndc[:, 1] + 1.0) / 2.0 * H
        # pixel rgb[r, c] is sampled at window (c + s, H - 1 - r + s), origin bottom-left
        uv_gl = np.c_[x_win - sample_offset, H - 1.0 - (y_win - sample_offset)]
        uv_exact, _ = project_points(OFF_CENTRE, T_wc, pts)
        np.testing.assert_allclose(uv_gl, uv_exact, atol=1e-6)
