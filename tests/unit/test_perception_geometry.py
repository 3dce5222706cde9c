"""Perception's RGB-D geometry: eq. 1, frame conventions, robust centroid and upright fits.

Depth comes from an exact ray caster (`perception_raycast`), so the truth (the hit points,
the shapes' axes) is known without eq. 1. The camera sits on a trunk that is pitched and
rolled, so the full camera-to-base rotation and the `base_yaw` frame are exercised.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.camera import PinholeCamera, backproject
from common.geometry import FloatArray, inv_T, make_T, rot_x, rot_y, rot_z, transform_points
from common.robot_description import R_FORWARD_OPTICAL
from services.perception.fits import BODY_DEPTH_M, fit_box, fit_cylinder
from services.perception.geometry import heading, robust_centroid
from services.perception.measure import FrameGeometry, ShapeCheck, measure
from tests.unit.perception_raycast import Plane, Shape, UprightBox, UprightCylinder, render

W, H = 320, 240
#: fx, fy, cx, cy (px), as the ray caster takes them.
K = (216.5, 216.5, (W - 1) / 2, (H - 1) / 2)
CAMERA = PinholeCamera(*K)
#: The trunk: at (1, 2) facing 30°, pitched 6° nose-down and rolled 3°, 0.55 m up.
T_WORLD_BASE = make_T(
    rot_z(math.radians(30)) @ rot_y(math.radians(6)) @ rot_x(math.radians(3)), (1.0, 2.0, 0.55)
)
#: A camera 0.3 m ahead of the trunk and 0.4 m up, looking along +x pitched 25° down.
T_BASE_CAMERA = make_T(rot_y(math.radians(25)) @ R_FORWARD_OPTICAL, (0.3, 0.0, 0.4))
GEO = FrameGeometry(CAMERA, T_BASE_CAMERA, T_WORLD_BASE)
T_WORLD_CAMERA = T_WORLD_BASE @ T_BASE_CAMERA


def ahead(distance: float, lateral: float = 0.0) -> tuple[float, float]:
    """A world point `distance` ahead of the base along its heading, `lateral` to its left."""
    yaw = math.radians(30)
    x = 1.0 + distance * math.cos(yaw) - lateral * math.sin(yaw)
    y = 2.0 + distance * math.sin(yaw) + lateral * math.cos(yaw)
    return x, y


def test_a_world_point_projects_to_a_pixel_and_back_to_the_same_point() -> None:
    p_world = np.array([*ahead(1.2, 0.1), 0.8])
    p_cam = transform_points(inv_T(T_WORLD_CAMERA), p_world)
    uv, d = CAMERA.project(p_cam)
    u, v = uv[0]
    assert 0 <= u < W and 0 <= v < H and d[0] > 0
    # the same pixel and depth, back through eq. 1 and the frames, land on the point
    back_world = transform_points(T_WORLD_CAMERA, CAMERA.unproject(uv, d))[0]
    np.testing.assert_allclose(back_world, p_world, atol=1e-9)


def test_a_rendered_pixel_back_projects_onto_the_surface_the_ray_hit() -> None:
    depth, _, points = _plane_scene()
    v, u = 117, 151
    back = transform_points(
        T_WORLD_CAMERA, backproject(depth[v : v + 1, u : u + 1], CAMERA, origin=(u, v))
    )
    np.testing.assert_allclose(back[0], points[v, u], atol=1e-9)


def test_optical_frame_conventions_left_is_small_u_up_is_small_v() -> None:
    level = FrameGeometry(CAMERA, make_T(R_FORWARD_OPTICAL, (0, 0, 0)), np.eye(4))
    T_c_b = inv_T(level.T_base_camera)
    centre, _ = CAMERA.project(transform_points(T_c_b, [2.0, 0.0, 0.0]))
    left, _ = CAMERA.project(transform_points(T_c_b, [2.0, 0.3, 0.0]))
    up, _ = CAMERA.project(transform_points(T_c_b, [2.0, 0.0, 0.3]))
    np.testing.assert_allclose(centre[0], [CAMERA.cx, CAMERA.cy])
    assert left[0, 0] < CAMERA.cx and up[0, 1] < CAMERA.cy


def test_heading_is_measured_in_base_yaw_so_trunk_pitch_does_not_change_it() -> None:
    x, y = ahead(1.0, 0.2)
    p_world = np.array([x, y, 0.9])
    for pitch in (-0.1, 0.0, 0.15):
        T_wb = make_T(rot_z(math.radians(30)) @ rot_y(pitch), (1.0, 2.0, 0.55))
        geo = FrameGeometry(CAMERA, T_BASE_CAMERA, T_wb)
        p_by = transform_points(inv_T(geo.T_world_base_yaw), p_world)[0]
        d_obj, theta = heading(p_by)
        assert d_obj == pytest.approx(math.hypot(1.0, 0.2), abs=1e-9)
        assert theta == pytest.approx(math.atan2(0.2, 1.0), abs=1e-9)


def _plane_scene() -> tuple[FloatArray, np.ndarray, FloatArray]:
    """A tilted plane 1.3 m ahead; the mask is a 60 × 40 pixel window on it."""
    x, y = ahead(1.3)
    normal = rot_z(math.radians(30)) @ np.array([-1.0, 0.3, 0.2])
    depth, labels, points = render([Plane((x, y, 0.5), tuple(normal))], T_WORLD_CAMERA, K, W, H)
    mask = np.zeros((H, W), dtype=bool)
    mask[100:140, 130:190] = True
    return depth, mask & (labels == 1), points


def test_eq1_centroid_of_a_plane_patch_is_within_a_millimetre() -> None:
    depth, mask, points = _plane_scene()
    m = measure(GEO, depth, mask, (0, 0), "thing")
    assert m is not None
    truth = points[mask].mean(axis=0)
    assert np.linalg.norm(m.centroid_world - truth) < 1e-3
    assert m.n_outliers == 0


def test_crops_give_the_same_points_as_the_full_image() -> None:
    depth, mask, _ = _plane_scene()
    full = backproject(depth, CAMERA, mask=mask)
    crop = backproject(depth[90:150, 120:200], CAMERA, mask=mask[90:150, 120:200], origin=(120, 90))
    np.testing.assert_allclose(np.sort(full, axis=0), np.sort(crop, axis=0))


def test_robust_centroid_rejects_mask_pixels_that_bleed_onto_the_background() -> None:
    depth, mask, points = _plane_scene()
    truth = points[mask].mean(axis=0)
    bleed = np.zeros_like(mask)
    bleed[98:142, 128:192] = True
    bleed &= ~mask
    noisy = depth.copy()
    noisy[bleed] = depth[bleed] + 0.8  # the wall behind
    m = measure(GEO, noisy, mask | bleed, (0, 0), "thing")
    assert m is not None and m.n_outliers == int(bleed.sum())
    assert np.linalg.norm(m.centroid_world - truth) < 1e-3


def test_robust_centroid_keeps_every_point_of_clean_data() -> None:
    rng = np.random.default_rng(0)
    pts = rng.uniform(-0.1, 0.1, size=(500, 3))
    c, keep = robust_centroid(pts)
    assert keep.all()
    np.testing.assert_allclose(c, pts.mean(axis=0))


def _bottle(
    distance: float, lateral: float, r: float = 0.03, with_neck: bool = True
) -> list[Shape]:
    x, y = ahead(distance, lateral)
    table = Plane((0, 0, 0.8), (0, 0, 1))
    body = UprightCylinder((x, y), r, 0.8, 0.8 + 0.12)
    shapes: list[Shape] = [table, body]
    if with_neck:
        shapes.append(UprightCylinder((x, y), 0.4 * r, 0.92, 0.96))
    return shapes


@pytest.mark.parametrize(
    ("distance", "lateral", "with_neck"),
    [(0.7, 0.0, False), (1.0, 0.15, True), (1.5, -0.2, True)],
)
def test_eq1_cylinder_centroid_within_1_mm_and_axis_within_2_mm(
    distance: float, lateral: float, with_neck: bool
) -> None:
    shapes = _bottle(distance, lateral, with_neck=with_neck)
    depth, labels, points = render(shapes, T_WORLD_CAMERA, K, W, H)
    mask = labels >= 2  # body and neck are one instance
    m = measure(GEO, depth, mask, (0, 0), "bottle")
    assert m is not None
    truth = points[mask].mean(axis=0)
    assert np.linalg.norm(m.centroid_world - truth) < 1e-3
    x, y = ahead(distance, lateral)
    assert np.hypot(m.axis_world[0] - x, m.axis_world[1] - y) < 2e-3
    assert not m.fit_base_yaw.fallback
    assert m.fit_base_yaw.radius == pytest.approx(0.03, abs=2e-3)
    d_obj, theta = heading(transform_points(inv_T(GEO.T_world_base_yaw), truth)[0])
    assert m.d_obj == pytest.approx(d_obj, abs=1e-3)
    assert m.theta_obj == pytest.approx(theta, abs=1e-3)


def test_a_cylinder_fit_on_a_visible_arc_recovers_axis_and_radius() -> None:
    angles = np.linspace(-1.2, 1.2, 40)  # the arc facing the eye at -x
    z = np.repeat(np.linspace(0.0, 0.1, 10), len(angles))
    a = np.tile(angles, 10)
    pts = np.column_stack([0.5 - 0.04 * np.cos(a), 0.2 + 0.04 * np.sin(a), z])
    fit = fit_cylinder(pts, eye=(-1.0, 0.2, 0.5))
    np.testing.assert_allclose(fit.axis[:2], [0.5, 0.2], atol=1e-6)
    assert fit.radius == pytest.approx(0.04, abs=1e-6)


def test_a_cylinder_too_far_to_fit_falls_back_to_a_radius_behind_the_centroid() -> None:
    pts = np.column_stack([np.full(12, 3.0), np.linspace(-0.02, 0.02, 12), np.linspace(0, 0.1, 12)])
    fit = fit_cylinder(pts, eye=(0.0, 0.0, 0.5))
    assert fit.fallback
    assert fit.axis[0] == pytest.approx(3.0 + fit.radius, abs=1e-9)


def test_a_box_showing_two_faces_gives_its_centre_yaw_and_extent() -> None:
    x, y = ahead(1.1, 0.05)
    box = UprightBox((x, y, 0.9), (0.06, 0.03, 0.1), math.radians(30 + 35))
    depth, labels, points = render([Plane((0, 0, 0.8), (0, 0, 1)), box], T_WORLD_CAMERA, K, W, H)
    m = measure(GEO, depth, labels == 2, (0, 0), "box")
    assert m is not None
    assert np.hypot(m.axis_world[0] - x, m.axis_world[1] - y) < 4e-3
    assert sorted(m.fit_base_yaw.extent[:2]) == pytest.approx([0.06, 0.12], abs=8e-3)
    off = (m.yaw_world - math.radians(65)) % (math.pi / 2)
    assert min(off, math.pi / 2 - off) < math.radians(1.0)
    fit = fit_box(points[labels == 2])
    assert sorted(fit.extent[:2]) == pytest.approx([0.06, 0.12], abs=8e-3)


def test_a_persons_axis_is_put_behind_what_the_camera_sees_of_them() -> None:
    """A body 24 cm across 1.5 m ahead: the visible centroid lies in front of its axis;
    the person's axis is `BODY_DEPTH_M` (6 cm) behind it, along the line of sight, and
    the centroid stays what was seen."""
    x, y = ahead(1.5)
    body = UprightCylinder((x, y), 0.12, 0.0, 1.7)
    depth, labels, points = render([Plane((0, 0, 0), (0, 0, 1)), body], T_WORLD_CAMERA, K, W, H)
    mask = labels == 2  # the plane is 1
    m = measure(GEO, depth, mask, (0, 0), "person")
    assert m is not None
    seen = points[mask].mean(axis=0)
    assert np.linalg.norm(m.centroid_world - seen) < 1e-3
    sight = np.array(ahead(1.0)) - np.array(ahead(0.0))
    assert np.dot(m.axis_world[:2] - seen[:2], sight) == pytest.approx(BODY_DEPTH_M, abs=2e-3)
    off_seen = np.hypot(seen[0] - x, seen[1] - y)  # ~10 cm: at 1.5 m less than half shows
    assert np.hypot(m.axis_world[0] - x, m.axis_world[1] - y) == pytest.approx(
        off_seen - BODY_DEPTH_M, abs=0.01
    )


def test_too_few_points_is_no_measurement() -> None:
    depth = np.zeros((H, W))
    depth[10, 10] = 1.0
    assert measure(GEO, depth, depth > 0, (0, 0), "bottle") is None


CHECK = ShapeCheck(range_m=1.2, rms_per_m2=2.8e-3)


def _noisy(depth: FloatArray, seed: int, sigma_per_m2: float = 1.0e-3) -> FloatArray:
    """Depth with white noise growing as depth² (a stereo sensor's), none where no hit."""
    rng = np.random.default_rng(seed)
    return np.where(depth > 0, depth + rng.normal(0.0, sigma_per_m2, depth.shape) * depth**2, 0.0)


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("yaw_deg", [0.0, 35.0])
def test_the_shape_check_reads_a_box_the_network_called_a_can_as_a_box(
    seed: int, yaw_deg: float
) -> None:
    # hall seed 0: a 9 x 6 x 13 cm box 0.78 m away, its top in view, square-on or not,
    # called a can
    x, y = ahead(0.8)
    box = UprightBox((x, y, 0.665), (0.045, 0.031, 0.065), math.radians(30 + yaw_deg))
    depth, labels, _ = render([Plane((0, 0, 0.6), (0, 0, 1)), box], T_WORLD_CAMERA, K, W, H)
    depth = _noisy(depth, seed)
    m = measure(GEO, depth, labels == 2, (0, 0), "can", CHECK)
    assert m is not None
    assert (m.class_name, m.network_class) == ("box", "can")
    assert m.fit_base_yaw.shape == "box"
    assert np.hypot(m.axis_world[0] - x, m.axis_world[1] - y) < 0.02
    unchecked = measure(GEO, depth, labels == 2, (0, 0), "can")
    assert unchecked is not None
    assert (unchecked.class_name, unchecked.fit_base_yaw.shape) == ("can", "cylinder")


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("distance", [0.75, 1.1])
def test_the_shape_check_reads_a_can_the_network_called_a_box_as_a_can(
    seed: int, distance: float
) -> None:
    x, y = ahead(distance)
    shapes: list[Shape] = [Plane((0, 0, 0.8), (0, 0, 1)), UprightCylinder((x, y), 0.03, 0.8, 0.92)]
    depth, labels, _ = render(shapes, T_WORLD_CAMERA, K, W, H)
    depth = _noisy(depth, seed)
    as_box = measure(GEO, depth, labels == 2, (0, 0), "box", CHECK)
    as_can = measure(GEO, depth, labels == 2, (0, 0), "can", CHECK)
    assert as_box is not None and as_can is not None
    assert (as_box.class_name, as_box.network_class) == ("can", "box")
    assert (as_can.class_name, as_can.network_class) == ("can", "")
    assert as_box.fit_base_yaw.radius == pytest.approx(0.03, abs=3e-3)


def test_the_shape_check_leaves_far_objects_bottles_and_unfitted_arcs_to_the_network() -> None:
    x, y = ahead(1.6)  # beyond range_m of the camera
    box = UprightBox((x, y, 0.865), (0.045, 0.031, 0.065), math.radians(30))
    depth, labels, _ = render([Plane((0, 0, 0.8), (0, 0, 1)), box], T_WORLD_CAMERA, K, W, H)
    far = measure(GEO, _noisy(depth, 0), labels == 2, (0, 0), "can", CHECK)
    assert far is not None and (far.class_name, far.network_class) == ("can", "")
    x, y = ahead(0.8)  # a bottle is not one of the pair, whatever its shape
    box = UprightBox((x, y, 0.865), (0.045, 0.031, 0.065), math.radians(30))
    depth, labels, _ = render([Plane((0, 0, 0.8), (0, 0, 1)), box], T_WORLD_CAMERA, K, W, H)
    bottle = measure(GEO, _noisy(depth, 0), labels == 2, (0, 0), "bottle", CHECK)
    assert bottle is not None and bottle.class_name == "bottle"
    arc = fit_cylinder(
        np.column_stack([np.full(12, 3.0), np.linspace(-0.02, 0.02, 12), np.linspace(0, 0.1, 12)]),
        eye=(0.0, 0.0, 0.5),
    )
    assert arc.fallback and CHECK.judge(arc, 0.8) is None
